"""The reference model in closed form for level ceiling cameras: fast enough to judge every
lattice of an exhaustive search and every move of a local search.

For a camera of the site's model hung level (looking straight down, yaw 0° or 90°) at depth d
above a point, the image offset is ``x_n = M·δ/d`` (δ the floor offset from the camera, M the
2×2 signed permutation of its yaw), visibility is an interval on each image axis, and every
entry of ``JᵀJ`` is a polynomial of degree ≤ 2 in δ. So the Fisher matrix of a layout at a
point is a fixed combination of six sums over the cameras that see it, Σ δₓᵖ δᵧᑫ (p + q ≤ 2),
and on a lattice each sum factors into a product over its columns and its rows (visibility
along x depends on δₓ alone, along y on δᵧ alone): a batch of lattices is a few matrix
products. For an undistorted camera model this is :func:`.reference.evaluate` exactly
(tested); with distortion it is the undistorted approximation, and every layout the planner
exports is judged by :func:`.reference.evaluate` itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..triangulation import trace_adjugate_det
from .families import ceiling_cameras
from .reference import MARGIN_PX, sample_grid, sample_levels, sample_step
from .site import Site

#: the camera yaws the model knows, rad
YAWS = (0.0, math.pi / 2)
#: entries of the symmetric Fisher matrix, as in ``predicted_rms_error``
PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
#: monomials δₓᵖ δᵧᑫ of the sums
MONOMIALS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


@dataclass
class Verdict:
    """Layouts judged (arrays over the batch)."""

    coverage: np.ndarray
    p95: np.ndarray  #: m; inf where nothing is covered
    meets: np.ndarray


class NadirModel:
    """The site's sample points and camera model, ready to judge batches of level layouts."""

    def __init__(self, site: Site, step: float | None = None, every: int = 1):
        """``every``: keep every n-th sample point along each axis (a coarse model for a
        search whose points are a subset of the exact model's)."""
        self.site = site
        r = site.requirements
        self.step = (sample_step(site) if step is None else step) * every
        xs, ys, inside = sample_grid(site, step)
        self.xs, self.ys, self.inside = xs[::every], ys[::every], inside[::every, ::every]
        self.levels = sample_levels(site)
        self.depths = [site.ceiling_height - h for h in self.levels]
        self.n_points = int(self.inside.sum()) * len(self.levels)
        self.rows_in, self.cols_in = np.nonzero(self.inside)  # the room's points, in order
        self._factor_cache = {}
        self.need, self.k = r.coverage, r.min_cameras
        self.bound = r.max_error_p95
        cam = site.camera
        self.intervals, self.coef = {}, {}
        for yaw in YAWS:
            c = ceiling_cameras(site, [(0.0, 0.0)], [yaw])[0]
            M = np.round(c.R[:2, :2])  # image axes (rows) against floor axes (columns)
            f, pp = (cam.fx, cam.fy), (cam.cx, cam.cy)
            hi = (cam.width - 0.5 - MARGIN_PX, cam.height - 0.5 - MARGIN_PX)
            # each floor axis is seen by one image axis: its visible interval of δ/d
            iv = []
            for axis in (0, 1):
                row = int(np.flatnonzero(M[:, axis])[0])
                ends = M[row, axis] * np.array([(MARGIN_PX - 0.5 - pp[row]) / f[row],
                                                (hi[row] - pp[row]) / f[row]])
                iv.append((ends.min(), ends.max()))
            self.intervals[yaw] = iv
            self.coef[yaw] = [self._coefficients(M, f, d) / r.pixel_noise ** 2
                              for d in self.depths]

    @staticmethod
    def _coefficients(M, f, d) -> np.ndarray:
        """6 × 6: Fisher entries (PAIRS) from the monomial sums (MONOMIALS) at depth d.
        Row r of J is f_r/d · [M_r0, M_r1, (M_r0 δₓ + M_r1 δᵧ)/d]."""
        C = np.zeros((6, 6))
        for r in (0, 1):
            g = f[r] ** 2 / d ** 2
            m0, m1 = M[r]
            v = [{(0, 0): m0}, {(0, 0): m1}, {(1, 0): m0 / d, (0, 1): m1 / d}]
            for k, (i, j) in enumerate(PAIRS):
                for (pa, qa), ca in v[i].items():
                    for (pb, qb), cb in v[j].items():
                        C[k, MONOMIALS.index((pa + pb, qa + qb))] += g * ca * cb
        return C

    # -- the sums ---------------------------------------------------------------------------
    def _axis(self, offsets, yaw, level, axis, powers=3):
        """Visibility × powers 0, 1, 2 of δ along one floor axis: offsets (..., P) → a list of
        ``powers`` arrays (..., P)."""
        lo, hi = self.intervals[yaw][axis]
        d = self.depths[level]
        v = ((offsets >= lo * d) & (offsets <= hi * d)).astype(float)
        return [v, v * offsets, v * offsets * offsets][:powers]

    def lattice_sums(self, cols, rows, mounted, yaw, level, monomials=MONOMIALS):
        """Monomial sums of a batch of B lattices at one level.

        ``cols`` (B × I) and ``rows`` (B × J): the column x and row y positions of each
        lattice; ``mounted`` (B × I × J, float): which lattice points carry a camera. Returns
        a list (one per monomial) of B × Py × Px."""
        powers = 1 + max(max(p, q) for p, q in monomials)
        X = self._axis(self.xs[None, :, None] - cols[:, None, :], yaw, level, 0, powers)
        Y = self._axis(self.ys[None, :, None] - rows[:, None, :], yaw, level, 1, powers)
        XM = {p: np.matmul(X[p], mounted) for p in {p for p, _ in monomials}}  # B×Px×J
        return [np.matmul(Y[q], np.swapaxes(XM[p], -1, -2)) for p, q in monomials]

    def _factors(self, axis: int, at: float, yaw: float, level: int):
        """Visibility × powers of δ along one floor axis for a camera at ``at`` (m), at every
        sample point in the room (cached: cameras on a grid share their columns and rows)."""
        key = (axis, round(at, 9), yaw, level)
        got = self._factor_cache.get(key)
        if got is None:
            if len(self._factor_cache) > 20000:
                self._factor_cache.clear()
            grid, pick = (self.xs, self.cols_in) if axis == 0 else (self.ys, self.rows_in)
            got = [f[pick] for f in self._axis(grid - at, yaw, level, axis)]
            self._factor_cache[key] = got
        return got

    def camera_fisher(self, x: float, y: float, yaw: float) -> np.ndarray:
        """One camera at floor position (x, y): its 6 Fisher entries and its count at every
        sample point in the room, levels after one another → 7 × (L·P)."""
        out = np.zeros((7, len(self.levels), len(self.rows_in)))
        for level in range(len(self.levels)):
            X = self._factors(0, x, yaw, level)
            Y = self._factors(1, y, yaw, level)
            C = self.coef[yaw][level]
            products = {}
            for m, (p, q) in enumerate(MONOMIALS):
                if C[:, m].any() or m == 0:
                    products[m] = Y[q] * X[p]
            for k in range(6):
                for m, prod in products.items():
                    if C[k, m]:
                        out[k, level] += C[k, m] * prod
            out[6, level] = products[0]
        return out.reshape(7, -1)

    def fisher(self, sums_by_yaw, level):
        """The 6 Fisher entries and the camera count from monomial sums per yaw at one level
        (each 6 × … × Py × Px) → (6 × …, count …)."""
        F, count = 0.0, 0.0
        for yaw, S in sums_by_yaw.items():
            C = self.coef[yaw][level]
            F = F + np.stack([sum(C[k, m] * S[m] for m in range(6) if C[k, m]) if C[k].any()
                              else np.zeros_like(S[0]) for k in range(6)])
            count = count + S[0]
        return F, count

    # -- the verdict ------------------------------------------------------------------------
    def covered(self, counts) -> np.ndarray:
        """Sample points seen by ≥ k cameras at one level: counts … × Py × Px → …"""
        return ((counts >= self.k - 0.5) & self.inside).sum(axis=(-2, -1))

    def judge(self, F, counts) -> Verdict:
        """Coverage, p95 and the verdict: F (L × 6 × B × Py × Px), counts (L × B × Py × Px)."""
        tr, det = trace_adjugate_det(*np.moveaxis(F, 1, 0))
        ok = (counts >= self.k - 0.5) & self.inside
        with np.errstate(invalid="ignore", divide="ignore"):
            err = np.where(ok, np.sqrt(tr / det), np.inf)
        err = np.moveaxis(err, 0, -3).reshape(err.shape[1], -1)  # B × (L·Py·Px)
        n_ok = ok.sum(axis=(0, -2, -1)).reshape(-1)
        p95 = np.full(len(n_ok), np.inf)
        for b in np.flatnonzero(n_ok):  # numpy's linear percentile of the covered points
            pos = 0.95 * (n_ok[b] - 1)
            lo, hi = int(math.floor(pos)), int(math.ceil(pos))
            part = np.partition(err[b], (lo, hi))
            p95[b] = part[lo] + (part[hi] - part[lo]) * (pos - lo)
        cov = n_ok / self.n_points
        return Verdict(cov, p95, (cov >= self.need) & (p95 <= self.bound))
