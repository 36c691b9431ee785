"""Cameras to and from other tools: aniposelib/anipose TOML and OpenCV FileStorage YAML.

Both carry the same pinhole-plus-distortion model as vlpcal (docs/conventions.md#pose):
``rotation`` is OpenCV's ``rvec`` (world → camera) and ``translation`` its ``tvec = −R ·
position``, so a point maps as ``x_cam = R · X + tvec``; ``dist`` is ``[k1, k2, p1, p2, k3]``.
What the other tools leave unsaid, the files written here state in their metadata: the length
unit and the world frame (z up, floor at z = 0).

aniposelib (``CameraGroup.load``) orders cameras by *sorting the section names as text*, so
``cam_10`` comes before ``cam_2`` and the order of more than ten cameras is lost. Files written
here zero-pad the index (``cam_00`` … ``cam_11``) so that the text order is the camera order;
files read here are ordered by the number in the section name, so aniposelib's own unpadded
files keep their order too.

cv2 (FileStorage) and shapely (the cameras inside the room) are imported where used, being
heavy: an anipose export needs neither.
"""

from __future__ import annotations

import re
import sys
from enum import Enum

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from .geometry import Camera, rodrigues
from .reading import ID_RULE, MAX_DEPTH, is_id, nesting_depth, shown

#: metres per unit
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
CONVENTION = ("x_cam = R(rotation) * X_world + translation (OpenCV rvec, tvec); world: "
              "right-handed, z up, floor at z = 0; pixels: OpenCV, centre of the top-left "
              "pixel at (0, 0)")


class Remedy(Enum):
    """What would mend a camera file that cannot be read, in this module's words (the value,
    which ends the message); a command says it with its own options."""

    STATE_UNITS = ": state it with the units argument, m, cm or mm"
    OPENCV_LAYOUT = " (expected what to_opencv_yaml writes)"


class InterchangeError(ValueError):
    """A camera file from another tool that cannot be read (one line: file, item, expected).

    ``problem``: the message without its ``remedy`` (a :class:`Remedy`, or None)."""

    def __init__(self, problem: str, remedy: Remedy | None = None):
        super().__init__(problem + (remedy.value if remedy else ""))
        self.problem, self.remedy = problem, remedy


def _tvec(cam: Camera) -> np.ndarray:
    return -rodrigues(cam.rotation) @ np.asarray(cam.position, float)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[ " + ", ".join(_toml_value(x) for x in v) + ",]"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def to_anipose_toml(cameras: list[Camera], units: str = "m", metadata: dict | None = None
                    ) -> str:
    """The cameras as an aniposelib ``CameraGroup`` TOML, in their order, lengths in
    ``units`` (m, cm or mm; anipose calibrations are usually in mm)."""
    scale = 1.0 / UNITS[units]
    width = len(str(len(cameras) - 1))
    lines = []
    for i, c in enumerate(cameras):
        matrix = [[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]]
        lines += [f"[cam_{i:0{width}d}]",
                  f"name = {_toml_value(c.id)}",
                  f"size = {_toml_value([int(c.width), int(c.height)])}",
                  f"matrix = {_toml_value(matrix)}",
                  f"distortions = {_toml_value(list(c.dist))}",
                  f"rotation = {_toml_value(list(c.rotation))}",
                  f"translation = {_toml_value(list(_tvec(c) * scale))}", ""]
    meta = {"adjusted": False, "units": units, "convention": CONVENTION, "written_by": "vlpcal",
            **(metadata or {})}
    lines += ["[metadata]"] + [f"{k} = {_toml_value(v)}" for k, v in meta.items()]
    return "\n".join(lines) + "\n"


def _toml_loads(text: str) -> dict:
    return tomllib.loads(text)


def from_anipose_toml(text: str, source: str = "<toml>", units: str | None = None
                      ) -> list[Camera]:
    """Cameras from an aniposelib TOML, in the order of their section numbers. ``units`` is
    the file's length unit; by default the one its metadata states (vlpcal writes it;
    aniposelib does not, so it must then be given)."""
    try:
        doc = _toml_loads(text)
    except ValueError as e:
        raise InterchangeError(f"{source}: not a TOML file ({e})") from None
    except RecursionError:
        raise InterchangeError(f"{source}: nested too deeply (expected an aniposelib "
                               "calibration TOML)") from None
    meta = doc.get("metadata", {})
    if not isinstance(meta, dict):
        raise InterchangeError(f"{source}: metadata: expected a [metadata] table")
    stated = meta.get("units")
    if units and stated and units != stated:
        raise InterchangeError(f"{source}: its [metadata] says units = {shown(stated)}; the unit "
                               f"given ({shown(units)}) disagrees: leave it out")
    units = units or stated
    if not isinstance(units, (str, type(None))) or units not in UNITS:
        if units is None:
            raise InterchangeError(f"{source}: the length unit is not stated in [metadata] "
                                   "(aniposelib does not record it)", Remedy.STATE_UNITS)
        raise InterchangeError(f"{source}: unknown length unit {shown(units)} (expected m, cm "
                               "or mm)")
    sections = []
    for key, value in doc.items():
        m = re.fullmatch(r"cam_(\d+)", key)
        if m and isinstance(value, dict):
            sections.append((int(m.group(1)), key, value))
        elif key != "metadata":
            raise InterchangeError(f"{source}: [{key}]: unexpected section (expected [cam_N] "
                                   "camera sections and [metadata])")
    if not sections:
        raise InterchangeError(f"{source}: no [cam_N] camera sections")
    cams, seen = [], set()
    for _, key, sec in sorted(sections):
        cams.append(_camera_of_section(sec, f"{source}: [{key}]", UNITS[units]))
        if cams[-1].id in seen:
            raise InterchangeError(f"{source}: [{key}].name: camera {shown(cams[-1].id)} twice")
        seen.add(cams[-1].id)
    return cams


def _camera_of_section(sec: dict, where: str, metres: float) -> Camera:
    if sec.get("fisheye"):
        raise InterchangeError(f"{where}: a fisheye camera (vlpcal models pinhole lenses with "
                               "OpenCV's k1, k2, p1, p2, k3 distortion)")

    def array(key, shape):
        try:
            a = np.asarray(sec[key], float)
        except KeyError:
            raise InterchangeError(f"{where}: missing key {shown(key)}") from None
        except (TypeError, ValueError):
            raise InterchangeError(f"{where}.{key}: expected numbers") from None
        if a.shape != shape or not np.isfinite(a).all():
            raise InterchangeError(f"{where}.{key}: expected {shape} finite numbers, got "
                                   f"{shown(sec[key])}")
        return a

    size, K = array("size", (2,)), array("matrix", (3, 3))
    try:
        dist = np.asarray(sec.get("distortions", [0.0] * 5), float).ravel()
    except (TypeError, ValueError):
        dist = np.full(6, np.nan)
    if dist.size > 5 or not np.isfinite(dist).all():
        raise InterchangeError(f"{where}.distortions: expected up to 5 finite numbers "
                               "(k1, k2, p1, p2, k3)")
    rvec, tvec = array("rotation", (3,)), array("translation", (3,)) * metres
    if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise InterchangeError(f"{where}.matrix: expected [[fx, 0, cx], [0, fy, cy], "
                               "[0, 0, 1]] with fx, fy > 0 (no skew)")
    name = str(sec.get("name", where.rsplit("[", 1)[-1].rstrip("]"))).strip()
    if size.min() < 1 or size.max() > 100000 or np.any(size != np.round(size)):
        raise InterchangeError(f"{where}.size: expected [width, height] in pixels")
    if not is_id(name):
        raise InterchangeError(f"{where}.name: expected a camera id ({ID_RULE}), got "
                               f"{shown(name)}")
    position = -rodrigues(rvec).T @ tvec
    return Camera(id=name, width=int(size[0]), height=int(size[1]), fx=float(K[0, 0]),
                  fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]),
                  dist=tuple(float(v) for v in np.r_[dist, np.zeros(5 - dist.size)]),
                  position=tuple(float(v) for v in position),
                  rotation=tuple(float(v) for v in rvec))


def to_opencv_yaml(cameras: list[Camera]) -> str:
    """The cameras as an OpenCV FileStorage YAML (``cv::FileStorage`` reads it back): per
    camera its id, image size, ``camera_matrix``, ``distortion_coefficients``, ``rvec``,
    ``tvec`` (metres) and ``position``, with the convention stated."""
    import cv2

    fs = cv2.FileStorage("cameras.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("units", "m")
    fs.write("convention", CONVENTION)
    fs.write("camera_count", len(cameras))
    fs.startWriteStruct("cameras", cv2.FileNode_SEQ)
    for c in cameras:
        fs.startWriteStruct("", cv2.FileNode_MAP)
        fs.write("id", c.id)
        fs.write("image_width", int(c.width))
        fs.write("image_height", int(c.height))
        fs.write("camera_matrix", np.array([[c.fx, 0, c.cx], [0, c.fy, c.cy], [0, 0, 1.0]]))
        fs.write("distortion_coefficients", np.asarray(c.dist, float).reshape(1, 5))
        fs.write("rvec", np.asarray(c.rotation, float).reshape(3, 1))
        fs.write("tvec", _tvec(c).reshape(3, 1))
        fs.write("position", np.asarray(c.position, float).reshape(3, 1))
        fs.endWriteStruct()
    fs.endWriteStruct()
    # every id quoted: FileStorage writes a text id unquoted when it can (true, null, nan),
    # and its reader takes true for the number 1 and null for nothing
    text = re.sub(r'(?m)^( +id: )"?([^"\n]*)"?$', r'\1"\2"', fs.releaseAndGetString())
    try:
        back = [c.id for c in from_opencv_yaml(text)]
    except InterchangeError:
        back = None
    if back != [c.id for c in cameras]:
        bad = next((c.id for c, b in zip(cameras, back or [None] * len(cameras)) if c.id != b),
                   cameras[0].id)
        raise InterchangeError(f"camera id {shown(bad)} does not survive OpenCV's YAML: "
                               "rename the camera")
    return text


#: what OpenCV's FileStorage reads as a number or as nothing when a YAML value is unquoted
_OPENCV_NOT_TEXT = ("true", "false", "null")
#: an ``id:`` key's value as written in a FileStorage YAML (block or flow style)
_ID_VALUE = re.compile(r"""(?:^|[{,\s])id\s*:[ \t]*("[^"\n]*"|'[^'\n]*'|[^\s,}#]*)""", re.M)


def from_opencv_yaml(text: str, source: str = "<yaml>") -> list[Camera]:
    """Cameras from a FileStorage YAML as :func:`to_opencv_yaml` writes it (its nesting
    checked first: OpenCV's parser recurses without a limit)."""
    import cv2

    if nesting_depth(text) > MAX_DEPTH:
        raise InterchangeError(f"{source}: nested deeper than {MAX_DEPTH} levels",
                               Remedy.OPENCV_LAYOUT)
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        node = fs.getNode("cameras")
        ok = not node.empty() and node.isSeq()
    except (cv2.error, SystemError):
        ok = False
    if not ok:
        raise InterchangeError(f"{source}: not an OpenCV FileStorage file with a 'cameras' "
                               "sequence", Remedy.OPENCV_LAYOUT)
    kind = fs.getNode("format").string()
    if kind.startswith("vlpcal"):
        raise InterchangeError(f"{source}: a {kind} file, not an OpenCV camera file",
                               Remedy.OPENCV_LAYOUT)
    unit = fs.getNode("units").string() or "m"
    if unit not in UNITS:
        raise InterchangeError(f"{source}: units: expected m, cm or mm, got {shown(unit)}")
    # each camera's id as the file writes it: FileStorage reads an unquoted true as 1 and
    # 01 as 1, which would rename the camera silently
    raw_all = [None if v[:1] in "\"'" else v for v in _ID_VALUE.findall(text)]  # quoted: text
    raw = raw_all if len(raw_all) == node.size() else None
    cams = []
    for i in range(node.size()):
        n, where = node.at(i), f"{source}: cameras[{i}]"

        def mat(key, shape, n=n, where=where):
            try:
                a = n.getNode(key).mat() if n.isMap() else None
            except (cv2.error, SystemError):
                a = None
            if a is None or a.size != int(np.prod(shape)) or not np.isfinite(a).all():
                raise InterchangeError(f"{where}.{key}: expected a {'×'.join(map(str, shape))} "
                                       "matrix of finite numbers")
            return a.reshape(shape).astype(float)

        K, dist = mat("camera_matrix", (3, 3)), mat("distortion_coefficients", (5,))
        rvec, tvec = mat("rvec", (3,)), mat("tvec", (3,)) * UNITS[unit]
        cid = n.getNode("id")
        written = raw[i] if raw is not None else None
        if cid.empty():
            raise InterchangeError(f"{where}.id: missing (expected a camera id, {ID_RULE})")
        if (written in _OPENCV_NOT_TEXT or cid.isNone()
                or (raw is None and cid.isInt() and any(v in _OPENCV_NOT_TEXT for v in raw_all))):
            said = written or ("null" if cid.isNone() else "true or false")
            reads = "nothing" if cid.isNone() else "a number"
            raise InterchangeError(f"{where}.id: {said} unquoted, which OpenCV reads as {reads} "
                                   f"(expected a camera id; quote it: id: \"{said}\")")
        if cid.isString():
            name = cid.string()
        elif written is not None and (cid.isInt() or cid.isReal()):
            name = written  # as written: 01 or 1.0 read back as 1 would rename the camera
        else:
            name = f"{cid.real():g}" if cid.isInt() or cid.isReal() else ""
        w, h = n.getNode("image_width").real(), n.getNode("image_height").real()
        if not is_id(name):
            raise InterchangeError(f"{where}.id: expected a camera id ({ID_RULE}), got "
                                   f"{shown(name)}")
        if not (w >= 1 and h >= 1):
            raise InterchangeError(f"{where}: expected image_width and image_height")
        cams.append(Camera(id=name, width=int(w), height=int(h), fx=K[0, 0], fy=K[1, 1],
                           cx=K[0, 2], cy=K[1, 2], dist=tuple(dist),
                           position=tuple(-rodrigues(rvec).T @ tvec),
                           rotation=tuple(rvec)))
    return cams


def check_world_frame(cameras: list[Camera], ceiling_height: float, source: str,
                      room_polygon=None) -> None:
    """Refuse cameras that cannot hang in a z-up room (anipose's world is often its first
    camera's frame or a calibration board's: align it to the floor first): above the floor,
    at most 0.5 m over the ceiling, within 1 m of the room in plan."""
    from shapely.geometry import Point, Polygon

    room = Polygon(room_polygon).buffer(1.0) if room_polygon is not None else None
    for c in cameras:
        z = c.position[2]
        if not 0.0 < z <= ceiling_height + 0.5 or (room is not None and not room.contains(
                Point(c.position[:2]))):
            raise InterchangeError(
                f"{source}: camera {c.id} at ({c.position[0]:.3g}, {c.position[1]:.3g}, "
                f"{z:.3g}) m is not between the floor and the {ceiling_height:g} m ceiling of "
                "the room: the file's world frame is not the room's (z up, floor at z = 0) or "
                "its unit is wrong")


def same_cameras(a, b, metres: float = 1e-4, radians: float = 1e-5) -> bool:
    """Same ids in the same order, poses within ``metres`` / ``radians`` and the same lenses."""
    if [c.id for c in a] != [c.id for c in b]:
        return False
    for p, q in zip(a, b):
        lens_p = np.r_[p.width, p.height, p.fx, p.fy, p.cx, p.cy, p.dist]
        lens_q = np.r_[q.width, q.height, q.fx, q.fy, q.cx, q.cy, q.dist]
        if (not np.allclose(lens_p, lens_q, rtol=1e-6, atol=1e-9)
                or np.linalg.norm(np.subtract(p.position, q.position)) > metres
                or np.abs(rodrigues(p.rotation) - rodrigues(q.rotation)).max() > radians):
            return False
    return True
