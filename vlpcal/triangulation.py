"""Triangulation: pixels of one LED in ≥ 2 cameras → its 3D position, vectorised over points.

Shapes follow aniposelib's habit: ``uv`` is ``C×N×2`` (C cameras, N points) with NaN where a
camera did not see the point; results are ``N×3`` world points (metres) with NaN where fewer
than two cameras saw it.

- :func:`triangulate_pair_paper`: the paper's two-camera method (section 2.2), the baseline.
- :func:`triangulate`: N-view least squares: a linear solve (the point closest to all rays),
  then Gauss–Newton on the reprojection error.
- :func:`triangulate_robust`: the same, dropping an observation whose reprojection error is far
  above the rest (a reflection picked up by one camera), and saying which.
- :func:`triangulate_cv2`: ``cv2.triangulatePoints`` (DLT) for comparison (cv2 is imported
  there: nothing else here needs that heavy import).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Camera


@dataclass
class PairEstimate:
    """The paper's pair method over N points: ``X`` (N×3) and where it is undefined."""

    X: np.ndarray
    #: the LED lies on the cameras' line in top view (or a ray does not reach the floor)
    degenerate: np.ndarray


@dataclass
class Triangulation:
    """N-view result: points ``N×3``, per-camera reprojection error ``C×N`` (px), views used.

    The reprojection error is measured in undistorted pixels (normalised coordinates times
    fx, fy): the pixel error to first order in the lens distortion.
    """

    X: np.ndarray
    residual: np.ndarray
    used: np.ndarray  # C×N bool: the observations the point was solved from
    #: the observations :func:`triangulate_robust` rejected (all False for plain least squares)
    dropped: np.ndarray

    @property
    def views(self) -> np.ndarray:
        return self.used.sum(axis=0)


#: top-view lines crossing at less than this (radians, 3°) are flagged degenerate: the paper's
#: intersection is undefined on the cameras' line and amplifies pixel noise ~1/sin(angle) near
#: it (0.1 px of noise gives metres of error within a few mm of the line)
MIN_CROSSING = np.radians(3.0)


def triangulate_pair_paper(cam1: Camera, cam2: Camera, uv1, uv2,
                           min_angle: float = MIN_CROSSING) -> PairEstimate:
    """The paper's 3D pair method (section 2.2), vectorised over ``N×2`` pixels.

    Top view: each camera's line from its position through its floor footprint of the LED
    (the ray met with the floor plane, the paper's ``l_i = K_i l_i^c``) passes through the LED;
    the two lines meet at (x, y) (eqs. 14–15). Depth: in the triangle of Fig. 7 with baseline B
    and view angles θᵢ along the baseline, ``E = B sin β / sin(180° − α − β)``, ``z = E sin α``
    with α = 90° − θ₁, β = 90° − θ₂, which is ``B / (tan θ₁ + tan θ₂)``. The tangents are signed
    along the baseline, so the result equals the paper's between the cameras (where it applies)
    and stays right beyond them. Both cameras are taken at their mean height, as the paper does
    (a height difference d between them biases z by up to ~0.4 d).

    Flagged ``degenerate`` (NaN): top-view lines crossing at less than ``min_angle`` (the LED
    on or near the cameras' line in top view, or straight below a camera), a ray that does not
    reach the floor, a non-positive depth.
    """
    c1, c2 = cam1.center, cam2.center
    d1, d2 = cam1.rays(uv1), cam2.rays(uv2)
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = np.where(d1[:, 2] < 0, -c1[2] / d1[:, 2], np.nan)
        s2 = np.where(d2[:, 2] < 0, -c2[2] / d2[:, 2], np.nan)
    # floor footprints l1, l2 (world x, y)
    xl1, yl1 = c1[0] + s1 * d1[:, 0], c1[1] + s1 * d1[:, 1]
    xl2, yl2 = c2[0] + s2 * d2[:, 0], c2[1] + s2 * d2[:, 1]
    x1, y1, x2, y2 = c1[0], c1[1], c2[0], c2[1]
    # eqs. 14–15: intersection of the lines C1→l1 and C2→l2
    den = (x1 - xl1) * (y2 - yl2) - (y1 - yl1) * (x2 - xl2)
    a = x1 * yl1 - y1 * xl1
    b = x2 * yl2 - y2 * xl2
    len1 = np.hypot(xl1 - x1, yl1 - y1)
    len2 = np.hypot(xl2 - x2, yl2 - y2)
    # |den| = |l1 − C1| |l2 − C2| sin(crossing angle)
    degenerate = ~(np.abs(den) > max(np.sin(min_angle), 1e-12) * len1 * len2) \
        | ~np.isfinite(den)
    with np.errstate(divide="ignore", invalid="ignore"):
        xL = np.where(degenerate, np.nan, (a * (x2 - xl2) - (x1 - xl1) * b) / den)
        yL = np.where(degenerate, np.nan, (a * (y2 - yl2) - (y1 - yl1) * b) / den)
    # depth from the triangle of Fig. 7, along the baseline
    base = np.array([x2 - x1, y2 - y1])
    B = float(np.hypot(*base))
    e = base / B
    t1 = ((xl1 - x1) * e[0] + (yl1 - y1) * e[1]) / c1[2]
    t2 = -((xl2 - x2) * e[0] + (yl2 - y2) * e[1]) / c2[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = B / (t1 + t2)
    bad = degenerate | ~(depth > 0)
    z = np.where(bad, np.nan, 0.5 * (c1[2] + c2[2]) - depth)
    return PairEstimate(np.stack([xL, yL, z], axis=-1), bad)


# -- N-view least squares ------------------------------------------------------------------------

def _solve3(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve symmetric 3×3 systems ``N×3×3 · x = N×3`` by cofactors (vectorised, no LAPACK loop)."""
    a00, a01, a02 = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    a11, a12, a22 = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([
            (c00 * b0 + c01 * b1 + c02 * b2) / det,
            (c01 * b0 + c11 * b1 + c12 * b2) / det,
            (c02 * b0 + c12 * b1 + c22 * b2) / det,
        ], axis=-1)


class _Views:
    """Per-camera arrays for a batch: undistorted normalised coordinates and a seen mask."""

    def __init__(self, cameras: list[Camera], uv):
        uv = np.asarray(uv, dtype=float)
        if uv.ndim != 3 or uv.shape[0] != len(cameras) or uv.shape[2] != 2:
            raise ValueError(f"uv must be C×N×2 with C = {len(cameras)} cameras, got {uv.shape}")
        self.cameras = cameras
        self.uv = uv
        # a camera with no spot in the batch: NaN without undistorting anything
        xy = np.stack([c.normalise(p) if np.isfinite(p).any() else np.full(p.shape, np.nan)
                       for c, p in zip(cameras, uv)]) if cameras else np.zeros(uv.shape)
        # a pixel with no undistorted inverse (past the lens's fold) counts as not seen
        self.seen = np.isfinite(xy).all(axis=2)
        self.xy = np.where(self.seen[..., None], xy, 0.0)

    def subset(self, idx: np.ndarray) -> _Views:
        """The same cameras over the points ``idx`` only."""
        sub = object.__new__(_Views)
        sub.cameras, sub.uv, sub.seen, sub.xy = self.cameras, self.uv[:, idx], \
            self.seen[:, idx], self.xy[:, idx]
        return sub


#: points solved together: small enough that the per-point arrays stay in the CPU cache
_CHUNK = 16384


def _project_n(cam: Camera, X: np.ndarray):
    """Camera-frame components of ``X`` (N×3): returns x/z, y/z, 1/z (undistorted)."""
    R, c = cam.R, cam.center
    dx, dy, dz = X[:, 0] - c[0], X[:, 1] - c[1], X[:, 2] - c[2]
    iz = 1.0 / (R[2, 0] * dx + R[2, 1] * dy + R[2, 2] * dz)
    a = (R[0, 0] * dx + R[0, 1] * dy + R[0, 2] * dz) * iz
    b = (R[1, 0] * dx + R[1, 1] * dy + R[1, 2] * dz) * iz
    return a, b, iz


def _solve_chunk(cameras, xy: np.ndarray, use: np.ndarray, iterations: int) -> np.ndarray:
    # the cameras that see none of these points add nothing: a site's hundred cameras cost
    # only the few that see its LED
    some = use.any(axis=1)
    if not some.all():
        idx = np.flatnonzero(some)
        cameras, xy, use = [cameras[i] for i in idx], xy[idx], use[idx]
    n = use.shape[1]
    A = np.zeros((n, 6))  # symmetric 3×3: 00 01 02 11 12 22
    b = np.zeros((n, 3))
    pairs = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    for cam, p, w in zip(cameras, xy, use):
        # ray direction d = Rᵀ (x, y, 1), normalised; P = I − d dᵀ (masked)
        R = cam.R
        d = [R[0, j] * p[:, 0] + R[1, j] * p[:, 1] + R[2, j] for j in range(3)]
        inv = w / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        c = cam.center
        Pc = [w * c[j] for j in range(3)]
        proj = (d[0] * c[0] + d[1] * c[1] + d[2] * c[2]) * inv
        for k, (i, j) in enumerate(pairs):
            A[:, k] += (w if i == j else 0.0) - d[i] * d[j] * inv
        for j in range(3):
            b[:, j] += Pc[j] - d[j] * proj
    X = _solve3(_full(A), b)
    for _ in range(iterations):
        H = np.zeros((n, 6))
        g = np.zeros((n, 3))
        for cam, p, w in zip(cameras, xy, use):
            a, bb, iz = _project_n(cam, X)
            R = cam.R
            s0, s1 = cam.fx * iz * w, cam.fy * iz * w
            J0 = [s0 * (R[0, j] - a * R[2, j]) for j in range(3)]
            J1 = [s1 * (R[1, j] - bb * R[2, j]) for j in range(3)]
            r0 = cam.fx * (a - p[:, 0])
            r1 = cam.fy * (bb - p[:, 1])
            for k, (i, j) in enumerate(pairs):
                H[:, k] += J0[i] * J0[j] + J1[i] * J1[j]
            for j in range(3):
                g[:, j] += J0[j] * r0 + J1[j] * r1
        step = _solve3(_full(H), g)
        X = X - step
        if not np.nanmax(np.abs(step), initial=0.0) > 1e-12:
            break
    bad = use.sum(axis=0) < 2
    for cam, w in zip(cameras, use):  # a solution behind a camera that saw it is no solution
        _, _, iz = _project_n(cam, X)
        bad |= w & ~(iz > 0)
    X[bad] = np.nan
    return X


def _full(S: np.ndarray) -> np.ndarray:
    """``N×6`` upper triangle → ``N×3×3`` symmetric matrices."""
    return S[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)


def _solve(views: _Views, use: np.ndarray, iterations: int) -> np.ndarray:
    """Least squares over the observations in ``use`` (C×N): linear solve, then Gauss–Newton.

    The linear step finds the point nearest all rays, (ΣᵢPᵢ)X = ΣᵢPᵢcᵢ with Pᵢ = I − dᵢdᵢᵀ.
    The Gauss–Newton steps minimise the reprojection error in undistorted pixels,
    rᵢ = (fx (x/z − xᵢ), fy (y/z − yᵢ)): the pixel error to first order, without re-running the
    distortion model each step. One step already converges (the linear point is close).
    """
    n = use.shape[1]
    X = np.empty((n, 3))
    with np.errstate(invalid="ignore", divide="ignore"):  # points seen < 2 times become NaN
        for s in range(0, n, _CHUNK):
            sl = slice(s, s + _CHUNK)
            X[sl] = _solve_chunk(views.cameras, views.xy[:, sl], use[:, sl], iterations)
    return X


def _residuals(views: _Views, X: np.ndarray) -> np.ndarray:
    """Reprojection error of ``X`` in undistorted pixels, every camera: ``C×N``, NaN if unseen."""
    out = np.full(views.seen.shape, np.nan)
    for k, cam in enumerate(views.cameras):
        if not views.seen[k].any():  # it saw none of them: NaN throughout
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            a, b, _ = _project_n(cam, X)
        err = np.hypot(cam.fx * (a - views.xy[k, :, 0]), cam.fy * (b - views.xy[k, :, 1]))
        out[k] = np.where(views.seen[k], err, np.nan)
    return out


def reprojection_errors(cameras: list[Camera], uv, X) -> np.ndarray:
    """Reprojection error (undistorted px) of points ``X`` (N×3) against ``uv`` (C×N×2): C×N."""
    return _residuals(_Views(cameras, uv), np.asarray(X, dtype=float))


def triangulate(cameras: list[Camera], uv, iterations: int = 2) -> Triangulation:
    """N-view least-squares triangulation of ``uv`` (``C×N×2``, NaN = not seen) → ``N×3``."""
    views = _Views(cameras, uv)
    X = _solve(views, views.seen, iterations)
    return Triangulation(X, _residuals(views, X), views.seen.copy(),
                         np.zeros_like(views.seen))


def triangulate_robust(cameras: list[Camera], uv, max_residual: float = 2.0,
                       iterations: int = 2) -> Triangulation:
    """N-view least squares that drops observations inconsistent with the rest.

    A point whose worst reprojection error exceeds ``max_residual`` px is re-solved without
    each of its cameras in turn (leave-one-out, vectorised over points); the subset with the
    smallest RMS error replaces it, and this repeats while the point still fails and keeps more
    than two views. Leave-one-out rather than "drop the worst": one wrong spot drags the
    least-squares point toward itself and can leave a good camera with the largest error.
    With two views an inconsistency is visible (``residual``) but cannot be attributed.
    """
    views = _Views(cameras, uv)
    use = views.seen.copy()
    X = _solve(views, use, iterations)
    res = _residuals(views, X)
    C = len(cameras)
    for _ in range(max(C - 2, 0)):
        worst = np.nanmax(np.where(use, res, np.nan), axis=0, initial=0.0)
        # no solution at all (a wild spot threw it behind a camera) fails as well
        fail = ((worst > max_residual) | ~np.isfinite(X).all(axis=1)) & (use.sum(axis=0) > 2)
        if not fail.any():
            break
        idx = np.flatnonzero(fail)
        sub = views.subset(idx)
        best_rms = np.full(len(idx), np.inf)
        best_X = X[idx].copy()
        best_use = use[:, idx].copy()
        for k in range(C):
            trial = use[:, idx].copy()
            if not trial[k].any():
                continue
            can = trial[k].copy()
            trial[k] = False
            Xk = _solve(sub, trial, iterations)
            rk = _residuals(sub, Xk)
            sq = np.where(trial & np.isfinite(rk), rk, 0.0) ** 2
            with np.errstate(invalid="ignore", divide="ignore"):
                rms = np.sqrt(sq.sum(axis=0) / (trial & np.isfinite(rk)).sum(axis=0))
            rms = np.where(np.isfinite(rms), rms, np.inf)
            better = can & (rms < best_rms)
            best_rms[better] = rms[better]
            best_X[better] = Xk[better]
            best_use[:, better] = trial[:, better]
        X[idx] = best_X
        use[:, idx] = best_use
        res[:, idx] = _residuals(sub, best_X)
    return Triangulation(X, res, use, views.seen & ~use)


def triangulate_cv2(cam1: Camera, cam2: Camera, uv1, uv2) -> np.ndarray:
    """``cv2.triangulatePoints`` (linear DLT) on undistorted normalised coordinates → ``N×3``."""
    import cv2

    if len(uv1) == 0:
        return np.zeros((0, 3))
    P1 = np.hstack([cam1.R, cam1.tvec[:, None]])
    P2 = np.hstack([cam2.R, cam2.tvec[:, None]])
    x1 = cam1.normalise(uv1).T.astype(np.float64)
    x2 = cam2.normalise(uv2).T.astype(np.float64)
    H = cv2.triangulatePoints(P1, P2, x1, x2)
    return (H[:3] / H[3]).T


def trace_adjugate_det(a00, a01, a02, a11, a12, a22):
    """trace(adj F) and det F of symmetric 3×3 matrices given by their upper triangles (arrays
    of any shape): trace(F⁻¹) = trace(adj F) / det F without forming the inverse."""
    c00, c01 = a11 * a22 - a12 * a12, a01 * a22 - a02 * a12
    det = a00 * c00 - a01 * c01 + a02 * (a01 * a12 - a02 * a11)
    return c00 + (a00 * a22 - a02 * a02) + (a00 * a11 - a01 * a01), det


def predicted_rms_error(cameras: list[Camera], X, used, pixel_noise: float) -> np.ndarray:
    """Predicted RMS 3D error (m) of points ``X`` (N×3) solved from the observations ``used``
    (C×N): ``sqrt(trace(F⁻¹))`` with ``F = Σᵢ JᵢᵀJᵢ / σ²`` over the cameras used, Jᵢ the 2×3
    pixel Jacobian and σ = ``pixel_noise`` px (the Cramér–Rao bound for Gaussian spot noise;
    the reference model, docs/conventions.md#reference-model). NaN where fewer than two
    cameras were used.
    """
    X = np.asarray(X, dtype=float)
    F = np.zeros((len(X), 6))
    pairs = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    for cam, w in zip(cameras, np.asarray(used, bool)):
        if not w.any():
            continue
        J = cam.jacobian(np.where(w[:, None], X, cam.center + cam.axis))  # dummy where unused
        for k, (i, j) in enumerate(pairs):
            F[:, k] += np.where(w, (J[:, :, i] * J[:, :, j]).sum(axis=1), 0.0)
    F /= pixel_noise ** 2
    adj_trace, det = trace_adjugate_det(*F.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.sqrt(adj_trace / det)
    out[(np.asarray(used, bool).sum(axis=0) < 2) | ~np.isfinite(X).all(axis=1)] = np.nan
    return out
