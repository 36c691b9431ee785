"""Simulated data on disk in DESIGN.md's formats: survey bundles, ``locate`` frame folders and
deployment files (nominal, and the true cameras for evaluation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..datasets import write_frames_folder, write_survey_bundle, write_truth_csv
from ..deployment import Deployment, provenance, save
from .scene import ROBOT_RADIUS, STREAM_PATH, STREAM_TAPE, Scene, render_scene


def grid_points(scene: Scene, step: float, heights, margin: float = 0.05,
                min_cameras: int = 1) -> np.ndarray:
    """A grid of LED points over the room (``step`` m) at each height, kept where at least
    ``min_cameras`` true cameras see them: ``N×3``."""
    from shapely import contains_xy
    from shapely.geometry import Polygon

    room = Polygon(scene.profile.room).buffer(-margin)
    x0, y0, x1, y1 = room.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[contains_xy(room, xy[:, 0], xy[:, 1])]
    pts = np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in heights])
    seen = np.stack([c.project(pts, margin=1.0)[2] for c in scene.true]).sum(axis=0)
    return pts[seen >= min_cameras]


def trajectory(scene: Scene, n: int, height: float = 0.15, seed: int = 0) -> np.ndarray:
    """A robot's LED path: a smooth closed loop inside the room at ``height`` (``n×3``)."""
    from shapely.geometry import Polygon

    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH])
    x0, y0, x1, y1 = Polygon(scene.profile.room).buffer(-0.3).bounds
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    a, b = rng.uniform(1, 3, 2).round()
    phase = rng.uniform(0, 2 * np.pi)
    x = (x0 + x1) / 2 + (x1 - x0) / 2 * 0.9 * np.sin(a * t + phase)
    y = (y0 + y1) / 2 + (y1 - y0) / 2 * 0.9 * np.sin(b * t)
    return np.c_[x, y, np.full(n, height)]


def free_path(scene: Scene, n: int, height: float | None = None, seed: int = 0
              ) -> np.ndarray:
    """A free survey's LED (``n×3``): a person sweeping the room with the LED on a pole, up
    and down between the floor and 40 % of the ceiling's height — or, with ``height``, a robot
    driving the room at that height. Both wander over the whole floor (a Lissajous figure with
    incommensurate frequencies, jittered, as a hand or a planner would)."""
    from shapely.geometry import Polygon

    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH, 2])
    x0, y0, x1, y1 = Polygon(scene.profile.room).buffer(-0.1).bounds
    t = np.linspace(0, 1, n)
    fx, fy, fz = 7.0, 7.0 * np.sqrt(2) + rng.uniform(-0.3, 0.3), 23.0 * np.sqrt(3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    x = (x0 + x1) / 2 + (x1 - x0) / 2 * np.sin(2 * np.pi * fx * t + phase[0])
    y = (y0 + y1) / 2 + (y1 - y0) / 2 * np.sin(2 * np.pi * fy * t + phase[1])
    xy = np.c_[x, y] + rng.normal(0, 0.02 * min(x1 - x0, y1 - y0), (n, 2))
    xy = np.clip(xy, [x0, y0], [x1, y1])
    if height is None:
        top = 0.4 * scene.profile.ceiling_height
        z = top * (0.5 + 0.5 * np.sin(2 * np.pi * fz * t + phase[2]))
    else:
        z = np.full(n, float(height))
    return np.c_[xy, z]


def simulate_free_survey(scene: Scene, root, references, n_free: int, seed: int = 0,
                         height: float | None = None, overwrite: bool = False,
                         carrier_radius: float | None = None):
    """A free survey bundle (issue 15): the ``references`` (true positions) taped to
    ± ``profile.tape`` per axis with their frames, and ``n_free`` free sets of the LED moved
    along :func:`free_path` (its positions unrecorded, as in life; a robot's body hides the
    floor under its LED, ``carrier_radius``, by default :data:`~.scene.ROBOT_RADIUS`).
    Returns (measured references, the free path's true positions)."""
    refs = np.asarray(references, float)
    path = free_path(scene, n_free, height, seed)
    if carrier_radius is None:
        carrier_radius = 0.0 if height is None else ROBOT_RADIUS
    carrier = np.r_[np.zeros(len(refs)), np.full(len(path), carrier_radius)]
    frames, seen = render_scene(scene, np.vstack([refs, path]), seed=seed,
                                carrier_radius=carrier)
    rng = np.random.default_rng([scene.seed, seed, STREAM_TAPE])
    measured = refs + rng.normal(0.0, scene.profile.tape, refs.shape)
    n = len(refs)
    kept = {cid: [f if s else None for f, s in zip(jpegs, seen[k])]
            for k, (cid, jpegs) in enumerate(frames.items())}
    write_survey_bundle(root, [f"R{i + 1:02d}" for i in range(n)], measured,
                        {c: v[:n] for c, v in kept.items()}, overwrite=overwrite,
                        free_frames={c: v[n:] for c, v in kept.items()},
                        free_ids=[f"F{i + 1:05d}" for i in range(n_free)])
    return measured, path


def deployment_of(scene: Scene, which: str = "nominal") -> Deployment:
    """The scene's ``nominal`` (what the installer believes) or ``true`` cameras as a file."""
    p = scene.profile
    cams = list(scene.nominal if which == "nominal" else scene.true)
    prov = provenance("vlpcal simulate", profile=p.name, seed=scene.seed, cameras=which)
    return Deployment(f"{p.name}-sim", p.ceiling_height, [list(xy) for xy in p.room], cams,
                      extra={"provenance": prov})


def write_deployments(scene: Scene, out) -> tuple[Path, Path]:
    """``nominal.yaml`` (to calibrate) and ``truth.yaml`` (to evaluate against) in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = out / "nominal.yaml", out / "truth.yaml"
    save(deployment_of(scene, "nominal"), paths[0],
         header=f"Simulated {scene.profile.name} install (seed {scene.seed}): the cameras as "
                "the installer believes them.")
    save(deployment_of(scene, "true"), paths[1],
         header=f"Simulated {scene.profile.name} install (seed {scene.seed}): the cameras as "
                "they really are (for evaluation only).")
    return paths


def simulate_survey(scene: Scene, root, points, seed: int = 0, overwrite: bool = False):
    """Render a survey at ``points`` (true positions) and write the bundle; ``points.csv``
    records the positions as a tape measure would give them (± ``profile.tape`` per axis).
    Returns the measured positions."""
    points = np.asarray(points, float)
    frames, seen = render_scene(scene, points, seed=seed)
    rng = np.random.default_rng([scene.seed, seed, STREAM_TAPE])
    measured = points + rng.normal(0.0, scene.profile.tape, points.shape)
    ids = [f"S{i + 1:04d}" for i in range(len(points))]
    kept = {cid: [f if s else None for f, s in zip(jpegs, seen[k])]
            for k, (cid, jpegs) in enumerate(frames.items())}
    write_survey_bundle(root, ids, measured, kept, overwrite=overwrite)
    return measured


def simulate_frames(scene: Scene, root, points, seed: int = 0, overwrite: bool = False):
    """Render a ``locate`` frames folder (every camera sends a frame for every instant) and
    write ``truth.csv`` beside it (``<root>.truth.csv``)."""
    points = np.asarray(points, float)
    frames, _ = render_scene(scene, points, seed=seed)
    ids = [f"{i:06d}" for i in range(len(points))]
    root = Path(root)
    write_frames_folder(root, ids, frames, overwrite=overwrite)
    write_truth_csv(root.with_name(root.name + ".truth.csv"), ids, points)
    return ids
