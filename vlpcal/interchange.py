"""Cameras to and from other tools: aniposelib/anipose TOML and OpenCV FileStorage YAML.

Both carry the same pinhole-plus-distortion model as vlpcal (DESIGN.md): ``rotation`` is
OpenCV's ``rvec`` (world → camera) and ``translation`` its ``tvec = −R · position``, so a point
maps as ``x_cam = R · X + tvec``; ``dist`` is ``[k1, k2, p1, p2, k3]``. What the other tools
leave unsaid, the files written here state in their metadata: the length unit and the world
frame (z up, floor at z = 0).

aniposelib (``CameraGroup.load``) orders cameras by *sorting the section names as text*, so
``cam_10`` comes before ``cam_2`` and the order of more than ten cameras is lost. Files written
here zero-pad the index (``cam_00`` … ``cam_11``) so that the text order is the camera order;
files read here are ordered by the number in the section name, so aniposelib's own unpadded
files keep their order too.
"""

from __future__ import annotations

import re
import sys

import numpy as np

from .geometry import Camera, rodrigues

#: metres per unit
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
CONVENTION = ("x_cam = R(rotation) * X_world + translation (OpenCV rvec, tvec); world: "
              "right-handed, z up, floor at z = 0; pixels: OpenCV, centre of the top-left "
              "pixel at (0, 0)")


class InterchangeError(ValueError):
    """A camera file from another tool that cannot be read (one line: file, item, expected)."""


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
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
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
    meta = doc.get("metadata", {})
    units = units or meta.get("units")
    if units not in UNITS:
        raise InterchangeError(
            f"{source}: the length unit is not stated in [metadata] (aniposelib does not "
            f"record it): state it with --units m, cm or mm" if units is None else
            f"{source}: unknown length unit {units!r} (expected m, cm or mm)")
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
            raise InterchangeError(f"{source}: [{key}].name: camera {cams[-1].id!r} twice")
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
            raise InterchangeError(f"{where}: missing key {key!r}") from None
        except (TypeError, ValueError):
            raise InterchangeError(f"{where}.{key}: expected numbers") from None
        if a.shape != shape or not np.isfinite(a).all():
            raise InterchangeError(f"{where}.{key}: expected {shape} finite numbers, got "
                                   f"{sec[key]!r}")
        return a

    size, K = array("size", (2,)), array("matrix", (3, 3))
    dist = np.asarray(sec.get("distortions", [0.0] * 5), float).ravel()
    if dist.size > 5 or not np.isfinite(dist).all():
        raise InterchangeError(f"{where}.distortions: expected up to 5 finite numbers "
                               "(k1, k2, p1, p2, k3)")
    rvec, tvec = array("rotation", (3,)), array("translation", (3,)) * metres
    if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise InterchangeError(f"{where}.matrix: expected [[fx, 0, cx], [0, fy, cy], "
                               "[0, 0, 1]] with fx, fy > 0 (no skew)")
    name = str(sec.get("name", where.rsplit("[", 1)[-1].rstrip("]")))
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
    return fs.releaseAndGetString()


def from_opencv_yaml(text: str, source: str = "<yaml>") -> list[Camera]:
    """Cameras from a FileStorage YAML as :func:`to_opencv_yaml` writes it."""
    import cv2

    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except cv2.error:
        raise InterchangeError(f"{source}: not an OpenCV FileStorage file") from None
    node = fs.getNode("cameras")
    if node.empty() or not node.isSeq():
        raise InterchangeError(f"{source}: no 'cameras' sequence (expected the file "
                               "vlpcal export --to opencv writes)")
    cams = []
    for i in range(node.size()):
        n, where = node.at(i), f"{source}: cameras[{i}]"
        K, dist = n.getNode("camera_matrix").mat(), n.getNode("distortion_coefficients").mat()
        rvec, tvec = n.getNode("rvec").mat(), n.getNode("tvec").mat()
        if any(a is None for a in (K, dist, rvec, tvec)):
            raise InterchangeError(f"{where}: expected camera_matrix, "
                                   "distortion_coefficients, rvec and tvec")
        rvec, tvec = rvec.ravel(), tvec.ravel()
        cams.append(Camera(id=n.getNode("id").string(), width=int(n.getNode("image_width")
                                                                  .real()),
                           height=int(n.getNode("image_height").real()), fx=K[0, 0],
                           fy=K[1, 1], cx=K[0, 2], cy=K[1, 2],
                           dist=tuple(float(v) for v in dist.ravel()),
                           position=tuple(float(v) for v in -rodrigues(rvec).T @ tvec),
                           rotation=tuple(float(v) for v in rvec)))
    return cams


def check_world_frame(cameras: list[Camera], ceiling_height: float, source: str) -> None:
    """Refuse cameras that cannot hang in a z-up room (anipose's world is often its first
    camera's frame or a calibration board's: align it to the floor first)."""
    for c in cameras:
        z = c.position[2]
        if not 0.0 < z <= ceiling_height + 0.5:
            raise InterchangeError(
                f"{source}: camera {c.id} is at z = {z:.3g} m, not between the floor and the "
                f"{ceiling_height:g} m ceiling: the file's world frame is not the room's (z up, "
                "floor at z = 0) or its unit is wrong")


