"""The CasADi optimiser over camera poses: for a given number of cameras, every camera's
position on the ceiling, yaw and tilt, solved by IPOPT on a smooth form of the reference
model (:mod:`.reference`).

The smooth model is the reference model with its steps softened: a camera sees a sample point
by a smooth step of the point's margin inside the image (width :data:`EDGE_SHARE` of it), a point is
covered by a smooth step of its (soft) camera count at ``min_cameras``, and it is good when
also its predicted error ``sqrt(trace(F⁻¹))`` — the same Fisher matrix ``Σ JᵀJ / σ²``, written
in CasADi's symbols — is by a smooth step within the error bound. The requirements become two
constraints with a margin ``t`` to maximise: the covered share is at least ``coverage + t``
and the good share at least 95 % of the covered share plus ``t`` (the p95 bound). Obstacles
hide points by a mask fixed from the start poses. The exact model (:func:`.reference.evaluate`)
judges every answer; this model only steers.

casadi is imported only here, and only when a solve is built: it is large, and the runtime
path (locating, tracking) never needs it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..triangulation import trace_adjugate_det
from .poses import posed_cameras
from .reference import MARGIN_PX, sample_levels, sample_points, sample_step, unobstructed
from .site import Site, floor, footprint

#: width of the smooth step at the image's edges, as a share of the image's short side
#: (3 px of a 160 × 120 image)
EDGE_SHARE = 0.025
#: width of the smooth step of the camera count, and of the error's within-bound step (as a
#: share of the bound squared)
COUNT_SOFTNESS, ERROR_SOFTNESS = 0.25, 0.15
#: IPOPT's iterations per solve (the exact model judges; a solve need not converge fully)
MAX_ITERATIONS = 120
#: iterations between two looks of the judge (:func:`solve_poses`)
JUDGE_EVERY = 10


@dataclass
class Solve:
    """One IPOPT solve: its start and answer poses (n×5), the margin reached and the cost."""

    start: np.ndarray
    poses: np.ndarray
    margin: float  #: the smooth model's margin t (> 0: the requirements met with room)
    status: str  #: IPOPT's return status
    iterations: int
    seconds: float
    judged: object = None  #: what the judge returned when it stopped the solve (else None)
    late: bool = False  #: stopped at its deadline


def _rotation(ca, yaw, wx, wy):
    """The world → camera rotation of :func:`.poses.rotation`, in CasADi's symbols."""
    theta = ca.sqrt(wx ** 2 + wy ** 2 + 1e-12)
    kx, ky = wx / theta, wy / theta
    K = ca.vertcat(ca.horzcat(0, 0, ky), ca.horzcat(0, 0, -kx), ca.horzcat(-ky, kx, 0))
    Q = ca.MX.eye(3) + ca.sin(theta) * K + (1 - ca.cos(theta)) * (K @ K)
    c, s = ca.cos(yaw), ca.sin(yaw)
    Rz = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    return ca.DM([[1, 0, 0], [0, -1, 0], [0, 0, -1]]) @ Rz.T @ Q.T


class PoseProblem:
    """The smooth model for ``n`` cameras over the sample ``points`` (N×3) as an IPOPT
    problem, built once and solved from many starts (building costs as much as a short
    solve). Which points obstacles hide from each camera is a parameter, set per start."""

    def __init__(self, site: Site, n: int, points):
        import casadi as ca

        self.site, self.n, self.points = site, n, np.asarray(points, float)
        N = len(self.points)
        m, r = site.camera, site.requirements
        P = ca.MX.sym("poses", 5, n)
        t = ca.MX.sym("margin")
        mask = ca.MX.sym("unhidden", n, N)
        X = [ca.DM(self.points[:, k]).T for k in range(3)]
        lo, hi_u, hi_v = MARGIN_PX - 0.5, m.width - 0.5 - MARGIN_PX, m.height - 0.5 - MARGIN_PX

        edge = EDGE_SHARE * min(m.width, m.height)  # px

        def step(a):
            return 0.5 + 0.5 * ca.tanh(a / (2 * edge))

        near = site.ceiling_height - max(site.requirements.heights)  # the scene's depth
        F, count = [0.0] * 6, 0.0
        for c in range(n):
            R = _rotation(ca, P[2, c], P[3, c], P[4, c])
            D = (X[0] - P[0, c], X[1] - P[1, c], X[2] - site.ceiling_height)
            Xc = [R[i, 0] * D[0] + R[i, 1] * D[1] + R[i, 2] * D[2] for i in range(3)]
            # in front: a point behind the camera would project into the image too
            iz = 1 / ca.fmax(Xc[2], 0.01 * near)
            xn, yn = Xc[0] * iz, Xc[1] * iz
            u, v = m.fx * xn + m.cx, m.fy * yn + m.cy
            seen = step(u - lo) * step(hi_u - u) * step(v - lo) * step(hi_v - v) \
                * (0.5 + 0.5 * ca.tanh((Xc[2] - 0.1 * near) / (0.05 * near)))
            if site.obstacles:
                seen = seen * mask[c, :]
            a = [m.fx * iz * (R[0, k] - xn * R[2, k]) for k in range(3)]
            b = [m.fy * iz * (R[1, k] - yn * R[2, k]) for k in range(3)]
            for k, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
                F[k] = F[k] + seen * (a[i] * a[j] + b[i] * b[j])
            count = count + seen
        # a small ridge keeps a point seen once (F of rank 2) finite: its error is then huge
        ridge = 1e-6 * (m.fx / site.ceiling_height) ** 2
        trace_adj, det = trace_adjugate_det(F[0] + ridge, F[1], F[2], F[3] + ridge, F[4],
                                            F[5] + ridge)  # plain arithmetic: symbols too
        error2 = r.pixel_noise ** 2 * trace_adj / det
        covered = 0.5 + 0.5 * ca.tanh((count - (r.min_cameras - 0.5)) / (2 * COUNT_SOFTNESS))
        good = covered * (0.5 + 0.5 * ca.tanh((1 - error2 / r.max_error_p95 ** 2)
                                              / (2 * ERROR_SOFTNESS)))
        cov, ok = ca.sum2(covered) / N, ca.sum2(good) / N
        tilt2 = (P[3, :] ** 2 + P[4, :] ** 2).T
        nlp = {"x": ca.vertcat(ca.vec(P), t), "f": -t, "p": ca.vec(mask),
               "g": ca.vertcat(cov - r.coverage - t, ok - 0.95 * cov - t, tilt2)}
        self.watch = _judge_class()(5 * n + 1, 2 + n, n)
        self.solver = ca.nlpsol("poses", "ipopt", nlp, {
            "ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes",
            "ipopt.hessian_approximation": "limited-memory",
            "ipopt.max_iter": MAX_ITERATIONS, "ipopt.tol": 1e-4, "error_on_fail": False,
            "iteration_callback": self.watch})

    def solve(self, start, bounds, max_tilt: float, judge=None,
              deadline: float = math.inf) -> Solve:
        """Optimise the poses ``start`` (n×5): positions within ``bounds`` (x0, y0, x1, y1),
        tilts within ``max_tilt`` (rad). ``judge`` (poses → a result or None) looks at the
        iterate every :data:`JUDGE_EVERY` iterations; a result stops the solve there (the
        exact model need not wait for the smooth one to converge). ``deadline``
        (``time.perf_counter()``): the solve stops there (:attr:`Solve.late`)."""
        t0 = time.perf_counter()
        n, site = self.n, self.site
        start = np.asarray(start, float).reshape(n, 5)
        x0, y0, x1, y1 = bounds
        lbx = np.tile([x0, y0, -np.inf, -max_tilt, -max_tilt], n).tolist() + [-1.0]
        ubx = np.tile([x1, y1, np.inf, max_tilt, max_tilt], n).tolist() + [1.0]
        begin = start.copy()
        begin[:, 0] = np.clip(begin[:, 0], x0, x1)
        begin[:, 1] = np.clip(begin[:, 1], y0, y1)
        begin[:, 3:] = np.clip(begin[:, 3:], -max_tilt, max_tilt)
        mask = np.ones((n, len(self.points)))
        if site.obstacles:  # hidden as seen from the start's positions
            for c, cam in enumerate(posed_cameras(site, begin)):
                mask[c] = unobstructed(cam.center, self.points, site.obstacles)
        self.watch.arm(judge, deadline)
        out = self.solver(x0=begin.ravel().tolist() + [0.0], lbx=lbx, ubx=ubx,
                          p=mask.ravel(order="F").tolist(), lbg=[0.0, 0.0] + [0.0] * n,
                          ubg=[np.inf, np.inf] + [max_tilt ** 2] * n)
        x = np.asarray(out["x"]).ravel()
        stats = self.solver.stats()
        if self.watch.interrupt is not None:
            raise self.watch.interrupt
        if stats["return_status"] == "User_Requested_Stop" and self.watch.result is None \
                and not self.watch.late:
            raise KeyboardInterrupt  # stopped by no judge and no deadline: by the user

        poses, judged = x[:-1].reshape(n, 5), None
        if self.watch.result is not None:
            poses, judged = self.watch.poses, self.watch.result
        return Solve(start, poses, float(x[-1]), str(stats["return_status"]),
                     int(stats["iter_count"]), time.perf_counter() - t0, judged,
                     self.watch.late)


def _judge_class():
    """casadi's Callback, subclassed only once casadi is imported."""
    import casadi as ca

    class Judge(ca.Callback):
        """IPOPT's iteration callback: hands the iterate's poses to ``judge`` now and then;
        a result stops the solve (casadi stops on a non-zero return)."""

        def __init__(self, nx, ng, n):
            ca.Callback.__init__(self)
            self.nx, self.ng, self.n = nx, ng, n
            self.arm(None)
            self.construct("judge", {})

        def arm(self, judge, deadline=math.inf):
            """A new solve: its judge (None: none) and the time it must end by."""
            self.judge, self.calls, self.result, self.poses = judge, 0, None, None
            self.deadline, self.late, self.interrupt = deadline, False, None

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "stop"

        def get_sparsity_in(self, i):
            name = ca.nlpsol_out(i)
            if name == "f":
                return ca.Sparsity.scalar()
            if name in ("x", "lam_x"):
                return ca.Sparsity.dense(self.nx)
            if name in ("g", "lam_g"):
                return ca.Sparsity.dense(self.ng)
            return ca.Sparsity(0, 0)

        def eval(self, arg):
            # a signal (Ctrl-C, SIGTERM) lands here, in the only Python IPOPT runs: stop the
            # solve and let the caller raise it, not count the solve as one that failed
            try:
                self.calls += 1
                if time.perf_counter() > self.deadline:
                    self.late = True
                    return [1]
                if self.judge is None or self.calls % JUDGE_EVERY:
                    return [0]
                poses = np.asarray(arg[0]).ravel()[:-1].reshape(self.n, 5)
                got = self.judge(poses)
                if got is None:
                    return [0]
                self.result, self.poses = got, poses
                return [1]
            except BaseException as e:  # noqa: BLE001 — re-raised by the solve
                self.interrupt = e
                return [1]

    return Judge



def _fine_step(site: Site) -> tuple[float, float]:
    """The smooth model's grid step before any cap (the reference model's, coarser where a
    camera's footprint spans many cells: about :data:`CELLS_PER_FOOTPRINT` along its short
    side) and the floor area it samples, all levels (m, m²)."""
    step = max(sample_step(site), min(footprint(site)) / CELLS_PER_FOOTPRINT)
    return step, floor(site.room, site.keep_out).area * len(sample_levels(site))


def optimiser_step(site: Site, cameras: int = 1) -> float:
    """m: the smooth model's sample grid: :func:`_fine_step`'s, coarser when ``cameras`` ×
    points would pass :data:`MAX_PAIRS` (IPOPT's memory grows with their product)."""
    step, area = _fine_step(site)
    return max(step, math.sqrt(area * cameras / MAX_PAIRS))


def optimiser_points(site: Site, cameras: int = 1) -> np.ndarray:
    """The smooth model's sample points (N×3), on :func:`optimiser_step`'s grid."""
    return sample_points(site, optimiser_step(site, cameras))


def too_coarse(site: Site, cameras: int) -> bool:
    """Whether ``cameras`` would leave the smooth model coarser than its fine grid (a room
    too large for one solve to model finely)."""
    step, area = _fine_step(site)
    return area / step ** 2 * cameras > MAX_PAIRS


#: the smooth model's sample cells along a level camera's short footprint side
CELLS_PER_FOOTPRINT = 9
#: cameras × sample points the smooth model takes on at most (about 800 bytes each while
#: IPOPT runs: every step of the model is kept for the gradient)
MAX_PAIRS = 150_000
