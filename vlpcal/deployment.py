"""The deployment file (``format: vlpcal-deployment``, ``version: 1``): load, check, save.

The one module that knows the file (docs/formats.md). Required keys exactly as the contract has
them; every other top-level block (detector settings, fusion policy, region maps, corrections,
LEDs' blink codes, provenance) is optional and kept as it was read (``Deployment.extra``), so a
tool that does not know a block never drops it. Errors name the file, the key path
(``cameras[2].fx``) and what was expected (:class:`DeploymentError`). Writes go through
:mod:`vlpcal.writing` (staged, then renamed). Some 760 lines in one module on purpose: most are
the checks of the optional blocks, a function each, sharing the key-path messages and the
number checks, so that the format is known in one place.

shapely is imported where polygons are judged (zones, keep-outs, a fix near the walls): a
deployment without them is loaded and used without that heavy import.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import yaml

from . import __version__
from .blink import BlinkCode, check_codes
from .bodies import gives_full_pose
from .detection import DEFAULT_DETECTOR, DEFAULTS, DETECTORS, DetectorSettings
from .fusion import FUSIONS, PAIR_METHODS, RegionMap
from .geometry import Camera, max_radius2
from .reading import (
    ID_RULE,
    ReadError,
    is_id,
    load_yaml,
    read_text,
    room_slip,
    shown,
    slipped_units,
    yaml_dumper,
)
from .writing import write_text

FORMAT, VERSION = "vlpcal-deployment", 1
CAMERA_KEYS = ("id", "width", "height", "fx", "fy", "cx", "cy", "dist", "position", "rotation")
SITE_KEYS = ("name", "ceiling_height", "room", "keep_out")
#: the optional top-level blocks; a missing block means the defaults
OPTIONAL_BLOCKS = ("detector", "fusion", "corrections", "uncertainty", "leds", "zones",
                   "bodies", "provenance")
DETECTOR_SETTINGS = tuple(DetectorSettings.__dataclass_fields__)
DEFAULT_FUSION = "robust"
#: a position further than this many of its predicted errors, plus :data:`ROOM_SLACK` of the
#: ceiling height, under the floor, over the ceiling or beyond the walls is not the LED
PLAUSIBLE_SIGMAS = 5.0
ROOM_SLACK = 0.02
#: px, the spot noise behind a fix's predicted uncertainty when the file states none (the blob
#: detector's RMS error per axis on simulated frames is ~0.04 px; benchmarks/detectors.py)
DEFAULT_PIXEL_NOISE = 0.05


#: the JSON Schema of the format, for editors (``# yaml-language-server: $schema=…``)
SCHEMA_PATH = Path(__file__).resolve().parent / "schemas" / "deployment.schema.json"


class DeploymentError(ValueError):
    """A deployment file that does not follow the format; the message is one line."""


@dataclass
class Deployment:
    """A site and its cameras (metres, radians), plus the optional blocks as read."""

    name: str
    ceiling_height: float
    room: list
    cameras: list[Camera]
    keep_out: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    # -- the optional blocks, parsed (they were checked when the file was read) ---------------
    @property
    def detector(self) -> str:
        """Spot detector by name (``detector.method``; default ``blob``)."""
        return self.extra.get("detector", {}).get("method", DEFAULT_DETECTOR)

    @property
    def detector_settings(self) -> DetectorSettings:
        given = {k: float(v) for k, v in self.extra.get("detector", {}).items() if k != "method"}
        if "window" in given:
            given["window"] = int(given["window"])
        return DetectorSettings(**given) if given else DEFAULTS

    @property
    def fusion(self) -> str:
        """Fusion by name (``fusion.method``; default ``robust``)."""
        return self.extra.get("fusion", {}).get("method", DEFAULT_FUSION)

    @property
    def pair_method(self) -> str:
        return self.extra.get("fusion", {}).get("pair_method", "paper")

    @property
    def size(self) -> float:
        """m: the scene's size — the room's larger side or its ceiling height, whichever is
        larger — against which a position's uncertainty or a survey point's place is judged."""
        xs = [p[0] for p in self.room]
        ys = [p[1] for p in self.room]
        return max(max(xs) - min(xs), max(ys) - min(ys), float(self.ceiling_height))

    def doubts(self) -> list[str]:
        """What the file holds that is possible but hardly meant, one line each — said, not
        refused (a plain calibration tool would take it): a camera under the floor, or whose
        optical axis looks up, away from the floor, so it sees no LED there (a rotation given
        camera-to-world, say: docs/conventions.md, "Pose")."""
        out = []
        for c in self.cameras:
            if c.center[2] < 0:
                out.append(f"camera {c.id} hangs {-c.center[2]:.3g} m under the floor "
                           f"(position z = {c.center[2]:g}): is the sign right?")
            axis = c.axis
            if axis[2] >= 0:
                up = math.degrees(math.atan2(axis[2], math.hypot(axis[0], axis[1])))
                out.append(f"camera {c.id} looks up, {up:.0f}° above level: it sees nothing on "
                           "the floor (is its rotation world-to-camera, as OpenCV's rvec?)")
        return out

    @property
    def max_residual(self) -> float:
        """px: the robust fusion's limit on an observation's reprojection error; unless the
        file states it (a survey calibration does, from its held-out residuals), 1 % of the
        smallest camera's image diagonal (2 px for the paper's 160 × 120)."""
        stated = self.extra.get("fusion", {}).get("max_residual")
        if stated is not None:
            return float(stated)
        return 0.01 * min(math.hypot(c.width, c.height) for c in self.cameras)

    @property
    def region_map(self) -> RegionMap | None:
        items = self.extra.get("fusion", {}).get("region_map")
        return RegionMap.from_dict(items) if items else None

    @property
    def pixel_offsets(self) -> dict:
        """Camera id → (du, dv) px subtracted from every detected spot (``corrections``)."""
        return {cid: tuple(map(float, c.get("pixel_offset", (0.0, 0.0))))
                for cid, c in self.extra.get("corrections", {}).items()}

    @property
    def pixel_noise(self) -> float:
        """px, the spot noise behind the predicted uncertainty (``uncertainty.pixel_noise``)."""
        return float(self.extra.get("uncertainty", {}).get("pixel_noise", DEFAULT_PIXEL_NOISE))

    @property
    def leds(self) -> list[BlinkCode]:
        """The LEDs' blink codes (``leds:``; none: LEDs without identity)."""
        return [BlinkCode(str(d["id"]), str(d["pattern"]), float(d["bit_rate"]))
                for d in self.extra.get("leds", [])]

    @property
    def bodies(self) -> list[Body]:
        """Rigid bodies carrying several LEDs (``bodies:``; none: every LED on its own)."""
        return [Body(str(b["id"]), {str(k): np.asarray(v, float) for k, v in b["leds"].items()})
                for b in self.extra.get("bodies", [])]

    @property
    def zones(self) -> dict:
        """Zone id → (floor polygon, camera ids) (``zones:``; none: one zone, the site)."""
        return {str(z["id"]): ([tuple(map(float, p)) for p in z["polygon"]],
                               [str(c) for c in z["cameras"]])
                for z in self.extra.get("zones", [])}

    def zone(self, zone_id: str) -> Deployment:
        """The deployment of one zone: its cameras only (and the rest as it is)."""

        polygon, ids = self.zones[zone_id]
        keep = set(ids)
        extra = {k: v for k, v in self.extra.items() if k != "fusion"}
        fusion = {k: v for k, v in self.extra.get("fusion", {}).items() if k != "region_map"}
        if fusion:
            extra["fusion"] = fusion
        return replace(self, name=f"{self.name}, zone {zone_id}",
                       cameras=[c for c in self.cameras if c.id in keep], extra=extra)

    def outside(self, X, sigma):
        """Positions ``X`` (N×3) that cannot be the LED: under the floor, over the ceiling or
        beyond the room's walls by more than :data:`PLAUSIBLE_SIGMAS` of their own predicted
        error ``sigma`` (N) and :data:`ROOM_SLACK` of the ceiling height."""
        X = np.atleast_2d(np.asarray(X, float))
        result = np.zeros(len(X), bool)
        if len(X) == 1 and self._point_surely_inside(*X[0].tolist()):
            return result  # one point (a tracker's fit): plain Python, no numpy call overhead
        # no position is never outside, a position surely inside neither: the others need
        # the geometry library
        doubt = np.isfinite(X).all(axis=1) & ~self._surely_inside(X)
        if not doubt.any():
            return result
        import shapely

        X = X[doubt]
        sigma = np.broadcast_to(np.asarray(sigma, float), len(doubt))[doubt]
        fixed = np.isfinite(X).all(axis=1)
        slack = PLAUSIBLE_SIGMAS * np.where(np.isfinite(sigma), sigma, 0.0) \
            + ROOM_SLACK * self.ceiling_height
        z = np.where(fixed, X[:, 2], 0.0)
        out = (z < -slack) | (z > self.ceiling_height + slack)
        pts = shapely.points(np.where(fixed[:, None], X[:, :2], 0.0))
        away = shapely.distance(shapely.Polygon(self.room), pts)
        result[doubt] = fixed & (out | (away > slack))
        return result

    def _surely_inside(self, X):
        """Which positions (N×3) lie between floor and ceiling and inside the room's outline
        (an even–odd crossing count over its edges; a point on the outline may say no): such a
        point is never :meth:`outside`, whatever its error."""

        x, y, z = X[:, 0, None], X[:, 1, None], X[:, 2]
        a = np.asarray(self.room, float)
        b = a[np.arange(-1, len(a) - 1)]  # each edge from b, the vertex before, to a
        rise = b[:, 1] - a[:, 1]
        up = (a[:, 1] > y) != (b[:, 1] > y)  # the edge spans the point's y (never when level)
        # the point lies before the edge's crossing at its y: x − a_x < (y − a_y) run / rise,
        # times rise² (no division, so level edges and NaN positions need no warnings muted)
        before = ((x - a[:, 0]) * rise - (y - a[:, 1]) * (b[:, 0] - a[:, 0])) * rise < 0
        inside = (z >= 0.0) & (z <= self.ceiling_height)
        return inside & ((up & before).sum(axis=1) % 2 == 1)

    def _point_surely_inside(self, x: float, y: float, z: float) -> bool:
        """:meth:`_surely_inside` for one point, in plain Python (on one point, numpy's
        per-call overhead is most of the cost): the same even–odd count by the same products."""
        if not 0.0 <= z <= self.ceiling_height:
            return False
        odd = False
        bx, by = self.room[-1]
        for ax, ay in self.room:
            rise = by - ay
            if (ay > y) != (by > y) and ((x - ax) * rise - (y - ay) * (bx - ax)) * rise < 0:
                odd = not odd
            bx, by = ax, ay
        return odd

    def camera(self, camera_id: str) -> Camera:
        for cam in self.cameras:
            if cam.id == camera_id:
                return cam
        raise KeyError(camera_id)

    def to_dict(self) -> dict:
        doc = {
            "format": FORMAT, "version": VERSION,
            "site": {"name": self.name, "ceiling_height": float(self.ceiling_height),
                     "room": [[float(x), float(y)] for x, y in self.room],
                     "keep_out": [[[float(x), float(y)] for x, y in poly]
                                  for poly in self.keep_out]},
            "cameras": [c.to_dict() for c in self.cameras],
        }
        doc.update({k: v for k, v in self.extra.items() if k not in doc})
        return doc


#: m: the largest coordinate or length a file may state (100 km: larger is a unit mistake,
#: and squares of it must stay far from overflow)
MAX_LENGTH = 1e5
#: focal length as a multiple of the image width: from a 179° view to a 0.06° one
FOCAL_RANGE = (0.01, 1000.0)
#: |a distortion term at the image corner|: OpenCV's fits of real lenses stay well inside
MAX_DISTORTION = 1e3
#: a lens whose radial distortion turns back (r · (1 + k1 r² + …) stops growing) nearer the
#: centre than this share of the corner's radius images nothing there: not a lens
FOLD_SHARE = 0.5
#: the power of the corner's radius each of k1, k2, p1, p2, k3 multiplies
DISTORTION_POWERS = (2, 4, 1, 1, 6)
#: radians: the length of a rotation vector (one turn is 2π; a fit may wrap once more)
MAX_ROTATION = 4 * math.pi


def _number(value, where: str, *, positive: bool = False, integer: bool = False,
            within: tuple | None = None, unit: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeploymentError(f"{where}: expected a number, got {shown(value)}")
    try:
        finite = math.isfinite(value)
    except OverflowError:
        finite = False
    if not finite:
        raise DeploymentError(f"{where}: expected a finite number, got {str(value)[:20]}")
    if integer and int(value) != value:
        raise DeploymentError(f"{where}: expected a whole number, got {shown(value)}")
    if positive and value <= 0:
        raise DeploymentError(f"{where}: expected a positive number, got {shown(value)}")
    if within is not None and not within[0] <= value <= within[1]:
        raise DeploymentError(f"{where}: expected {within[0]:g} to {within[1]:g}{unit}, got "
                              f"{value:g}")
    return value


def _vector(value, n: int, where: str, within: tuple | None = None, unit: str = "") -> list:
    if not isinstance(value, (list, tuple)) or len(value) != n \
            or any(isinstance(v, (list, tuple, dict)) for v in value):
        raise DeploymentError(f"{where}: expected a list of {n} numbers, got {shown(value)}")
    return [_number(v, f"{where}[{i}]", within=within, unit=unit) for i, v in enumerate(value)]


#: a coordinate in metres, as the range checks state it
METRES = ((-MAX_LENGTH, MAX_LENGTH), " m")


def _polygon(value, where: str) -> list:
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise DeploymentError(f"{where}: expected a polygon of at least 3 [x, y] points, "
                              f"got {shown(value)}")
    pts = [_vector(p, 2, f"{where}[{i}]", *METRES) for i, p in enumerate(value)]
    from shapely.geometry import Polygon

    poly = Polygon(pts)
    if not poly.is_valid or poly.area <= 0:
        raise DeploymentError(f"{where}: expected a simple polygon with an area, "
                              "got one that crosses itself or is flat")
    return pts


def from_dict(doc, source: str = "<deployment>") -> Deployment:
    """Check a parsed document and build the :class:`Deployment` (errors name ``source``)."""

    def fail(msg):
        raise DeploymentError(f"{source}: {msg}")

    try:
        if not isinstance(doc, dict):
            kind = {"str": "a line of text", "list": "a list", "NoneType": "an empty file"}
            fail(f"not a vlpcal deployment (expected a YAML mapping with format: {FORMAT}; "
                 f"the file holds {kind.get(type(doc).__name__, type(doc).__name__)})")
        if doc.get("format") != FORMAT:
            fail(f"format: expected {shown(FORMAT)}, got {shown(doc.get('format'))}")
        if type(doc.get("version")) is not int or doc.get("version") != VERSION:
            fail(f"version: expected {VERSION}, got {shown(doc.get('version'))} (this vlpcal reads "
                 f"version {VERSION})")
        for key in ("site", "cameras"):
            if key not in doc:
                fail(f"{key}: missing")
        site = doc["site"]
        if not isinstance(site, dict):
            fail("site: expected a mapping")
        for key in ("name", "ceiling_height", "room"):
            if key not in site:
                fail(f"site.{key}: missing")
        if not isinstance(site["name"], str) or not site["name"].strip():
            fail(f"site.name: expected a non-empty text, got {shown(site['name'])}")
        height = _number(site["ceiling_height"], "site.ceiling_height", positive=True,
                         within=(0, MAX_LENGTH), unit=" m")
        room = _polygon(site["room"], "site.room")
        slip = room_slip(float(height), room)
        if slip:
            fail(slip)
        keep_out = site.get("keep_out")
        keep_out = [] if keep_out is None else keep_out
        if not isinstance(keep_out, list):
            fail("site.keep_out: expected a list of polygons")
        keep_out = [_polygon(p, f"site.keep_out[{i}]") for i, p in enumerate(keep_out)]
        cams_raw = doc["cameras"]
        if not isinstance(cams_raw, list) or not cams_raw:
            fail("cameras: expected a non-empty list of cameras")
        cameras, seen = [], set()
        for k, c in enumerate(cams_raw):
            where = f"cameras[{k}]"
            if not isinstance(c, dict):
                fail(f"{where}: expected a mapping")
            missing = [key for key in CAMERA_KEYS if key not in c]
            if missing:
                fail(f"{where}.{missing[0]}: missing")
            unknown = sorted(set(c) - set(CAMERA_KEYS))
            if unknown:
                fail(f"{where}.{unknown[0]}: unknown key (expected {', '.join(CAMERA_KEYS)})")
            cid = c["id"]
            if not is_id(cid):
                fail(f"{where}.id: expected a camera id ({ID_RULE}), got {shown(cid)}")
            cid = str(cid)
            if cid in seen:
                fail(f"{where}.id: duplicate camera id {shown(cid)}")
            seen.add(cid)
            check_intrinsics(c, where)
            z = c["position"][2] if isinstance(c["position"], list) \
                and len(c["position"]) == 3 else None
            if isinstance(z, (int, float)) and not isinstance(z, bool) and z > 10 * height:
                # (ten times the ceiling: a unit, not a fit that stood the cameras too high —
                # that one is said where it is made, as a plain bundle adjustment would keep it)
                fail(f"{where}.position[2]: {z:g} m above the floor under a {height:g} m "
                     f"ceiling: {slipped_units(z, lambda m: 0 < m <= 1.25 * height)} (metres "
                     "expected)")
            _near_the_room(_vector(c["position"], 3, f"{where}.position", *METRES), room,
                           height, f"{where}.position")
            rvec = _vector(c["rotation"], 3, f"{where}.rotation")
            if math.hypot(*rvec) > MAX_ROTATION:
                fail(f"{where}.rotation: expected a rotation vector (radians) up to 4π long, "
                     f"got one {math.hypot(*rvec):g} long")
            cameras.append(Camera.from_dict(c))
        unknown = sorted(set(site) - set(SITE_KEYS))
        if unknown:
            fail(f"site.{unknown[0]}: unknown key (expected {', '.join(SITE_KEYS)})")
        extra = {k: v for k, v in doc.items() if k not in ("format", "version", "site", "cameras")}
        for key in extra:
            if key not in OPTIONAL_BLOCKS:
                fail(f"{key}: unknown key (expected format, version, site, cameras, or the "
                     f"optional {', '.join(OPTIONAL_BLOCKS)})")
        _check_blocks(extra, {c.id for c in cameras}, room)
    except DeploymentError as e:
        if str(e).startswith(source):
            raise
        raise DeploymentError(f"{source}: {e}") from None
    return Deployment(str(site["name"]), float(height), room, cameras, keep_out, extra)


#: px: the largest image side a camera can send (a JPEG frame's limit)
MAX_IMAGE_SIDE = 65535


def check_intrinsics(c: dict, where: str) -> None:
    """Image size, focal lengths, principal point and distortion of a camera mapping (also
    the planner's camera model)."""
    for key in ("width", "height"):
        _number(c[key], f"{where}.{key}", positive=True, integer=True)
        if c[key] > MAX_IMAGE_SIDE:
            raise DeploymentError(f"{where}.{key}: expected an image side in pixels up to "
                                  f"{MAX_IMAGE_SIDE} (the largest a JPEG frame can have), got "
                                  f"{shown(c[key])}")
    w, h = c["width"], c["height"]
    for key in ("fx", "fy"):
        _number(c[key], f"{where}.{key}", positive=True,
                within=(FOCAL_RANGE[0] * w, FOCAL_RANGE[1] * w),
                unit=f" px ({FOCAL_RANGE[0]:g}× to {FOCAL_RANGE[1]:g}× the image width)")
    # a narrow view's principal point trades against its tilt (an offset of one focal length
    # is a 45° tilt): within one image of the image, or one focal length of its centre
    for key, side, f in (("cx", w, c["fx"]), ("cy", h, c["fy"])):
        reach = max(1.5 * side, f)
        _number(c[key], f"{where}.{key}", within=(side / 2 - reach, side / 2 + reach),
                unit=" px (the principal point within one image of the image, or one focal "
                     "length of its centre)")
    dist = _vector(c["dist"], 5, f"{where}.dist")
    # each term as it acts at the image corner: a narrow lens's k3 of 10⁵ bends its corner
    # less than a wide lens's k1 of 0.3 (r: the corner's radius in focal lengths)
    r = math.hypot(max(c["cx"], w - c["cx"]) / c["fx"], max(c["cy"], h - c["cy"]) / c["fy"])
    for i, (value, power) in enumerate(zip(dist, DISTORTION_POWERS)):
        if not abs(value) * r ** power <= MAX_DISTORTION:
            raise DeploymentError(
                f"{where}.dist[{i}]: expected a coefficient whose term at the image corner "
                f"(× r^{power}, r = {r:.3g}) is within -{MAX_DISTORTION:g} to "
                f"{MAX_DISTORTION:g}, got {shown(value)}")
    fold = math.sqrt(max_radius2(dist))
    if fold < FOLD_SHARE * r:
        raise DeploymentError(
            f"{where}.dist: expected a lens that images the middle of its picture, got one "
            f"whose distortion folds back at {fold / r:.1%} of the way to the image corner")


def _near_the_room(position, room, height: float, where: str) -> None:
    """A camera more than ten times the room's size away from it is a unit or sign mistake."""
    xs, ys = [p[0] for p in room], [p[1] for p in room]
    size = max(max(xs) - min(xs), max(ys) - min(ys), height)
    gap = max(min(xs) - position[0], position[0] - max(xs), min(ys) - position[1],
              position[1] - max(ys), -position[2], position[2] - height, 0.0)
    if gap > 10 * size:
        raise DeploymentError(f"{where}: {gap:g} m from the room (expected a camera within ten "
                              f"times the room's size, {10 * size:g} m, of it: a unit mistake?)")


def _mapping(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise DeploymentError(f"{where}: expected a mapping, got {shown(value)}")
    return value


def _choice(value, options, where: str) -> str:
    if value not in options:
        raise DeploymentError(f"{where}: expected one of {', '.join(options)}, got {shown(value)}")
    return value


def _check_blocks(extra: dict, camera_ids: set, room: list) -> None:
    """Check the optional blocks (see :data:`OPTIONAL_BLOCKS`; ``room``: the site's floor)."""
    if "detector" in extra:
        det = _mapping(extra["detector"], "detector")
        for key, value in det.items():
            if key == "method":
                _choice(value, DETECTORS, "detector.method")
            elif key in DETECTOR_SETTINGS:
                _number(value, f"detector.{key}", positive=key not in ("threshold",))
            else:
                raise DeploymentError(f"detector.{key}: unknown key (expected method, "
                                      f"{', '.join(DETECTOR_SETTINGS)})")
    if "fusion" in extra:
        fus = _mapping(extra["fusion"], "fusion")
        for key, value in fus.items():
            if key == "method":
                _choice(value, FUSIONS, "fusion.method")
            elif key == "pair_method":
                _choice(value, PAIR_METHODS, "fusion.pair_method")
            elif key == "max_residual":
                _number(value, "fusion.max_residual", positive=True)
            elif key == "region_map":
                if not isinstance(value, list):
                    raise DeploymentError("fusion.region_map: expected a list of "
                                          "{polygon, cameras} regions")
                for i, region in enumerate(value):
                    where = f"fusion.region_map[{i}]"
                    _mapping(region, where)
                    _polygon(region.get("polygon"), f"{where}.polygon")
                    ids = region.get("cameras")
                    if not isinstance(ids, list) or len(set(map(str, ids))) < 2:
                        raise DeploymentError(f"{where}.cameras: expected a list of at least 2 "
                                              f"camera ids, got {shown(ids)}")
                    for cid in ids:
                        if str(cid) not in camera_ids:
                            raise DeploymentError(f"{where}.cameras: unknown camera {shown(cid)}")
            else:
                raise DeploymentError(f"fusion.{key}: unknown key (expected method, "
                                      "pair_method, max_residual, region_map)")
    if "corrections" in extra:
        for cid, corr in _mapping(extra["corrections"], "corrections").items():
            where = f"corrections.{cid}"
            if str(cid) not in camera_ids:
                raise DeploymentError(f"{where}: unknown camera {shown(cid)}")
            for key, value in _mapping(corr, where).items():
                if key != "pixel_offset":
                    raise DeploymentError(f"{where}.{key}: unknown key (expected pixel_offset)")
                _vector(value, 2, f"{where}.pixel_offset")
    if "uncertainty" in extra:
        for key, value in _mapping(extra["uncertainty"], "uncertainty").items():
            if key != "pixel_noise":
                raise DeploymentError(f"uncertainty.{key}: unknown key (expected pixel_noise)")
            _number(value, "uncertainty.pixel_noise", positive=True)
    if "leds" in extra:
        _check_leds(extra["leds"])
    if "zones" in extra:
        _check_zones(extra["zones"], camera_ids, room)
    if "bodies" in extra:
        _check_bodies(extra["bodies"], {str(d["id"]) for d in extra.get("leds", [])})
    if "provenance" in extra:
        _mapping(extra["provenance"], "provenance")


ZONE_KEYS = ("id", "polygon", "cameras")
#: a zone's floor polygon has at most this many points
MAX_ZONE_POINTS = 1000
#: zones a site may be split into (a locator process each)
MAX_ZONES = 64
#: zones may part, or overlap, by a sliver at most this share of the room's larger side wide
#: (1 mm in a 10 m room: coordinates rounded); anything wider is a gap or an overlap
ZONE_SLACK = 1e-4


def _records(value, block: str, keys: tuple, noun: str, most: int | None = None):
    """A block that is a list of records with ids (``leds:``, ``zones:``): ``(where, record)``
    for each, its keys and id checked and each id given once."""
    if not isinstance(value, list) or not value or (most is not None and len(value) > most):
        count = f"1 to {most} " if most is not None else ""
        raise DeploymentError(f"{block}: expected a list of {count}{{{', '.join(keys)}}}, got "
                              f"{shown(value)}")
    seen = set()
    for i, d in enumerate(value):
        where = f"{block}[{i}]"
        _mapping(d, where)
        unknown = sorted(set(map(str, d)) - set(keys))
        if unknown:
            raise DeploymentError(f"{where}.{unknown[0]}: unknown key (expected "
                                  f"{', '.join(keys)})")
        for key in keys:
            if key not in d:
                raise DeploymentError(f"{where}.{key}: missing (expected {', '.join(keys)})")
        if not is_id(d["id"]):
            raise DeploymentError(f"{where}.id: expected {ID_RULE}, got {shown(d['id'])}")
        if str(d["id"]) in seen:
            raise DeploymentError(f"{block}: id {d['id']} given twice (expected each {noun} "
                                  "once)")
        seen.add(str(d["id"]))
        yield where, d


def _check_zones(value, camera_ids: set, room: list) -> None:
    """``zones:`` a list of ``{id, polygon, cameras}``: a site split among locator processes;
    a camera on a border belongs to both zones. The zones tile the room: each over part of its
    floor, none overlapping another, together covering it (up to :data:`ZONE_SLACK`), so that
    every fix in the room is one zone's to publish (docs/formats.md, the deployment file)."""
    ids, polygons = [], []
    for where, z in _records(value, "zones", ZONE_KEYS, "zone", MAX_ZONES):
        if isinstance(z["polygon"], list) and len(z["polygon"]) > MAX_ZONE_POINTS:
            raise DeploymentError(f"{where}.polygon: expected at most {MAX_ZONE_POINTS} points, "
                                  f"got {len(z['polygon'])}")
        polygons.append(_polygon(z["polygon"], f"{where}.polygon"))
        ids.append(str(z["id"]))
        cams = z["cameras"]
        if not isinstance(cams, list) or len(set(map(str, cams))) < 2:
            raise DeploymentError(f"{where}.cameras: expected a list of at least 2 camera ids, "
                                  f"got {shown(cams)}")
        for cid in cams:
            if str(cid) not in camera_ids:
                raise DeploymentError(f"{where}.cameras: unknown camera {shown(cid)}")
    _check_tiling(ids, polygons, room)


def _check_tiling(ids: list, polygons: list, room: list) -> None:
    """Zones ``ids`` with floor ``polygons`` (checked simple) tile the ``room``: none outside
    it, no two overlapping, no part of it in none — each judged by whether a part wider than
    :data:`ZONE_SLACK` of the room's size is left once every part is narrowed by it."""
    import shapely

    floor = shapely.Polygon(room)
    zones = np.array([shapely.Polygon(p) for p in polygons], dtype=object)
    x0, y0, x1, y1 = floor.bounds
    slack = ZONE_SLACK * max(x1 - x0, y1 - y0)

    def wide(geometry):
        """Which geometries hold a part wider than the slack (any: a point or a line none)."""
        return ~shapely.is_empty(shapely.buffer(geometry, -slack / 2))

    def where(geometry) -> str:
        x, y = shapely.get_coordinates(shapely.point_on_surface(geometry))[0]
        return f"around ({x:.3g}, {y:.3g})"

    inside = wide(shapely.intersection(zones, floor))
    if not inside.all():
        k = int(np.argmin(inside))
        raise DeploymentError(f"zones[{k}].polygon: zone {ids[k]} lies outside site.room "
                              "(expected a part of the room's floor: a zone there publishes "
                              "no fix)")
    a, b = shapely.STRtree(zones).query(zones, predicate="intersects")
    a, b = a[a < b], b[a < b]
    common = shapely.intersection(zones[a], zones[b])
    over = np.flatnonzero(wide(common))
    if len(over):
        k = over[0]
        area = shapely.area(common[k])
        raise DeploymentError(f"zones: {ids[a[k]]} and {ids[b[k]]} overlap over {area:.3g} m² "
                              f"{where(common[k])} (expected zones that meet along their "
                              "borders at most: a fix there would be published twice)")
    pieces = shapely.get_parts(shapely.difference(floor, shapely.union_all(zones)))
    pieces = pieces[wide(pieces)]
    if len(pieces):
        gap = pieces[np.argmax(shapely.area(pieces))]
        near = shapely.distance(zones, gap)
        around = [ids[k] for k in np.flatnonzero(near <= max(slack, near.min()))]
        area = float(shapely.area(pieces).sum())
        raise DeploymentError(f"zones: {area:.3g} m² of site.room ({area / floor.area:.2%}) in "
                              f"no zone, the most beside {' and '.join(around)} {where(gap)} "
                              "(expected zones that cover the room: a fix there would be "
                              "published by none)")


BODY_KEYS = ("id", "leds")
#: LEDs one body may carry
MAX_BODY_LEDS = 16


@dataclass(frozen=True)
class Body:
    """A rigid body (a robot) carrying several LEDs: each LED's position in the body's frame
    (m; x forward, y left, z up); its pose is the rotation and translation from that frame to
    the world's."""

    id: str
    leds: dict  #: LED id → position (3,) in the body's frame

    @property
    def full_pose(self) -> bool:
        """Whether its LEDs give the full pose (:func:`~vlpcal.bodies.gives_full_pose`)."""
        return gives_full_pose(list(self.leds.values()))

    def apart(self, a: str, b: str) -> float:
        """How far apart its LEDs ``a`` and ``b`` are, m."""
        return float(np.linalg.norm(np.subtract(self.leds[a], self.leds[b])))


def _check_bodies(value, led_ids: set) -> None:
    """``bodies:`` a list of ``{id, leds: {LED id: [x, y, z]}}``: rigid bodies carrying LEDs
    that ``leds:`` names; each LED on one body, at least two apart on each."""
    carried: dict = {}
    for where, b in _records(value, "bodies", BODY_KEYS, "body"):
        if str(b["id"]) in led_ids:
            raise DeploymentError(f"{where}.id: {b['id']} is also an LED's id in leds: (a "
                                  "body's rows and an LED's share the led column)")
        leds = _mapping(b["leds"], f"{where}.leds")
        if not 2 <= len(leds) <= MAX_BODY_LEDS:
            raise DeploymentError(f"{where}.leds: expected 2 to {MAX_BODY_LEDS} LEDs "
                                  f"({{LED id: [x, y, z]}}, m in the body's frame), got "
                                  f"{shown(b['leds'])}")
        points = []
        for led, pos in leds.items():
            if str(led) not in led_ids:
                raise DeploymentError(f"{where}.leds.{led}: not an LED of leds: (expected "
                                      f"{', '.join(sorted(led_ids)) or 'a leds: block'})")
            if str(led) in carried:
                raise DeploymentError(f"{where}.leds.{led}: already on body "
                                      f"{carried[str(led)]} (an LED rides one body)")
            carried[str(led)] = str(b["id"])
            points.append(_vector(pos, 3, f"{where}.leds.{led}", *METRES))
        p = np.array(points, float)
        size = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
        near = min(np.linalg.norm(p[i] - p[j]) for i in range(len(p))
                   for j in range(i + 1, len(p)))
        if not near > 1e-3 * max(size, 1e-12) or size == 0:
            raise DeploymentError(f"{where}.leds: two LEDs at the same place (expected them "
                                  "apart: their spread gives the body's heading)")
        flat = np.linalg.norm(p[:, :2] - p[:, :2].mean(axis=0), axis=1).max()
        if not flat > 1e-3 * size and not gives_full_pose(p):
            raise DeploymentError(f"{where}.leds: all on one vertical line (expected LEDs "
                                  "apart across the body: a vertical line has no heading)")


LED_KEYS = ("id", "pattern", "bit_rate")
#: LEDs a deployment may name (a frame is searched for as many spots)
MAX_LEDS = 64


def _check_leds(value) -> None:
    """``leds:`` a list of ``{id, pattern, bit_rate}``: the LEDs' blink codes."""
    codes = []
    for where, d in _records(value, "leds", LED_KEYS, "LED", MAX_LEDS):
        if not isinstance(d["pattern"], str):
            raise DeploymentError(f"{where}.pattern: expected a quoted string of 0 and 1, got "
                                  f"{shown(d['pattern'])} (YAML reads an unquoted 0101 as a "
                                  "number: write '0101')")
        rate = _number(d["bit_rate"], f"{where}.bit_rate", positive=True)
        if rate > 10000:
            raise DeploymentError(f"{where}.bit_rate: expected bits per second up to 10000, got "
                                  f"{shown(d['bit_rate'])}")
        codes.append(BlinkCode(str(d["id"]), d["pattern"], float(rate)))
    wrong = check_codes(codes)
    if wrong:
        raise DeploymentError(f"leds: {wrong}")


#: bytes: a deployment file is at most this large (a camera's line is ~250 bytes: thousands
#: of cameras fit), checked before the YAML parser reads it (its time and memory grow fast
#: with the file)
MAX_DEPLOYMENT_BYTES = 1 << 20


def load(path) -> Deployment:
    """Read and check a deployment file; :class:`DeploymentError` names what is wrong (a file
    larger than :data:`MAX_DEPLOYMENT_BYTES`, not UTF-8 YAML, with a key twice, nested too
    deep or full of aliases included: :mod:`.reading`)."""

    path, what = Path(path), "a deployment YAML file"
    try:
        doc = load_yaml(path, what, text=read_text(path, what, MAX_DEPLOYMENT_BYTES))
    except ReadError as e:
        raise DeploymentError(str(e)) from None
    return from_dict(doc, str(path))


def dumps(deployment: Deployment, header: str = "") -> str:
    """The deployment file's text (cameras one per flow-style line for reading), checked: a
    text that would not load is never returned."""
    doc = deployment.to_dict()
    from_dict(doc, f"{deployment.name} (not written)")
    cams = doc.pop("cameras")

    dumper = yaml_dumper()
    text = yaml.dump(doc, Dumper=dumper, sort_keys=False, default_flow_style=None)
    lines = ["cameras:"] + [
        "  - " + yaml.dump(c, Dumper=dumper, sort_keys=False, default_flow_style=True,
                           width=10_000).strip()
        for c in cams]
    out = text + "\n".join(lines) + "\n"
    if header:
        out = "".join(f"# {line}\n" for line in header.splitlines()) + out
    return out


def save(deployment: Deployment, path, header: str = "") -> None:
    """Write the deployment file (staged and renamed: :mod:`vlpcal.writing`)."""

    write_text(path, dumps(deployment, header))


def provenance(command: str, **fields) -> dict:
    """The provenance block every writer of a deployment adds: command, version, time, more."""

    return {"command": command, "vlpcal": __version__,
            "written": datetime.now(timezone.utc).isoformat(timespec="seconds"), **fields}

