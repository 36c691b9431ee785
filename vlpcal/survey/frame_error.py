"""How precisely frame marks fix the frame, predicted from the cameras alone.

A wand survey's frame is where the LED stood on its marks (``O``: all three coordinates, ``X``:
its y and z, each floor mark: its z). Each mark is triangulated from the views that see it,
with an error that does not average out over a resting LED's frames (the spot's sub-pixel
bias; a mark seen by two cameras whose rays meet at a narrow angle is known poorly in depth)
and the calibrated cameras' own error where it stands, which more views do not shrink.
The frame is the rigid motion that best puts the marks on their recorded coordinates, so its
error is a weighted least-squares error: ``(Σ Aᵀ W A)⁻¹`` over the marks' recorded
coordinates. What a user lives with is that error carried to the fixes: the mean over the
zone of ``trace(B Σ Bᵀ)``, ``B = [−[q]×, I]`` the motion's effect on a point ``q``.
"""

from __future__ import annotations

import numpy as np

#: a mark's error that more views do not average away — the calibrated cameras' own error
#: where it stands — as this many times its spot's, at the nearest view's pixel footprint
#: (chosen on the wand benchmark, seeds 0–2: 0 crowds the floor marks where three cameras
#: overlap and loses on the widest lens, 3 keeps their lever and wins on every profile)
NETWORK_SHARE = 3.0


def mark_covariances(cameras, P, views) -> np.ndarray:
    """``N×3×3`` covariance of each point triangulated from the views that see it (``views``
    C×N), per px² of spot error, plus :data:`NETWORK_SHARE` px of isotropic error at the
    nearest view's pixel footprint; a point seen once has an unbounded depth (the
    pseudo-inverse of its information)."""
    info = np.zeros((len(P), 3, 3))
    foot = np.full(len(P), np.inf)
    for cam, seen in zip(cameras, views):
        J = np.nan_to_num(cam.jacobian(P))
        info += np.where(seen[:, None, None], np.einsum("nki,nkj->nij", J, J), 0.0)
        far = np.linalg.norm(P - cam.center, axis=1) / cam.fx
        foot = np.where(seen, np.minimum(foot, far), foot)
    foot = np.where(np.isfinite(foot), foot, 0.0)
    return np.linalg.pinv(info, hermitian=True) \
        + (NETWORK_SHARE * foot)[:, None, None] ** 2 * np.eye(3)


def _rows(P, axes) -> np.ndarray:
    """``N×K×6``: the derivative of the chosen coordinates (``axes``, K indices into x, y, z) of
    points ``P`` (N×3) with respect to a small rotation and translation ``(ω, t)``."""
    n = len(P)
    B = np.zeros((n, 3, 6))
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    # ω × p = −[p]× ω
    B[:, 0, 1], B[:, 0, 2] = z, -y
    B[:, 1, 0], B[:, 1, 2] = -z, x
    B[:, 2, 0], B[:, 2, 1] = y, -x
    B[:, :, 3:] = np.eye(3)
    return B[:, list(axes)]


def mark_information(P, cov, axes) -> np.ndarray:
    """``N×6×6``: what each mark at ``P`` (covariance ``cov`` N×3×3) adds to the frame's
    information through its recorded coordinates ``axes``."""
    A = _rows(P, axes)
    S = cov[:, list(axes)][:, :, list(axes)]
    return np.einsum("nki,nkl,nlj->nij", A, np.linalg.pinv(S, hermitian=True), A)


def roles_information(Q, cov, across: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What each place (``Q`` N×3 from the origin, ``cov`` N×3×3) would add to the frame's
    information as ``O`` (all three coordinates recorded), as ``X`` (``across``, the
    horizontal coordinate across O→X, and z) and as a floor mark (z): three N×6×6."""
    return (mark_information(Q, cov, (0, 1, 2)), mark_information(Q, cov, (across, 2)),
            mark_information(Q, cov, (2,)))


def zone_weight(zone) -> np.ndarray:
    """``6×6`` mean of ``BᵀB`` over the zone's points (M×3): ``trace(Σ · this)`` is the mean
    squared displacement the frame's error ``Σ`` gives a fix there."""
    B = _rows(np.asarray(zone, float), (0, 1, 2))
    return np.einsum("mki,mkj->ij", B, B) / len(B)


def frame_errors(info, weight) -> np.ndarray:
    """Mean squared displacement over the zone (``weight``, :func:`zone_weight`) for each
    candidate frame information ``…×6×6``; infinite where the marks leave a motion free."""
    w, V = np.linalg.eigh(info)  # symmetric: its spectrum gives both the test and the inverse
    ok = np.isfinite(w).all(axis=-1) & (w[..., 0] > 1e-12 * w[..., -1])
    out = np.full(info.shape[:-2], np.inf)
    if ok.any():
        inv = np.einsum("nik,nk,njk->nij", V[ok], 1.0 / w[ok], V[ok])
        out[ok] = np.einsum("nij,ji->n", inv, weight)
    return out


def marks_frame_error(cameras, marks, views, zone) -> float:
    """RMS displacement (m per px of spot error) the frame set by marks ``O``, ``X``, ``F…``
    at ``marks`` (K×3, in that order; ``views`` C×K) gives points of ``zone`` (M×3)."""
    P = np.asarray(marks, float)
    cov = mark_covariances(cameras, P, views)
    Q, Z = P - P[0], np.asarray(zone, float) - P[0]  # from O: far from the origin alike
    across = 1 if abs(Q[1, 0]) >= abs(Q[1, 1]) else 0  # X's recorded zero: across O→X
    as_o, as_x, on_floor = roles_information(Q, cov, across)
    info = as_o[0] + as_x[1] + on_floor[2:].sum(axis=0)
    return float(np.sqrt(frame_errors(info[None], zone_weight(Z))[0]))
