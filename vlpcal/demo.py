"""The built-in demo: the paper's three-camera rig, simulated frames, every pipeline compared.

A first version of ``vlpcal demo``: renders JPEG frames of an LED at a grid of points and
heights as the paper's three cameras would see them, then runs the paper's pipeline (NI-P spots,
pair method, fusion (a) and (b)) beside vlpcal's (blob detector, all-camera least squares) on the
same frames and prints one table. The cameras are known exactly here; calibration comes later.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .detection import detect_spots
from .fusion import fuse
from .geometry import paper_rig
from .sim import Sensor, SpotLook, render_views

#: (label, detector, fusion, pair method)
PIPELINES = (
    ("paper: NI-P + pairs (a) mean", "nip", "mean", "paper"),
    ("paper: NI-P + pairs (b) nearest", "nip", "nearest", "paper"),
    ("vlpcal: blob + pairs (b) nearest", "blob", "nearest", "paper"),
    ("vlpcal: blob + all-camera LS", "blob", "all", "paper"),
)


@dataclass
class Row:
    label: str
    mean_cm: float
    median_cm: float
    p90_cm: float
    fix_rate: float
    us_per_fix: float


def demo_points(step: float = 0.15, heights=(0.0, 0.35)) -> np.ndarray:
    """LED test points: a grid over the area the paper's pairs share, at each height."""
    xs = np.arange(0.75, 2.85 + 1e-9, step)
    ys = np.arange(0.30, 1.50 + 1e-9, step)
    gx, gy = np.meshgrid(xs, ys)
    return np.concatenate([np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, h)] for h in heights])


def run_demo(seed: int = 0, step: float = 0.15) -> tuple[list[Row], int]:
    """Render the frames once, run every pipeline on them; returns the table rows and N."""
    cams = paper_rig()
    X = demo_points(step)
    frames = render_views(cams, X, look=SpotLook(0.9, 170.0), sensor=Sensor(), seed=seed)
    rows = []
    for label, detector, fusion, pair_method in PIPELINES:
        t0 = time.perf_counter()
        spots = [detect_spots(frames[c.id], detector) for c in cams]
        uv = np.stack([s.uv for s in spots])
        res = fuse(cams, uv, fusion, pair_method=pair_method)
        dt = time.perf_counter() - t0
        err = np.linalg.norm(res.X - X, axis=1) * 100
        ok = np.isfinite(err)
        rows.append(Row(label, float(np.mean(err[ok])), float(np.median(err[ok])),
                        float(np.percentile(err[ok], 90)), float(ok.mean()),
                        dt / len(X) * 1e6))
    return rows, len(X)


def format_table(rows: list[Row]) -> str:
    head = f"{'pipeline':34s} {'mean':>7s} {'median':>7s} {'p90':>7s} {'fixed':>6s} {'µs/fix':>7s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.label:34s} {r.mean_cm:6.2f}  {r.median_cm:6.2f}  {r.p90_cm:6.2f}  "
                     f"{100 * r.fix_rate:5.1f}% {r.us_per_fix:7.1f}")
    return "\n".join(lines)
