"""A ceiling camera's pose as an installer sets it: where it hangs (x, y), its yaw about the
vertical and its tilt, a horizontal rotation vector (wx, wy) whose length is the angle from
straight down. Poses are rows ``n×5`` (:data:`POSE`); the optimiser works on them, cameras
are made from them, and they snap to what a bracket can be set to."""

from __future__ import annotations

import math

import numpy as np

from ..geometry import NADIR, Camera, rodrigues, rotation_vector
from .site import Site

POSE = ("x", "y", "yaw", "wx", "wy")
#: rad: yaw, tilt and tilt direction are set in steps of this (a protractor's 5°)
ANGLE_STEP = math.radians(5.0)


def rotation(yaw: float, wx: float, wy: float) -> np.ndarray:
    """World → camera rotation: the level camera turned by ``yaw`` about the vertical, then
    its body tilted by the horizontal rotation vector (wx, wy) (as
    :func:`.families.ceiling_cameras` for w = 0)."""
    level = rodrigues(NADIR) @ rodrigues((0.0, 0.0, float(yaw))).T
    return level @ rodrigues((float(wx), float(wy), 0.0)).T


def posed_cameras(site: Site, poses) -> list[Camera]:
    """Cameras of the site's model on the ceiling at ``poses`` (n×5), named C1, C2, …"""
    m = site.camera
    out = []
    for k, (x, y, yaw, wx, wy) in enumerate(np.asarray(poses, float).reshape(-1, 5)):
        out.append(Camera(f"C{k + 1}", m.width, m.height, m.fx, m.fy, m.cx, m.cy, m.dist,
                          (round(float(x), 6), round(float(y), 6), site.ceiling_height),
                          rotation_vector(rotation(yaw, wx, wy))))
    return out


def pose_of(camera: Camera) -> np.ndarray:
    """The pose (5) of a ceiling camera: the tilt from its optical axis, the yaw from what is
    left once the tilt is undone."""
    d = camera.axis
    h = math.hypot(d[0], d[1])
    theta = camera.tilt
    w = (theta * d[1] / h, -theta * d[0] / h) if h > 1e-12 else (0.0, 0.0)
    # R = N·Rz(yaw)ᵀ·Q(w)ᵀ  ⇒  Rz(yaw)ᵀ = Nᵀ·R·Q(w)
    Rz = (rodrigues(NADIR).T @ camera.R @ rodrigues((w[0], w[1], 0.0))).T
    return np.array([camera.position[0], camera.position[1], math.atan2(Rz[1, 0], Rz[0, 0]),
                     w[0], w[1]])


def tilts(poses) -> np.ndarray:
    """rad: each pose's angle from straight down."""
    poses = np.asarray(poses, float).reshape(-1, 5)
    return np.hypot(poses[:, 3], poses[:, 4])


def snapped(poses, step: float, max_tilt: float, x0: float = 0.0, y0: float = 0.0):
    """Poses as an installer sets them: positions on the mounting grid (multiples of ``step``
    from (x0, y0)), yaw, tilt and the tilt's direction in :data:`ANGLE_STEP` steps, the tilt
    within ``max_tilt``."""
    p = np.asarray(poses, float).reshape(-1, 5).copy()
    p[:, 0] = x0 + np.round((p[:, 0] - x0) / step) * step
    p[:, 1] = y0 + np.round((p[:, 1] - y0) / step) * step
    p[:, 2] = np.round(np.mod(p[:, 2], 2 * math.pi) / ANGLE_STEP) * ANGLE_STEP
    theta = np.minimum(np.round(tilts(p) / ANGLE_STEP) * ANGLE_STEP,
                       math.floor(max_tilt / ANGLE_STEP + 1e-9) * ANGLE_STEP)
    phi = np.round(np.arctan2(p[:, 4], p[:, 3]) / ANGLE_STEP) * ANGLE_STEP
    p[:, 3], p[:, 4] = theta * np.cos(phi), theta * np.sin(phi)
    return p
