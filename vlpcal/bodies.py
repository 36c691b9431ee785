"""A rigid body's pose from its LEDs' rays at their own capture times.

Motion capture tracks rigid bodies: several markers on one object give its pose. Here a body
carries LEDs at known places in its frame (the deployment's ``bodies:``), and each camera
frame's spot of one of them is a ray at that frame's time. Over a short window the body's
origin follows a quadratic path (as one LED's does in :mod:`vlpcal.tracking`) and so does its
heading (a robot's turn quickens and slows as its path bends); its pitch and roll hold. All
of them are fitted at once to every ray of every LED of the body in the window, by
Gauss–Newton in pixels: no two rays need to be simultaneous, nor of one LED, nor from one
camera, so a body is placed even when each of its LEDs is seen by a different camera at a
different moment. Two LEDs (or LEDs on one line) give the position and heading of a level
body; three or more not on one line the full pose.

Angles are Z-Y-X (yaw about z, then pitch about y, then roll about x), body to world:
``X_world = position + R(yaw, pitch, roll) · X_body``.
"""

from __future__ import annotations

import math

import numpy as np

#: Gauss–Newton steps at most, and the step (in each unknown's own sigma) that ends them
ITERATIONS, CONVERGED = 12, 1e-3


def rotation(yaw, pitch=0.0, roll=0.0) -> np.ndarray:
    """Z-Y-X angles (rad; arrays of one shape S) → rotations S×3×3, body to world."""
    yaw, pitch, roll = np.broadcast_arrays(*(np.asarray(a, float) for a in (yaw, pitch, roll)))
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        np.stack([-sp, cp * sr, cp * cr], -1)], -2)


def angles(R) -> np.ndarray:
    """A rotation (3×3, body to world) → its Z-Y-X angles (yaw, pitch, roll), rad."""
    R = np.asarray(R, float)
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    return np.array([math.atan2(R[1, 0], R[0, 0]), pitch, math.atan2(R[2, 1], R[2, 2])])


def gives_full_pose(points) -> bool:
    """Whether LEDs at ``points`` (K×3, a body's frame) give its full pose: three or more, not
    on one line (judged against their own spread); else its heading only, taken as level."""
    p = np.asarray(points, float)
    if len(p) < 3:
        return False
    spread = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return bool(spread[1] > 1e-3 * spread[0])


def pose_from_points(body_points, world_points) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motion taking a body's LEDs (K×3, body frame) to where they were seen (K×3,
    world): (position, angles). Two points (or points on one line): the heading alone, the
    body level (Kabsch's fit of the turn about z); more: the full rotation (Kabsch)."""
    B, W = np.asarray(body_points, float), np.asarray(world_points, float)
    bc, wc = B.mean(axis=0), W.mean(axis=0)
    if gives_full_pose(B):
        U, _, Vt = np.linalg.svd((W - wc).T @ (B - bc))
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
        R = U @ D @ Vt
        ang = angles(R)
    else:
        b, w = (B - bc)[:, :2], (W - wc)[:, :2]
        yaw = math.atan2(float(np.sum(b[:, 0] * w[:, 1] - b[:, 1] * w[:, 0])),
                         float(np.sum(b[:, 0] * w[:, 0] + b[:, 1] * w[:, 1])))
        ang = np.array([yaw, 0.0, 0.0])
        R = rotation(yaw)
    return wc - R @ bc, ang


def _derivatives(yaw, pitch, roll):
    """dR/dyaw, dR/dpitch, dR/droll (each S×3×3) of :func:`rotation`."""
    h = 1e-6
    return [(rotation(*(a + h * (k == i) for k, a in enumerate((yaw, pitch, roll))))
             - rotation(*(a - h * (k == i) for k, a in enumerate((yaw, pitch, roll))))) / (2 * h)
            for i in range(3)]


def fit_pose(rows, y, tau, axis, along, ff, led_points, guess, full: bool,
             acceleration: float, spin: float, pixel_sigma: float, prior=None):
    """Gauss–Newton over a window's rays of a body's LEDs: M equations (two per ray) —
    ``rows`` M×3 and ``y`` M (``rows · X = y`` for the LED's world position X on the ray),
    ``tau`` M (the ray's time from the fit's), ``axis`` M×3 and ``along`` M (its camera's
    optical axis and axis·centre: the depth), ``ff`` M (f over the spot noise), ``led_points``
    M×3 (the ray's LED in the body's frame) — for the body's origin at ``t + τ``, ``a + b τ +
    c τ² / 2`` (its acceleration held to ``acceleration``), its yaw ``ψ + ω τ + α τ² / 2``
    (``α`` held to ``spin``, rad/s²: a turn's rate changes as its path bends), and (``full``)
    its pitch and roll. ``guess``: the 14 unknowns to start from (position, velocity,
    acceleration, yaw, yaw rate, pitch, roll, yaw acceleration); ``prior``: (14 values, 14
    informations — 0: none), the body's state before, joined as equations. Returns (the 14
    unknowns, RMS residual px, their covariance 14×14 — pitch and roll held at the guess's,
    their variance 0, when not ``full`` — and each equation's residual in spot sigmas), or
    (None, inf, None, None) when the rays do not determine them."""
    q = np.array(guess, float)
    free = np.arange(14) if full else np.r_[0:11, 13]
    n_free = len(free)
    P = tau[:, None] ** np.arange(3.0) * np.array([1.0, 1.0, 0.5])  # M×3
    A_pos = (P[:, :, None] * rows[:, None, :]).reshape(len(rows), 9)
    D = np.zeros(14)
    D[6:9] = 1.0 / acceleration ** 2
    D[13] = 1.0 / spin ** 2
    centre = np.zeros(14)
    if prior is not None:
        centre = np.array(prior[0], float)
        D = D + np.asarray(prior[1], float)
    D = D[free]
    cov = None
    J = np.empty((len(rows), 14))
    for _ in range(ITERATIONS):
        yaw = q[9] + q[10] * tau + q[13] * P[:, 2]
        R = rotation(yaw, q[11], q[12])  # M×3×3
        Rb = np.einsum("mij,mj->mi", R, led_points)
        X = P @ q[:9].reshape(3, 3) + Rb  # the LED at each ray's time
        depth = np.einsum("mi,mi->m", axis, X) - along
        if not (depth > 0).all():
            return None, np.inf, None, None
        w = ff / depth
        r = (np.einsum("mi,mi->m", rows, X) - y) * w
        dR = _derivatives(yaw, q[11], q[12])
        dyaw = np.einsum("mi,mij,mj->m", rows, dR[0], led_points)
        J[:, :9] = A_pos
        J[:, 9] = dyaw
        J[:, 10] = dyaw * tau
        J[:, 13] = dyaw * P[:, 2]
        if full:
            J[:, 11] = np.einsum("mi,mij,mj->m", rows, dR[1], led_points)
            J[:, 12] = np.einsum("mi,mij,mj->m", rows, dR[2], led_points)
        Jf = J[:, free] * w[:, None]
        N = Jf.T @ Jf
        N.flat[::n_free + 1] += D
        dq = q - centre
        dq[9] = math.remainder(dq[9], 2 * math.pi)  # the yaw's, the short way round
        g = Jf.T @ r + D * dq[free]
        try:
            cov = np.linalg.inv(N)
        except np.linalg.LinAlgError:
            return None, np.inf, None, None
        inflation = np.diag(cov) * np.diag(N)
        if not (np.isfinite(inflation).all() and (inflation < 1e12).all()):
            return None, np.inf, None, None
        step = -cov @ g
        q[free] += step
        if np.all(np.abs(step) <= CONVERGED * np.sqrt(np.maximum(np.diag(cov), 1e-300))):
            break
    yaw = q[9] + q[10] * tau + q[13] * P[:, 2]
    X = P @ q[:9].reshape(3, 3) + np.einsum("mij,mj->mi", rotation(yaw, q[11], q[12]),
                                            led_points)
    depth = np.einsum("mi,mi->m", axis, X) - along
    if not (depth > 0).all():
        return None, np.inf, None, None
    r = (np.einsum("mi,mi->m", rows, X) - y) * ff / depth
    full_cov = np.zeros((14, 14))
    full_cov[np.ix_(free, free)] = cov
    q[9] = math.remainder(q[9], 2 * math.pi)
    return q, float(pixel_sigma * np.sqrt(r @ r / len(r))), full_cov, r
