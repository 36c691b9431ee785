"""The deployment file (DESIGN.md ``format: vlpcal-deployment``, ``version: 1``): load, check, save.

The one module that knows the file. Required keys exactly as DESIGN.md; every other top-level
block (detector settings, fusion policy, region maps, corrections, provenance) is optional and
kept as it was read (``Deployment.extra``), so a tool that does not know a block never drops it.
Errors name the file, the key path (``cameras[2].fx``) and what was expected
(:class:`DeploymentError`). Writes are atomic: a temporary file beside the target, then rename.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from .geometry import Camera

FORMAT, VERSION = "vlpcal-deployment", 1
CAMERA_KEYS = ("id", "width", "height", "fx", "fy", "cx", "cy", "dist", "position", "rotation")


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

    def camera(self, camera_id: str) -> Camera:
        for cam in self.cameras:
            if cam.id == camera_id:
                return cam
        raise KeyError(camera_id)

    def to_dict(self) -> dict:
        return {
            "format": FORMAT, "version": VERSION,
            "site": {"name": self.name, "ceiling_height": float(self.ceiling_height),
                     "room": [[float(x), float(y)] for x, y in self.room],
                     "keep_out": [[[float(x), float(y)] for x, y in poly]
                                  for poly in self.keep_out]},
            "cameras": [c.to_dict() for c in self.cameras],
            **self.extra,
        }


def _number(value, where: str, *, positive: bool = False, integer: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeploymentError(f"{where}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise DeploymentError(f"{where}: expected a finite number, got {value!r}")
    if integer and int(value) != value:
        raise DeploymentError(f"{where}: expected a whole number, got {value!r}")
    if positive and value <= 0:
        raise DeploymentError(f"{where}: expected a positive number, got {value!r}")
    return value


def _vector(value, n: int, where: str) -> list:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise DeploymentError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return [_number(v, f"{where}[{i}]") for i, v in enumerate(value)]


def _polygon(value, where: str) -> list:
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise DeploymentError(f"{where}: expected a polygon of at least 3 [x, y] points, "
                              f"got {value!r}")
    pts = [_vector(p, 2, f"{where}[{i}]") for i, p in enumerate(value)]
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
            fail(f"expected a mapping with format: {FORMAT}, got {type(doc).__name__}")
        if doc.get("format") != FORMAT:
            fail(f"format: expected {FORMAT!r}, got {doc.get('format')!r}")
        if doc.get("version") != VERSION:
            fail(f"version: expected {VERSION}, got {doc.get('version')!r} (this vlpcal reads "
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
        height = _number(site["ceiling_height"], "site.ceiling_height", positive=True)
        room = _polygon(site["room"], "site.room")
        keep_out = site.get("keep_out") or []
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
            cid = str(c["id"])
            if cid in seen:
                fail(f"{where}.id: duplicate camera id {cid!r}")
            seen.add(cid)
            for key in ("width", "height"):
                _number(c[key], f"{where}.{key}", positive=True, integer=True)
            for key in ("fx", "fy"):
                _number(c[key], f"{where}.{key}", positive=True)
            for key in ("cx", "cy"):
                _number(c[key], f"{where}.{key}")
            _vector(c["dist"], 5, f"{where}.dist")
            _vector(c["position"], 3, f"{where}.position")
            _vector(c["rotation"], 3, f"{where}.rotation")
            cameras.append(Camera.from_dict(c))
    except DeploymentError as e:
        if str(e).startswith(source):
            raise
        raise DeploymentError(f"{source}: {e}") from None
    extra = {k: v for k, v in doc.items() if k not in ("format", "version", "site", "cameras")}
    return Deployment(str(site["name"]), float(height), room, cameras, keep_out, extra)


def load(path) -> Deployment:
    """Read and check a deployment file; :class:`DeploymentError` names what is wrong."""
    import yaml

    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise DeploymentError(f"{path}: cannot read ({e.strerror})") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark else ""
        raise DeploymentError(f"{path}: not valid YAML{at}") from None
    return from_dict(doc, str(path))


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same folder and a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save(deployment: Deployment, path, header: str = "") -> None:
    """Write the deployment file atomically (cameras one per flow-style line for reading)."""
    import yaml

    doc = deployment.to_dict()
    cams = doc.pop("cameras")
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    lines = ["cameras:"] + [
        "  - " + yaml.safe_dump(c, sort_keys=False, default_flow_style=True, width=10_000).strip()
        for c in cams]
    body = text.split("\n", 2)  # format, version first
    out = "\n".join(body[:2]) + "\n" + body[2] + "\n".join(lines) + "\n"
    if header:
        out = "".join(f"# {line}\n" for line in header.splitlines()) + out
    atomic_write_text(path, out)
