"""The site file (``format: vlpcal-site``, ``version: 1``; docs/formats.md, "Site file"): a
room, a camera model and requirements, read as strictly as a deployment; and what the rest of
planning reads off a site: the floor to serve and a level camera's footprint on it.

shapely is imported inside the functions that draw polygons: importing planning for its types
(as the viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..deployment import (
    MAX_LENGTH,
    DeploymentError,
    _mapping,
    _number,
    _polygon,
    check_intrinsics,
)
from ..geometry import NADIR, Camera
from ..reading import (
    SLIP_UNITS,
    ReadError,
    load_yaml,
    room_sides,
    room_slip,
    shown,
    slipped_units,
)

FORMAT, VERSION = "vlpcal-site", 1
FAMILIES = ("linear", "triangular", "square", "free")
REQUIREMENT_KEYS = ("heights", "min_cameras", "coverage", "max_error_p95", "pixel_noise")
CAMERA_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "dist")
SITE_KEYS = ("name", "ceiling_height", "room", "keep_out")
MOUNTING_KEYS = ("max_tilt", "wall_clearance")
OBSTACLE_KEYS = ("polygon", "height")
#: degrees: the steepest tilt a site may allow (past it a ceiling camera looks at the walls)
TILT_LIMIT = 75.0
#: m: the reference model samples the floor on a grid this fine or finer (the format's
#: contract, "at most 10 cm"); a site must hold at least one such cell of floor
SAMPLE_STEP = 0.10


class SiteError(DeploymentError):
    """A site file that does not follow the format (one line: file, key path, expectation)."""


@dataclass
class Requirements:
    heights: tuple  #: LED heights served, m
    min_cameras: int = 2
    coverage: float = 0.99
    max_error_p95: float = 0.02  #: m
    pixel_noise: float = 0.3  #: px


@dataclass(frozen=True)
class CameraMounting:
    """How cameras may hang (the site file's ``mounting:``): tilted up to ``max_tilt`` from
    straight down, at least ``wall_clearance`` inside the walls."""

    max_tilt: float = 0.0  #: rad
    wall_clearance: float = 0.0  #: m


@dataclass(frozen=True)
class Obstacle:
    """A keep-out area that stands ``height`` m tall (a pillar, a shelf): it also hides what
    is behind it from a camera."""

    polygon: list
    height: float  #: m


@dataclass
class Site:
    """A room to plan for, the camera model to hang, and what the plan must achieve."""

    name: str
    ceiling_height: float
    room: list
    camera: Camera  #: the model; id, position and rotation are placeholders
    requirements: Requirements
    keep_out: list = field(default_factory=list)  #: floor polygons left out, obstacles too
    families: tuple = FAMILIES
    #: None: level cameras only (the plan then says what tilting would save)
    mounting: CameraMounting | None = None
    obstacles: list = field(default_factory=list)  #: Obstacle, the keep-outs with a height


def floor(room, keep_out):
    """The floor to serve: the room polygon minus the union of the keep-out areas (one union,
    so thousands of small keep-outs stay fast)."""
    from shapely import union_all
    from shapely.geometry import Polygon

    area = Polygon(room)
    if keep_out:
        area = area.difference(union_all([Polygon(p).buffer(0) for p in keep_out]))
    return area


def footprint(site: Site) -> tuple[float, float]:
    """Width and depth (m) of a nadir camera's view at the highest LED height: the scale that
    the mounting grid, the lattices' spacings and the sample grid are set against."""
    z = site.ceiling_height - max(site.requirements.heights)
    return site.camera.width / site.camera.fx * z, site.camera.height / site.camera.fy * z


def site_from_dict(doc, source: str = "<site>") -> Site:
    """Check a parsed site document (:class:`SiteError` names ``source`` and the key path)."""
    try:
        if not isinstance(doc, dict):
            raise SiteError(f"expected a mapping with format: {FORMAT}")
        if doc.get("format") != FORMAT:
            raise SiteError(f"format: expected {shown(FORMAT)}, got {shown(doc.get('format'))}")
        if type(doc.get("version")) is not int or doc.get("version") != VERSION:
            raise SiteError(f"version: expected {VERSION}, got {shown(doc.get('version'))}")
        unknown = sorted(set(doc) - {"format", "version", "site", "camera", "requirements",
                                     "families", "mounting"})
        if unknown:
            raise SiteError(f"{unknown[0]}: unknown key (expected format, version, site, "
                            "camera, requirements, families, mounting)")
        for key in ("site", "camera", "requirements"):
            if key not in doc:
                raise SiteError(f"{key}: missing")
        site = _mapping(doc["site"], "site")
        _only(site, SITE_KEYS, "site")
        for key in ("name", "ceiling_height", "room"):
            if key not in site:
                raise SiteError(f"site.{key}: missing")
        ceiling = _number(site["ceiling_height"], "site.ceiling_height", positive=True,
                          within=(0, MAX_LENGTH), unit=" m")
        room = _polygon(site["room"], "site.room")
        slip = room_slip(float(ceiling), room)
        if slip:  # a ceiling of 280 (cm meant) would plan a 280 m hall, not name the slip
            raise SiteError(slip)
        items = site.get("keep_out") or []
        if not isinstance(items, list):
            raise SiteError("site.keep_out: expected a list of polygons or {polygon, height} "
                            "obstacles")
        obstacles = [_obstacle(p, f"site.keep_out[{i}]", ceiling)
                     for i, p in enumerate(items)]
        keep_out = [o.polygon for o in obstacles]
        obstacles = [o for o in obstacles if o.height > 0]
        _check_floor(room, keep_out)
        mounting = _mounting(doc["mounting"], room) if "mounting" in doc else None
        cam = _mapping(doc["camera"], "camera")
        _only(cam, CAMERA_KEYS, "camera")
        absent = [key for key in CAMERA_KEYS if key not in cam]
        if absent:  # all at once: a camera block is often written from memory
            raise SiteError(f"camera.{absent[0]}: missing"
                            + (f" (and {', '.join(absent[1:])}; a camera needs "
                               f"{', '.join(CAMERA_KEYS)})" if len(absent) > 1 else ""))
        check_intrinsics(cam, "camera")
        req = _mapping(doc["requirements"], "requirements")
        _only(req, REQUIREMENT_KEYS, "requirements")
        for key in REQUIREMENT_KEYS:
            if key not in req:
                raise SiteError(f"requirements.{key}: missing")
        heights = req["heights"]
        if not isinstance(heights, list) or not heights:
            raise SiteError("requirements.heights: expected a list of LED heights, m")
        heights = [_number(h, f"requirements.heights[{i}]") for i, h in enumerate(heights)]
        if any(not 0 <= h < ceiling for h in heights):
            slip = "" if min(heights) < 0 else "; " + slipped_units(
                max(heights), lambda m: m < ceiling)
            raise SiteError(f"requirements.heights: expected heights from 0 to below the "
                            f"ceiling ({ceiling:g} m), got {shown(heights)}{slip}")
        min_cams = int(_number(req["min_cameras"], "requirements.min_cameras", positive=True,
                               integer=True))
        if min_cams < 2:
            raise SiteError("requirements.min_cameras: expected 2 or more (one camera cannot "
                            "give a 3D fix)")
        coverage = _number(req["coverage"], "requirements.coverage", positive=True)
        if coverage > 1:
            raise SiteError(f"requirements.coverage: expected a share from 0 to 1, "
                            f"got {coverage}")
        families = doc.get("families", list(FAMILIES))
        if not isinstance(families, list) or not families or \
                any(f not in FAMILIES for f in families):
            raise SiteError(f"families: expected a list of {', '.join(FAMILIES)}, "
                            f"got {shown(families)}")
        extent = max(max(p[k] for p in room) - min(p[k] for p in room) for k in (0, 1))
        p95 = float(_number(req["max_error_p95"], "requirements.max_error_p95", positive=True,
                            within=(0, extent), unit=" m (the room's size)"))
        longer, shorter = room_sides(room)
        scale = min(longer, float(ceiling))  # the room's size, along or up
        if p95 > scale / 4:  # an error a quarter of the room's size places nothing in it
            raise SiteError(f"requirements.max_error_p95: {p95:g} m in a room {longer:g} × "
                            f"{shorter:g} m under a {ceiling:g} m ceiling (an error "
                            f"{p95 / scale:.0%} of its size): "
                            f"{slipped_units(p95, lambda m: m <= scale / 4)} (metres expected)")
        noise = float(_number(req["pixel_noise"], "requirements.pixel_noise", positive=True))
        if not 1e-6 <= noise <= min(cam["width"], cam["height"]):
            raise SiteError(f"requirements.pixel_noise: expected a spot noise in px between "
                            f"1e-6 and the image's size, got {noise:g}")
        if not isinstance(site["name"], (str, int, float)):
            raise SiteError(f"site.name: expected a name (text), got {shown(site['name'])}")
    except DeploymentError as e:
        raise SiteError(f"{source}: {e}") from None
    camera = Camera("model", cam["width"], cam["height"], cam["fx"], cam["fy"], cam["cx"],
                    cam["cy"], cam["dist"], (0.0, 0.0, ceiling), NADIR)
    requirements = Requirements(tuple(heights), min_cams, float(coverage), p95, noise)
    return Site(str(site["name"]), float(ceiling), room, camera, requirements, keep_out,
                tuple(families), mounting, obstacles)


#: a room whose narrow side is this many times its ceiling may be real (a car park), but where
#: no plan fits it, a room written in centimetres under a ceiling in metres is worth asking
SIDE_PER_CEILING_DOUBT = 20.0


def unit_doubt(site: Site) -> str:
    """What a failed plan adds when the site's room is far wider than high (empty when it is
    not): the room may be in centimetres under a ceiling in metres."""
    longer, shorter = room_sides(site.room)
    ceiling = site.ceiling_height
    if shorter <= SIDE_PER_CEILING_DOUBT * ceiling:
        return ""
    units = " or ".join(name for name, k in SLIP_UNITS
                        if k * shorter <= SIDE_PER_CEILING_DOUBT * ceiling) or "another unit"
    return (f"; or is site.room ({longer:g} × {shorter:g} m, {shorter / ceiling:.0f} times "
            f"wider than the {ceiling:g} m ceiling is high) in {units}?")


def _obstacle(item, where: str, ceiling: float) -> Obstacle:
    """A keep-out item: a polygon (a floor area, height 0) or ``{polygon, height}``."""
    if not isinstance(item, dict):
        return Obstacle(_polygon(item, where), 0.0)
    _only(item, OBSTACLE_KEYS, where)
    if "polygon" not in item:
        raise SiteError(f"{where}.polygon: missing")
    height = item.get("height", 0.0)
    if isinstance(height, (int, float)) and not isinstance(height, bool) and \
            ceiling < height <= MAX_LENGTH:
        raise SiteError(f"{where}.height: {height:g} m, above the {ceiling:g} m ceiling: "
                        f"{slipped_units(height, lambda m: m <= ceiling)} (metres expected)")
    height = _number(height, f"{where}.height", within=(0, ceiling),
                     unit=f" m (from the floor to the ceiling, {ceiling:g} m)")
    return Obstacle(_polygon(item["polygon"], f"{where}.polygon"), float(height))


def _mounting(block, room) -> CameraMounting:
    """The ``mounting:`` block: a tilt in degrees up to :data:`TILT_LIMIT`, a clearance that
    leaves some ceiling to hang cameras from."""
    from shapely.geometry import Polygon

    block = _mapping(block, "mounting")
    _only(block, MOUNTING_KEYS, "mounting")
    tilt = _number(block.get("max_tilt", 0.0), "mounting.max_tilt", within=(0, TILT_LIMIT),
                   unit="° (from straight down)")
    clearance = _number(block.get("wall_clearance", 0.0), "mounting.wall_clearance",
                        within=(0, MAX_LENGTH), unit=" m")
    if clearance and Polygon(room).buffer(-clearance).is_empty:
        units = slipped_units(clearance, lambda m: not Polygon(room).buffer(-m).is_empty)
        raise SiteError(f"mounting.wall_clearance: {clearance:g} m from every wall leaves no "
                        f"ceiling to hang a camera from: {units} (metres expected)")
    return CameraMounting(math.radians(float(tilt)), float(clearance))


def _only(block: dict, keys, where: str) -> None:
    """Refuse a key the format does not have (a misspelling would otherwise be dropped)."""
    unknown = sorted(str(k) for k in set(block) - set(keys))
    if unknown:
        raise SiteError(f"{where}.{unknown[0]}: unknown key (expected {', '.join(keys)})")


def _check_floor(room, keep_out) -> None:
    """The room must be a simple polygon with floor left once the keep-out areas are cut."""
    from shapely.geometry import Polygon

    area = Polygon(room)
    if not area.is_valid or area.area <= 0:
        raise SiteError("site.room: expected a simple polygon (its edges must not cross)")
    for i, poly in enumerate(keep_out):
        if not Polygon(poly).buffer(0).intersects(area):
            raise SiteError(f"site.keep_out[{i}]: lies wholly outside the room (a typo, or "
                            "another unit?)")
    area = floor(room, keep_out)
    if area.is_empty or not area.area > 1e-9 * Polygon(room).area:
        raise SiteError("site.keep_out: the keep-out areas cover the whole room: no floor is "
                        "left to plan for")
    if area.area < SAMPLE_STEP ** 2:
        raise SiteError(f"site.room: less floor than one cell of the reference model's "
                        f"{SAMPLE_STEP * 100:g} cm grid (metres expected)")


def load_site(path) -> Site:
    """Read and check a site file (read within :mod:`vlpcal.reading`'s bounds)."""
    path = Path(path)
    try:
        doc = load_yaml(path, "a site YAML file")
    except ReadError as e:
        raise SiteError(str(e)) from None
    return site_from_dict(doc, str(path))
