"""Layout planning: the site file, the reference accuracy/coverage model, the grid families.

The site file (DESIGN.md ``format: vlpcal-site``, ``version: 1``) states a room, a camera model
and requirements; the *reference model* (DESIGN.md, the contract) judges a layout: a sample
point is seen by a camera when it projects inside the image (2 px margin) in front of it; the
predicted error of a point seen by ≥ 2 cameras is ``sqrt(trace(F⁻¹))``, ``F = Σ JᵢᵀJᵢ / σ²``;
a layout meets the requirements when at least ``coverage`` of the sample points are seen by
``min_cameras`` cameras and the 95th percentile of their predicted error is within
``max_error_p95``. Sample points: the room minus keep-out areas on a grid of at most 10 cm, at
the lowest, middle and highest LED height.

The optimiser that searches the families is the next step; :func:`evaluate` is the independent
check every plan must pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .deployment import (
    Deployment,
    DeploymentError,
    _mapping,
    _number,
    _polygon,
    check_intrinsics,
    provenance,
)
from .geometry import NADIR, Camera, rodrigues, rotation_vector
from .triangulation import predicted_rms_error

FORMAT, VERSION = "vlpcal-site", 1
FAMILIES = ("linear", "triangular", "square")
REQUIREMENT_KEYS = ("heights", "min_cameras", "coverage", "max_error_p95", "pixel_noise")
CAMERA_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "dist")
SITE_KEYS = ("name", "ceiling_height", "room", "keep_out")
#: weight of the surrogate's penalty on covered points whose error exceeds the requirement
PENALTY = 0.5
#: sample grid spacing of the reference model, m (DESIGN.md: at most 10 cm)
SAMPLE_STEP = 0.10
#: px: a point is seen when it projects at least this far inside the image
MARGIN_PX = 2.0


class SiteError(DeploymentError):
    """A site file that does not follow the format (one line: file, key path, expectation)."""


@dataclass
class Requirements:
    heights: tuple  #: LED heights served, m
    min_cameras: int = 2
    coverage: float = 0.99
    max_error_p95: float = 0.02  #: m
    pixel_noise: float = 0.3  #: px


@dataclass
class Site:
    """A room to plan for, the camera model to hang, and what the plan must achieve."""

    name: str
    ceiling_height: float
    room: list
    camera: Camera  #: the model; id, position and rotation are placeholders
    requirements: Requirements
    keep_out: list = field(default_factory=list)
    families: tuple = FAMILIES


def site_from_dict(doc, source: str = "<site>") -> Site:
    """Check a parsed site document (:class:`SiteError` names ``source`` and the key path)."""
    try:
        if not isinstance(doc, dict):
            raise SiteError(f"expected a mapping with format: {FORMAT}")
        if doc.get("format") != FORMAT:
            raise SiteError(f"format: expected {FORMAT!r}, got {doc.get('format')!r}")
        if type(doc.get("version")) is not int or doc.get("version") != VERSION:
            raise SiteError(f"version: expected {VERSION}, got {doc.get('version')!r}")
        unknown = sorted(set(doc) - {"format", "version", "site", "camera", "requirements",
                                     "families"})
        if unknown:
            raise SiteError(f"{unknown[0]}: unknown key (expected format, version, site, "
                            "camera, requirements, families)")
        for key in ("site", "camera", "requirements"):
            if key not in doc:
                raise SiteError(f"{key}: missing")
        site = _mapping(doc["site"], "site")
        _only(site, SITE_KEYS, "site")
        for key in ("name", "ceiling_height", "room"):
            if key not in site:
                raise SiteError(f"site.{key}: missing")
        ceiling = _number(site["ceiling_height"], "site.ceiling_height", positive=True)
        room = _polygon(site["room"], "site.room")
        keep_out = [_polygon(p, f"site.keep_out[{i}]")
                    for i, p in enumerate(site.get("keep_out") or [])]
        _check_floor(room, keep_out)
        cam = _mapping(doc["camera"], "camera")
        _only(cam, CAMERA_KEYS, "camera")
        for key in CAMERA_KEYS:
            if key not in cam:
                raise SiteError(f"camera.{key}: missing")
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
            raise SiteError(f"requirements.heights: expected heights from 0 to below the "
                            f"ceiling ({ceiling:g} m), got {heights}")
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
                            f"got {families!r}")
    except DeploymentError as e:
        raise SiteError(f"{source}: {e}") from None
    camera = Camera("model", cam["width"], cam["height"], cam["fx"], cam["fy"], cam["cx"],
                    cam["cy"], cam["dist"], (0.0, 0.0, ceiling), NADIR)
    requirements = Requirements(tuple(heights), min_cams, float(coverage),
                                float(_number(req["max_error_p95"], "requirements.max_error_p95",
                                              positive=True)),
                                float(_number(req["pixel_noise"], "requirements.pixel_noise",
                                              positive=True)))
    return Site(str(site["name"]), float(ceiling), room, camera, requirements, keep_out,
                tuple(families))


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
    for poly in keep_out:
        area = area.difference(Polygon(poly).buffer(0))
    if area.is_empty or area.area <= 1e-9 * Polygon(room).area:
        raise SiteError("site.keep_out: the keep-out areas cover the whole room: no floor is "
                        "left to plan for")


def load_site(path) -> Site:
    """Read and check a site file."""
    import yaml

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise SiteError(f"{path}: cannot read ({e.strerror})") from None
    except (UnicodeDecodeError, yaml.YAMLError):
        raise SiteError(f"{path}: not a YAML text file") from None
    return site_from_dict(doc, str(path))


# -- the reference model ---------------------------------------------------------------------------

def sample_points(site: Site, step: float = SAMPLE_STEP) -> np.ndarray:
    """The reference model's sample points ``N×3``: the room minus keep-out areas on a square
    grid (``step`` ≤ 10 cm, cell centres), at the lowest, middle (halfway between the lowest
    and the highest) and highest LED height."""
    from shapely import contains_xy
    from shapely.geometry import Polygon

    area = Polygon(site.room)
    for poly in site.keep_out:
        area = area.difference(Polygon(poly))
    x0, y0, x1, y1 = area.bounds
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[contains_xy(area, xy[:, 0], xy[:, 1])]
    hs = site.requirements.heights
    levels = sorted({min(hs), (min(hs) + max(hs)) / 2, max(hs)})  # lowest, halfway, highest
    return np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in levels])


@dataclass
class Evaluation:
    """A layout judged by the reference model."""

    coverage: float  #: share of sample points seen by ≥ min_cameras cameras
    p95: float  #: m, 95th percentile of the predicted error over those points
    mean: float  #: m, mean predicted error over those points
    meets: bool
    points: np.ndarray  #: the sample points N×3
    views: np.ndarray  #: N, cameras that see each point
    error: np.ndarray  #: N, predicted RMS error (m; NaN where < 2 cameras)


def evaluate(site: Site, cameras: list[Camera], step: float = SAMPLE_STEP) -> Evaluation:
    """Judge a layout with the reference model (DESIGN.md), independently of any optimiser."""
    pts = sample_points(site, step)
    seen = np.stack([c.project(pts, margin=MARGIN_PX)[2] for c in cameras]) if cameras \
        else np.zeros((0, len(pts)), bool)
    views = seen.sum(axis=0)
    err = predicted_rms_error(cameras, pts, seen, site.requirements.pixel_noise) if cameras \
        else np.full(len(pts), np.nan)
    ok = views >= site.requirements.min_cameras
    coverage = float(ok.mean()) if len(pts) else 0.0
    p95 = float(np.percentile(err[ok], 95)) if ok.any() else math.inf
    mean = float(np.mean(err[ok])) if ok.any() else math.inf
    r = site.requirements
    return Evaluation(coverage, p95, mean, coverage >= r.coverage and p95 <= r.max_error_p95,
                      pts, views, err)


# -- grid families ---------------------------------------------------------------------------------

def grid_cameras(site: Site, family: str, nx: int, ny: int, spacing: tuple, origin: tuple,
                 rotation: float = 0.0, drop: float = 0.0, yaw: float = 0.0) -> list[Camera]:
    """Cameras of a grid family, nadir, hung ``drop`` m below the ceiling.

    ``linear``: one row of ``nx`` (``ny`` ignored); ``square``: ``nx × ny`` with spacings
    (a, b) (a = b for a square lattice); ``triangular``: rows ``b = a·√3/2`` apart, every other
    row shifted by a/2. The grid is rotated by ``rotation`` (rad) about ``origin`` (its first
    camera); each camera also turns by ``yaw`` about the vertical (0 or 90° matters for a
    160 × 120 image).
    """
    a = spacing[0]
    b = spacing[1] if len(spacing) > 1 else a
    pos = []
    if family == "linear":
        pos = [(i * a, 0.0) for i in range(nx)]
    elif family == "square":
        pos = [(i * a, j * b) for j in range(ny) for i in range(nx)]
    elif family == "triangular":
        b = a * math.sqrt(3) / 2
        pos = [(i * a + (a / 2 if j % 2 else 0.0), j * b) for j in range(ny) for i in range(nx)]
    else:
        raise ValueError(f"unknown family {family!r}; expected one of {', '.join(FAMILIES)}")
    c, s = math.cos(rotation), math.sin(rotation)
    z = site.ceiling_height - drop
    # the nadir camera turned by (rotation + yaw) about the world's vertical:
    # x_cam = R_nadir · Rz(θ)ᵀ · (X − C), so image-right points along Rz(θ)·x
    rvec = rotation_vector(rodrigues(NADIR) @ rodrigues((0.0, 0.0, rotation + yaw)).T)
    out = []
    for k, (px, py) in enumerate(pos):
        x = origin[0] + c * px - s * py
        y = origin[1] + s * px + c * py
        out.append(Camera(f"C{k + 1}", site.camera.width, site.camera.height, site.camera.fx,
                          site.camera.fy, site.camera.cx, site.camera.cy, site.camera.dist,
                          (x, y, z), rvec))
    return out


# -- exhaustive search (the baseline the optimiser must match) ------------------------------------

@dataclass
class Candidate:
    """A layout of one family with its parameters and its verdict under the reference model."""

    family: str
    nx: int
    ny: int
    spacing: tuple  #: m, (a,) or (a, b)
    origin: tuple  #: m, the first camera's floor position
    yaw: float  #: rad
    cameras: list
    evaluation: Evaluation

    @property
    def count(self) -> int:
        return len(self.cameras)


def footprint(site: Site) -> tuple[float, float]:
    """Width and depth (m) of a nadir camera's view at the highest LED height."""
    z = site.ceiling_height - max(site.requirements.heights)
    return site.camera.width / site.camera.fx * z, site.camera.height / site.camera.fy * z


def shapes(family: str, n: int) -> list[tuple[int, int]]:
    """The (nx, ny) arrangements of ``n`` cameras a family allows."""
    if family == "linear":
        return [(n, 1)]
    return [(nx, n // nx) for nx in range(1, n + 1) if n % nx == 0 and n // nx >= 2 and nx >= 2]


def arrangements(site: Site, n: int):
    """Every (family, nx, ny, yaw) of ``n`` cameras worth trying: the site's families, their
    shapes, yaw 0° and 90°, kept by :func:`promising`."""
    for family in site.families:
        for nx, ny in shapes(family, n):
            for yaw in (0.0, math.pi / 2):
                if promising(site, family, nx, ny, yaw):
                    yield family, nx, ny, yaw


def lower_bound(site: Site) -> int:
    """Fewest cameras worth trying: k footprints' worth of the covered area at the highest
    LED height."""
    from shapely.geometry import Polygon

    fw, fd = footprint(site)
    r = site.requirements
    return max(2, math.ceil(r.min_cameras * r.coverage * Polygon(site.room).area / (fw * fd)))


def promising(site: Site, family: str, nx: int, ny: int, yaw: float) -> bool:
    """Whether an arrangement can meet the coverage at all (a cheap closed-form screen,
    FIELD-NOTES): on an axis-aligned lattice a point's camera count is columns × rows seeing
    it, so covering the room once needs nx footprints across and ny along, and k cameras
    need k-fold cover along at least one axis (10 % slack for the coverage share)."""
    from shapely.geometry import Polygon

    fw, fd = footprint(site)
    if yaw:
        fw, fd = fd, fw
    x0, y0, x1, y1 = Polygon(site.room).bounds
    lx, ly = x1 - x0, y1 - y0
    rows = 1 if family == "linear" else ny
    k = site.requirements.min_cameras
    once = nx * fw >= 0.9 * lx and rows * fd >= 0.9 * ly
    k_fold = nx * fw >= 0.9 * k * lx or rows * fd >= 0.9 * k * ly
    return once and k_fold


def mountable(site: Site, cameras: list[Camera]) -> list[Camera]:
    """The cameras that can hang from the ceiling: inside the room polygon (keep-out areas are
    floor obstacles, not ceiling bans); renamed C1, C2, … in order."""
    from dataclasses import replace as _replace

    from shapely import contains_xy
    from shapely.geometry import Polygon

    room = Polygon(site.room).buffer(1e-9)
    xy = np.array([c.position[:2] for c in cameras])
    inside = contains_xy(room, xy[:, 0], xy[:, 1]) if len(xy) else np.zeros(0, bool)
    kept = [c for c, ok in zip(cameras, inside) if ok]
    return [_replace(c, id=f"C{k + 1}") for k, c in enumerate(kept)]


def exhaustive_search(site: Site, n: int, steps: int = 8, offsets: int = 5,
                      screen_step: float = 0.2) -> list[Candidate]:
    """Every layout of ``n`` cameras over a grid of spacings (``steps`` values from 0.3 to 1.0
    footprint) and offsets (``offsets`` × ``offsets`` shifts within a spacing), both yaws
    (0°, 90°), for each of the site's families; screened on a coarse sample grid, the
    promising ones judged by :func:`evaluate`. Returns the candidates that meet the
    requirements, best predicted p95 first."""
    from itertools import product

    from shapely.geometry import Polygon

    x0, y0, x1, y1 = Polygon(site.room).bounds
    grid = np.linspace(0.3, 1.0, steps)
    found = []
    for family, nx, ny, yaw in arrangements(site, n):
        fw, fd = footprint(site)
        if yaw:
            fw, fd = fd, fw
        for fa, fb in product(grid, grid if family == "square" else [None]):
            a = fa * fw
            b = fb * fd if fb is not None else (a * math.sqrt(3) / 2
                                                 if family == "triangular" else 0.0)
            span_x = (nx - 1) * a + (a / 2 if family == "triangular" and ny > 1 else 0.0)
            cx0 = (x0 + x1 - span_x) / 2
            cy0 = (y0 + y1 - (ny - 1) * b) / 2
            spacing = (a, b) if family == "square" else (a,)
            shifts_x = np.linspace(-a / 2, a / 2, offsets) if nx > 1 else [0.0]
            shifts_y = np.linspace(-b / 2, b / 2, offsets) if ny > 1 and b else [0.0]
            for dx, dy in product(shifts_x, shifts_y):
                origin = (cx0 + dx, cy0 + dy)
                cams = mountable(site, grid_cameras(site, family, nx, ny, spacing, origin,
                                                    yaw=yaw))
                if not evaluate(site, cams, screen_step).meets:
                    continue
                ev = evaluate(site, cams)
                if ev.meets:
                    found.append(Candidate(family, nx, ny, spacing, origin, yaw, cams, ev))
    return sorted(found, key=lambda c: c.evaluation.p95)


# -- the optimiser ----------------------------------------------------------------------------

def optimise_layout(site: Site, family: str, nx: int, ny: int, yaw: float,
                    starts: int = 3, screen_step: float = 0.2) -> Candidate | None:
    """Spacing(s) and offset of one grid arrangement by CasADi/IPOPT on smooth surrogates,
    then judged by the reference model (:func:`evaluate`): the best start, passing or not
    (cameras that would hang outside the room are left out). None if IPOPT gave nothing.

    Surrogates (nadir cameras, the site's camera model): a camera sees a sample point with
    weight σ(k·(half-width·Z − |d|)) per image axis, a point is covered with
    σ(8·(Σ weights − (min_cameras − ½))), and its predicted error is sqrt(trace(F⁻¹)) with F
    built from those weights. On an axis-aligned lattice every sum separates into a sum over
    columns times a sum over rows (FIELD-NOTES), so the surrogate costs O(cameras × (columns
    + rows)) per height, not O(cameras × points): large rooms stay fast. A triangular lattice
    is two such lattices (even and odd rows). The objective rewards soft coverage and
    penalises covered points whose error exceeds the requirement; the steepness rises
    20 → 60 m⁻¹ with warm starts; ``starts`` initial spacings.
    """
    import casadi as ca
    from shapely import contains_xy
    from shapely.geometry import Polygon

    def sig(x):  # the logistic function without overflow (tanh form)
        return 0.5 * (1 + ca.tanh(x / 2))

    r = site.requirements
    cam = site.camera
    area = Polygon(site.room)
    for poly in site.keep_out:
        area = area.difference(Polygon(poly))
    x0, y0, x1, y1 = Polygon(site.room).bounds
    xs = np.arange(x0 + screen_step / 2, x1, screen_step)
    ys = np.arange(y0 + screen_step / 2, y1, screen_step)
    gx, gy = np.meshgrid(xs, ys)
    mask = contains_xy(area, gx.ravel(), gy.ravel()).reshape(gx.shape).astype(float)
    mask_dm = ca.DM(mask)
    total = float(mask.sum())
    hs = r.heights
    levels = sorted({min(hs), (min(hs) + max(hs)) / 2, max(hs)})
    hw = (cam.width / 2 - 0.5 - MARGIN_PX) / cam.fx
    hh = (cam.height / 2 - 0.5 - MARGIN_PX) / cam.fy
    if yaw:
        hw, hh = hh, hw
    fw, fd = footprint(site)
    if yaw:
        fw, fd = fd, fw
    rows = ny if family != "linear" else 1
    # row groups of one shift each: (shift in spacings, row indices)
    groups = [(0.0, list(range(rows)))] if family != "triangular" else \
        [(0.0, list(range(0, rows, 2))), (0.5, list(range(1, rows, 2)))]
    groups = [g for g in groups if g[1]]

    opti = ca.Opti()
    a = opti.variable()
    b = opti.variable() if family == "square" else (a * math.sqrt(3) / 2
                                                    if family == "triangular" else 0.0)
    dx, dy = opti.variable(), opti.variable()
    k_vis = opti.parameter()
    span_x = (nx - 1 + (0.5 if family == "triangular" and rows > 1 else 0.0)) * a
    span_y = (rows - 1) * b
    ox = (x0 + x1) / 2 - span_x / 2 + dx
    oy = (y0 + y1) / 2 - span_y / 2 + dy
    xs_row = ca.DM(xs).T  # 1 × Mx
    ys_col = ca.DM(ys)  # My × 1
    objective = 0
    for h in levels:
        Z = site.ceiling_height - h
        c = (cam.fx / Z) ** 2 / r.pixel_noise ** 2
        count = 0
        F00 = F02 = F12 = F22 = 0
        for shift, js in groups:
            Sx = [0, 0, 0]
            for i in range(nx):
                d = xs_row - (ox + (i + shift) * a)
                v = sig(k_vis * (hw * Z - d)) * sig(k_vis * (hw * Z + d))
                Sx = [Sx[0] + v, Sx[1] + v * d / Z, Sx[2] + v * (d / Z) ** 2]
            Sy = [0, 0, 0]
            for j in js:
                d = ys_col - (oy + j * b)
                v = sig(k_vis * (hh * Z - d)) * sig(k_vis * (hh * Z + d))
                Sy = [Sy[0] + v, Sy[1] + v * d / Z, Sy[2] + v * (d / Z) ** 2]
            n00 = ca.mtimes(Sy[0], Sx[0])  # My × Mx: Σ weights
            count = count + n00
            F00 = F00 + c * n00
            F02 = F02 + c * ca.mtimes(Sy[0], Sx[1])
            F12 = F12 + c * ca.mtimes(Sy[1], Sx[0])
            F22 = F22 + c * (ca.mtimes(Sy[0], Sx[2]) + ca.mtimes(Sy[2], Sx[0]))
        eps = 1e-6
        F00, F22 = F00 + eps, F22 + eps
        # F = [[F00, 0, F02], [0, F00, F12], [F02, F12, F22]]
        det = F00 * (F00 * F22 - F12 ** 2) - F02 * (F00 * F02)
        tr_inv = ((F00 * F22 - F12 ** 2) + (F00 * F22 - F02 ** 2) + F00 ** 2) / det
        err = ca.sqrt(tr_inv + 1e-12)
        covered = sig(8 * (count - (r.min_cameras - 0.5)))
        x = 8 * (err / r.max_error_p95 - 1)
        excess = (ca.fmax(x, 0) + ca.log1p(ca.exp(-ca.fabs(x)))) / 8  # softplus, no overflow
        objective = objective - ca.sum1(ca.sum2(mask_dm * covered)) / total \
            + PENALTY * ca.sum1(ca.sum2(mask_dm * covered * excess)) / total
    opti.minimize(objective / len(levels))
    opti.subject_to(opti.bounded(0.2 * fw, a, 1.2 * fw))
    if family == "square":
        opti.subject_to(opti.bounded(0.2 * fd, b, 1.2 * fd))
    opti.subject_to(opti.bounded(-fw, dx, fw))
    opti.subject_to(opti.bounded(-fd, dy, fd))
    opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                          "ipopt.max_iter": 150,
                          "ipopt.hessian_approximation": "limited-memory"})
    best = None
    for s0 in np.linspace(0.5, 0.9, starts):
        opti.set_initial(a, s0 * fw)
        if family == "square":
            opti.set_initial(b, s0 * fd)
        opti.set_initial(dx, 0.0)
        opti.set_initial(dy, 0.0)
        try:
            for k in (20.0, 60.0):
                opti.set_value(k_vis, k)
                sol = opti.solve()
                opti.set_initial(sol.value_variables())
            va = float(sol.value(a))
            vb = float(sol.value(b)) if family == "square" else None
            vdx, vdy = float(sol.value(dx)), float(sol.value(dy))
        except RuntimeError:
            try:  # IPOPT stopped early (iterations): its last point is still worth judging
                va = float(opti.debug.value(a))
                vb = float(opti.debug.value(b)) if family == "square" else None
                vdx, vdy = float(opti.debug.value(dx)), float(opti.debug.value(dy))
            except RuntimeError:
                continue
        bb = vb if vb is not None else (va * math.sqrt(3) / 2 if family == "triangular"
                                        else 0.0)
        spacing = (va, vb) if family == "square" else (va,)
        sx = (nx - 1 + (0.5 if family == "triangular" and rows > 1 else 0.0)) * va
        origin = ((x0 + x1) / 2 - sx / 2 + vdx, (y0 + y1) / 2 - (rows - 1) * bb / 2 + vdy)
        cams = mountable(site, grid_cameras(site, family, nx, ny, spacing, origin, yaw=yaw))
        ev = evaluate(site, cams, screen_step)  # a quick look; the full model if promising
        if ev.coverage >= r.coverage - 0.02 and ev.p95 <= 1.1 * r.max_error_p95:
            ev = evaluate(site, cams)
        cand = Candidate(family, nx, ny, spacing, origin, yaw, cams, ev)
        if best is None or _rank(cand) < _rank(best):
            best = cand
    return best


def _rank(c: Candidate) -> tuple:
    """Passing layouts first (fewer cameras, then lower p95), then the closest to passing."""
    ev = c.evaluation
    return (0, c.count, ev.p95) if ev.meets else (1, -ev.coverage, ev.p95)


@dataclass
class Plan:
    """The result of planning: ranked candidates at the fewest cameras that meet the site's
    requirements (empty when none up to ``max_cameras`` does), and the best seen otherwise."""

    candidates: list  # Candidate, best p95 first
    tried: int  # arrangements optimised
    seconds: float
    closest: Candidate | None = None  # when nothing meets: the best coverage seen


def plan_site(site: Site, max_cameras: int = 60, starts: int = 3, progress=None) -> Plan:
    """The fewest cameras that meet the requirements: for each count from a lower bound up, every
    family and arrangement (nx × ny) and both yaws, spacing and offset by
    :func:`optimise_layout`, each result judged by :func:`evaluate`; the first count with a
    passing layout ends the search and its candidates are ranked by predicted p95."""
    import time


    t0 = time.perf_counter()
    tried, closest = 0, None
    for n in range(lower_bound(site), max_cameras + 1):
        found = []
        for family, nx, ny, yaw in arrangements(site, n):
            tried += 1
            c = optimise_layout(site, family, nx, ny, yaw, starts)
            if c is None:
                continue
            if c.evaluation.meets:
                found.append(c)
            elif closest is None or _rank(c) < _rank(closest):
                closest = c
        if progress and next(arrangements(site, n), None):
            progress(n)
        if found:
            return Plan(sorted(found, key=_rank), tried, time.perf_counter() - t0)
    return Plan([], tried, time.perf_counter() - t0, closest)


def planned_deployment(site: Site, cand: Candidate, rank: int = 1, source: str = "") -> Deployment:
    """The deployment file of a planned layout, with its predicted figures in the provenance
    (so that the survey can later report planned against achieved)."""
    ev, r = cand.evaluation, site.requirements
    prov = provenance(
        "vlpcal plan", **{"from": {"site": str(source)}},
        plan={"family": cand.family, "grid": [cand.nx, cand.ny],
              "spacing_m": [float(v) for v in cand.spacing],
              "origin_m": [float(v) for v in cand.origin],
              "yaw_rad": float(cand.yaw), "rank": rank},
        predicted={"coverage": ev.coverage, "mean_error_m": ev.mean, "p95_error_m": ev.p95,
                   "model": "reference model (docs/formats.md)", "pixel_noise_px": r.pixel_noise})
    return Deployment(site.name, site.ceiling_height, site.room, cand.cameras, site.keep_out,
                      {"uncertainty": {"pixel_noise": r.pixel_noise}, "provenance": prov})
