"""The built-in demo: a simulated install of the paper's rig, every pipeline on the same frames.

A first version of ``vlpcal demo``: simulates the paper's lab (``paper-2024`` profile: the
cameras as really hung differ slightly from the plan), renders JPEG frames of an LED at a grid
of positions and two heights, and runs the paper's pipeline (NI-P spots, pair method, fusion
(a) and (b)) beside vlpcal's (blob spots, robust all-camera least squares) with the *nominal*
cameras, then with the cameras calibrated from a simulated survey (a grid of other points at
three heights, tape-measured), and given the true cameras — the floor calibration aims for.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .detection import detect_spots
from .fusion import fuse
from .sim.profiles import get_profile
from .sim.scene import make_scene, render_scene
from .sim.writers import grid_points
from .survey import calibrate

#: (label, detector, fusion, which cameras)
PIPELINES = (
    ("paper: NI-P + pairs (a) mean", "nip", "mean", "nominal"),
    ("paper: NI-P + pairs (b) nearest", "nip", "nearest", "nominal"),
    ("vlpcal: blob + robust LS", "blob", "robust", "nominal"),
    ("vlpcal, calibrated from a survey", "blob", "robust", "calibrated"),
    ("vlpcal, cameras known exactly", "blob", "robust", "true"),
)


@dataclass
class Row:
    label: str
    mean_cm: float
    median_cm: float
    p90_cm: float
    fix_rate: float
    us_per_fix: float


def run_demo(seed: int = 0, step: float = 0.15) -> tuple[list[Row], int]:
    """Simulate, render once, run every pipeline; returns the table rows and N positions."""
    scene = make_scene(get_profile("paper-2024"), seed)
    X = grid_points(scene, step, (0.0, 0.35), min_cameras=2) + [0.011, 0.013, 0.0]
    frames, _ = render_scene(scene, X, seed=seed)
    cams = {"nominal": list(scene.nominal), "true": list(scene.true),
            "calibrated": _calibrated(scene, seed)}
    rows = []
    for label, detector, fusion, which in PIPELINES:
        t0 = time.perf_counter()
        uv = np.stack([detect_spots(frames[c.id], detector).uv for c in scene.nominal])
        res = fuse(cams[which], uv, fusion)
        dt = time.perf_counter() - t0
        err = np.linalg.norm(res.X - X, axis=1) * 100
        ok = np.isfinite(err)
        rows.append(Row(label, float(np.mean(err[ok])), float(np.median(err[ok])),
                        float(np.percentile(err[ok], 90)), float(ok.mean()),
                        dt / len(X) * 1e6))
    return rows, len(X)


def _calibrated(scene, seed: int) -> list:
    """The cameras as a survey calibrates them: a grid at three heights (not the test
    positions), tape-measured to ±3 mm, frames rendered, spots found, lens and pose fitted."""
    survey = grid_points(scene, 0.25, (0.0, 0.35, 0.7))
    frames, _ = render_scene(scene, survey, seed=seed + 1000)
    measured = survey + np.random.default_rng(seed).normal(0, scene.profile.tape, survey.shape)
    uv = np.stack([detect_spots(frames[c.id]).uv for c in scene.nominal])
    ids = [f"S{i + 1:04d}" for i in range(len(survey))]
    return calibrate(list(scene.nominal), measured, uv, ids, intrinsics=True).cameras


def format_table(rows: list[Row]) -> str:
    head = f"{'pipeline':34s} {'mean':>7s} {'median':>7s} {'p90':>7s} {'fixed':>6s} {'µs/fix':>7s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.label:34s} {r.mean_cm:6.2f}  {r.median_cm:6.2f}  {r.p90_cm:6.2f}  "
                     f"{100 * r.fix_rate:5.1f}% {r.us_per_fix:7.1f}")
    return "\n".join(lines)
