"""The CasADi/IPOPT layout optimiser: smooth coverage and error surrogates per arrangement,
steepness continuation, multistart, every result judged by the reference model."""

from __future__ import annotations

import math

import numpy as np

from .families import Candidate, footprint, grid_cameras, mountable, rank_key
from .reference import MARGIN_PX, evaluate
from .site import Site

#: weight of the surrogate's penalty on covered points whose error exceeds the requirement
PENALTY = 0.5


def optimise_layout(site: Site, family: str, nx: int, ny: int, yaw: float,
                    starts: int = 3, screen_step: float = 0.2) -> Candidate | None:
    """Spacing(s) and offset of one grid arrangement by CasADi/IPOPT on smooth surrogates,
    then judged by the reference model (:func:`evaluate`): the best start, passing or not
    (cameras that would hang outside the room are left out). None if IPOPT gave nothing.

    Surrogates (nadir cameras, the site's camera model): a camera sees a sample point with
    weight σ(k·(half-width·Z − |d|)) per image axis, a point is covered with
    σ(8·(Σ weights − (min_cameras − ½))), and its predicted error is sqrt(trace(F⁻¹)) with F
    built from those weights. On an axis-aligned lattice every sum separates into a sum over
    columns times a sum over rows (FIELD-NOTES), so the surrogate costs O(cameras × (columns
    + rows)) per height, not O(cameras × points): large rooms stay fast. A triangular lattice
    is two such lattices (even and odd rows). The objective rewards soft coverage and
    penalises covered points whose error exceeds the requirement; the steepness rises
    20 → 60 m⁻¹ with warm starts; ``starts`` initial spacings.
    """
    import casadi as ca
    from shapely import contains_xy
    from shapely.geometry import Polygon

    def sig(x):  # the logistic function without overflow (tanh form)
        return 0.5 * (1 + ca.tanh(x / 2))

    r = site.requirements
    cam = site.camera
    area = Polygon(site.room)
    for poly in site.keep_out:
        area = area.difference(Polygon(poly))
    x0, y0, x1, y1 = Polygon(site.room).bounds
    xs = np.arange(x0 + screen_step / 2, x1, screen_step)
    ys = np.arange(y0 + screen_step / 2, y1, screen_step)
    gx, gy = np.meshgrid(xs, ys)
    mask = contains_xy(area, gx.ravel(), gy.ravel()).reshape(gx.shape).astype(float)
    mask_dm = ca.DM(mask)
    total = float(mask.sum())
    hs = r.heights
    levels = sorted({min(hs), (min(hs) + max(hs)) / 2, max(hs)})
    hw = (cam.width / 2 - 0.5 - MARGIN_PX) / cam.fx
    hh = (cam.height / 2 - 0.5 - MARGIN_PX) / cam.fy
    if yaw:
        hw, hh = hh, hw
    fw, fd = footprint(site)
    if yaw:
        fw, fd = fd, fw
    rows = ny if family != "linear" else 1
    # row groups of one shift each: (shift in spacings, row indices)
    groups = [(0.0, list(range(rows)))] if family != "triangular" else \
        [(0.0, list(range(0, rows, 2))), (0.5, list(range(1, rows, 2)))]
    groups = [g for g in groups if g[1]]

    opti = ca.Opti()
    a = opti.variable()
    b = opti.variable() if family == "square" else (a * math.sqrt(3) / 2
                                                    if family == "triangular" else 0.0)
    dx, dy = opti.variable(), opti.variable()
    k_vis = opti.parameter()
    span_x = (nx - 1 + (0.5 if family == "triangular" and rows > 1 else 0.0)) * a
    span_y = (rows - 1) * b
    ox = (x0 + x1) / 2 - span_x / 2 + dx
    oy = (y0 + y1) / 2 - span_y / 2 + dy
    xs_row = ca.DM(xs).T  # 1 × Mx
    ys_col = ca.DM(ys)  # My × 1
    objective = 0
    for h in levels:
        Z = site.ceiling_height - h
        c = (cam.fx / Z) ** 2 / r.pixel_noise ** 2
        count = 0
        F00 = F02 = F12 = F22 = 0
        for shift, js in groups:
            Sx = [0, 0, 0]
            for i in range(nx):
                d = xs_row - (ox + (i + shift) * a)
                v = sig(k_vis * (hw * Z - d)) * sig(k_vis * (hw * Z + d))
                Sx = [Sx[0] + v, Sx[1] + v * d / Z, Sx[2] + v * (d / Z) ** 2]
            Sy = [0, 0, 0]
            for j in js:
                d = ys_col - (oy + j * b)
                v = sig(k_vis * (hh * Z - d)) * sig(k_vis * (hh * Z + d))
                Sy = [Sy[0] + v, Sy[1] + v * d / Z, Sy[2] + v * (d / Z) ** 2]
            n00 = ca.mtimes(Sy[0], Sx[0])  # My × Mx: Σ weights
            count = count + n00
            F00 = F00 + c * n00
            F02 = F02 + c * ca.mtimes(Sy[0], Sx[1])
            F12 = F12 + c * ca.mtimes(Sy[1], Sx[0])
            F22 = F22 + c * (ca.mtimes(Sy[0], Sx[2]) + ca.mtimes(Sy[2], Sx[0]))
        eps = 1e-6
        F00, F22 = F00 + eps, F22 + eps
        # F = [[F00, 0, F02], [0, F00, F12], [F02, F12, F22]]
        det = F00 * (F00 * F22 - F12 ** 2) - F02 * (F00 * F02)
        tr_inv = ((F00 * F22 - F12 ** 2) + (F00 * F22 - F02 ** 2) + F00 ** 2) / det
        err = ca.sqrt(tr_inv + 1e-12)
        covered = sig(8 * (count - (r.min_cameras - 0.5)))
        x = 8 * (err / r.max_error_p95 - 1)
        excess = (ca.fmax(x, 0) + ca.log1p(ca.exp(-ca.fabs(x)))) / 8  # softplus, no overflow
        objective = objective - ca.sum1(ca.sum2(mask_dm * covered)) / total \
            + PENALTY * ca.sum1(ca.sum2(mask_dm * covered * excess)) / total
    opti.minimize(objective / len(levels))
    opti.subject_to(opti.bounded(0.2 * fw, a, 1.2 * fw))
    if family == "square":
        opti.subject_to(opti.bounded(0.2 * fd, b, 1.2 * fd))
    opti.subject_to(opti.bounded(-fw, dx, fw))
    opti.subject_to(opti.bounded(-fd, dy, fd))
    opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                          "ipopt.max_iter": 150,
                          "ipopt.hessian_approximation": "limited-memory"})
    best = None
    for s0 in np.linspace(0.5, 0.9, starts):
        opti.set_initial(a, s0 * fw)
        if family == "square":
            opti.set_initial(b, s0 * fd)
        opti.set_initial(dx, 0.0)
        opti.set_initial(dy, 0.0)
        try:
            for k in (20.0, 60.0):
                opti.set_value(k_vis, k)
                sol = opti.solve()
                opti.set_initial(sol.value_variables())
            va = float(sol.value(a))
            vb = float(sol.value(b)) if family == "square" else None
            vdx, vdy = float(sol.value(dx)), float(sol.value(dy))
        except RuntimeError:
            try:  # IPOPT stopped early (iterations): its last point is still worth judging
                va = float(opti.debug.value(a))
                vb = float(opti.debug.value(b)) if family == "square" else None
                vdx, vdy = float(opti.debug.value(dx)), float(opti.debug.value(dy))
            except RuntimeError:
                continue
        bb = vb if vb is not None else (va * math.sqrt(3) / 2 if family == "triangular"
                                        else 0.0)
        spacing = (va, vb) if family == "square" else (va,)
        sx = (nx - 1 + (0.5 if family == "triangular" and rows > 1 else 0.0)) * va
        origin = ((x0 + x1) / 2 - sx / 2 + vdx, (y0 + y1) / 2 - (rows - 1) * bb / 2 + vdy)
        cams = mountable(site, grid_cameras(site, family, nx, ny, spacing, origin, yaw=yaw))
        ev = evaluate(site, cams, screen_step)  # a quick look; the full model if promising
        if ev.coverage >= r.coverage - 0.02 and ev.p95 <= 1.1 * r.max_error_p95:
            ev = evaluate(site, cams)
        cand = Candidate(family, nx, ny, spacing, origin, yaw, cams, ev)
        if best is None or rank_key(cand) < rank_key(best):
            best = cand
    return best
