"""Robust least squares for the survey: Levenberg–Marquardt on a soft-L1 loss, dense for one
camera's few parameters, sparse with a Schur complement for a bundle adjustment."""

from __future__ import annotations

import numpy as np


def levenberg_marquardt(resid, jac, p0, f_scale: float, iterations: int = 60, solve=None,
                        tolerance: float = 1e-10, negligible: float = 0.0):
    """Minimise the soft-L1 cost of ``resid`` (scale ``f_scale``) from ``p0``: Levenberg–
    Marquardt on the normal equations, damped along their diagonal (so the parameters' units
    do not matter). ``jac`` returns a dense array (a single camera's few parameters: the
    loss's own curvature ρ′ + 2zρ″ in the Hessian, as Triggs et al. §4.3 and SciPy's
    ``least_squares`` do, converging as fast as Gauss–Newton) or a sparse matrix (a bundle
    adjustment: reweighted by ρ′, which keeps every free point's block invertible).
    ``solve(A, g, damping)``: a solver that knows a sparse problem's structure
    (:class:`SchurSolver`), else (or where it returns None) a general direct sparse solve.
    Stops when a step gains less than ``tolerance`` of the cost or less than ``negligible``
    times ``f_scale``² (a gain below the noise's own scale, Δχ² ≪ 1, moves nothing that
    matters). Returns (p, cost)."""
    from scipy.sparse import diags  # (scipy: loaded by a fit only)
    from scipy.sparse.linalg import spsolve

    def cost_of(r):
        z = (r / f_scale) ** 2
        return f_scale ** 2 * np.sum(np.sqrt(1 + z) - 1)

    p = np.asarray(p0, float).copy()
    r = resid(p)
    cost = cost_of(r)
    lam = 1e-3
    for _ in range(iterations):
        J = jac(p)
        z1 = 1 + (r / f_scale) ** 2
        w = 1.0 / np.sqrt(z1)  # the loss's slope ρ′
        dense = isinstance(J, np.ndarray)
        # a camera's few parameters: the loss's curvature ρ′ + 2zρ″; a bundle adjustment,
        # whose free points a wrong spot could leave without curvature: ρ′ (reweighting)
        h = np.maximum(w / z1, np.finfo(float).eps) if dense else w
        A = (J * h[:, None]).T @ J if dense else (J.T @ diags(h) @ J).tocsc()
        g = J.T @ (w * r)
        d = np.diag(A).copy() if dense else A.diagonal()
        d = np.where(d > 0, d, 1.0)
        while True:
            if dense:
                try:
                    step = np.linalg.solve(A + np.diag(lam * d), -g)
                except np.linalg.LinAlgError:
                    step = np.full_like(p, np.nan)
            else:
                step = solve(A, g, lam * d) if solve is not None else None
                if step is None:
                    step = spsolve((A + diags(lam * d)).tocsc(), -g)
            trial = p + step
            r_new = resid(trial) if np.isfinite(trial).all() else np.full_like(r, np.inf)
            new = cost_of(r_new)
            if np.isfinite(new) and new <= cost:
                break
            lam *= 4
            if lam > 1e12:
                return p, cost
        small = cost - new <= max(tolerance * cost, negligible * f_scale ** 2)
        p, r, cost = trial, r_new, new
        lam = max(lam / 3, 1e-9)
        if small:
            break
    return p, cost


class SchurSolver:
    """Solve a bundle adjustment's damped normal equations by the Schur complement: the
    points' blocks (3 × 3, or 6 × 6 for two points held a length apart, in general one block
    per group of linked points) are inverted in one batch and eliminated, leaving a dense
    system in the cameras' few parameters (Triggs et al., "Bundle adjustment — a modern
    synthesis", §6.1). ``n_cam``: camera parameters first, then ``n_pts`` × 3 coordinates;
    ``pairs``: index arrays of linked points. Returns None where a block is singular (the
    caller falls back to a general sparse solve)."""

    def __init__(self, n_cam: int, n_pts: int, pairs=None):
        from scipy.sparse import coo_matrix  # (scipy: loaded by a fit only)
        from scipy.sparse.csgraph import connected_components

        self.n_cam = n_cam
        if pairs is not None and len(pairs[0]):
            i, j = pairs
            g = coo_matrix((np.ones(len(i)), (i, j)), shape=(n_pts, n_pts))
            _, comp = connected_components(g, directed=False)
        else:
            comp = np.arange(n_pts)
        order = np.argsort(comp, kind="stable")  # points grouped by their block
        c_sorted = comp[order]
        starts = np.flatnonzero(np.r_[True, c_sorted[1:] != c_sorted[:-1]])
        sizes = np.diff(np.r_[starts, n_pts])
        rank = np.empty(n_pts, int)
        rank[order] = np.arange(n_pts) - np.repeat(starts, sizes)
        block_of = np.empty(n_pts, int)
        block_of[order] = np.repeat(np.arange(len(starts)), sizes)
        self.block = np.repeat(block_of, 3)  # per coordinate: its block,
        self.local = (3 * rank[:, None] + np.arange(3)).ravel()  # and its place in it
        self.size = 3 * sizes  # per block
        # per block size: the blocks of that size and their coordinates (B × s, global)
        self.groups = []
        for sz in np.unique(self.size):
            blocks = np.flatnonzero(self.size == sz)
            coords = np.zeros((len(blocks), sz), int)
            where = np.full(len(starts), -1)
            where[blocks] = np.arange(len(blocks))
            q = np.flatnonzero(where[self.block] >= 0)
            coords[where[self.block[q]], self.local[q]] = q
            self.groups.append((sz, blocks, coords, where))

    def __call__(self, A, g, damping):
        """``step`` solving ``(A + diag(damping)) step = -g`` (``A``: CSC), or None."""
        from scipy.sparse import coo_matrix  # (scipy: loaded by a fit only)

        nc = self.n_cam
        A = A.tocsr()
        U = A[:nc, :nc].toarray() + np.diag(damping[:nc])
        W = A[:nc, nc:]
        V = A[nc:, nc:].tocoo()
        dp = damping[nc:]
        keep = self.block[V.row] == self.block[V.col]
        r, c, v = V.row[keep], V.col[keep], V.data[keep]
        rows, cols, vals = [], [], []
        for sz, blocks, coords, where in self.groups:
            mine = where[self.block[r]] >= 0
            B = np.zeros((len(blocks), sz, sz))
            np.add.at(B, (where[self.block[r[mine]]], self.local[r[mine]],
                          self.local[c[mine]]), v[mine])
            B[:, np.arange(sz), np.arange(sz)] += dp[coords]
            try:
                Binv = np.linalg.inv(B)
            except np.linalg.LinAlgError:
                return None
            rows.append(np.repeat(coords, sz, axis=1).ravel())
            cols.append(np.tile(coords, (1, sz)).ravel())
            vals.append(Binv.ravel())
        n = A.shape[0] - nc
        Vinv = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n, n)).tocsr()
        WV = W @ Vinv
        S = U - (WV @ W.T).toarray()
        gc, gp = g[:nc], g[nc:]
        try:
            dc = np.linalg.solve(S, -(gc - WV @ gp))
        except np.linalg.LinAlgError:
            return None
        step = np.r_[dc, Vinv @ (-gp - W.T @ dc)]
        return step if np.isfinite(step).all() else None
