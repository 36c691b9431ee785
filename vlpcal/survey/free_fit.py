"""A free survey's joint fit: its unknowns from one start (the references, then the free
points used), their priors, the fit with its rejection of spots that disagree, and the choice
between the starts — the deployment's cameras, or those placed from the free sets — by which
fit explains the data better."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .calibration import estimate_precision
from .free_checks import REJECT_SIGMAS
from .free_start import free_positions, median_reprojection, reference_start
from .network import EPIPOLAR_SHARE, align_to_references, label_wand, network_start
from .wand import (
    HELD_OUT_EVERY,
    LABEL_TOLERANCE,
    WAND_PRECISION,
    check_wand_length,
    wand_points,
    wrong_lengths,
)

#: the free sets one calibration uses at most (an even sample beyond): the fit's time grows
#: with the sets, and some tens of thousands exhaust the sparse solver's memory
MAX_FREE_SETS = 5000
#: pixels are square: a camera's fx / fy stays the deployment's within this relative spread
#: (a lens's anamorphism or a sensor's scaling, about 1 %, as a scatter; without it a camera
#: that sees the LED over part of its image stretches one focal length against its pose)
ASPECT_SPREAD = 0.02
#: a start from the data is tried when it fits the free sets this many times better than the
#: nominal cameras (median reprojection error), and kept when the fit from it is this many
#: times better again (:func:`_misfit`, with a k1 lens)
BETTER_START = 0.5


@dataclass
class FreeUnknowns:
    """The joint fit's unknowns from one start, and what its rejection dropped: the references
    then the free points used, and each one's spots."""

    X0: np.ndarray  #: N×3 the references' start (as measured, empty cells from the cameras)
    pts_free: np.ndarray  #: C×M×2 the free points' spots (a wand's LEDs at 2m, 2m + 1)
    P0: np.ndarray  #: the unknown points' start: the references, then the free points used
    free: np.ndarray  #: per point, a free LED (no prior)
    unmeasured: np.ndarray  #: per point and axis, no measured coordinate
    uv_all: np.ndarray  #: C×P×2 every point's spots
    pair_i: np.ndarray  #: a wand set's first LED (its second follows)
    free_idx: np.ndarray  #: the free points used, of ``pts_free``
    held_out: np.ndarray  #: per free point, held out of the fit to judge a wand's length
    dropped: int = 0  #: free sets of two views that disagree (which is wrong: unknown)
    rejected: dict = field(default_factory=dict)  #: camera id → spots rejected


class FreeFit:
    """A free survey's joint fit: the references ``X`` (N×3, NaN: not measured) and their
    spots ``uv`` (C×N×2), the free points' spots given per start — with their priors (the
    references' precision ``stated``, or estimated where None), a stated ``free_height``, a
    ``wand``'s length between each set's LEDs, and square pixels."""

    def __init__(self, nominal, X, uv, free_height, wand, stated, share, scale, notes, tick):
        self.nominal, self.X, self.uv = nominal, X, uv
        self.N, self.measured = len(X), np.isfinite(X)
        self.ids = [c.id for c in nominal]
        self.free_height, self.wand, self.stated = free_height, wand, stated
        self.wand_sigma = None if wand is None else WAND_PRECISION * wand
        self.per_set = 2 if wand is not None else 1
        self.share, self.scale, self.notes, self.tick = share, scale, notes, tick
        self.aspect = (np.array([c.fx / c.fy for c in nominal]), ASPECT_SPREAD)

    def unknowns(self, pts_free, cams, X0) -> tuple[FreeUnknowns, np.ndarray]:
        """The joint fit's unknowns from the free points' spots ``pts_free`` (C×M×2), started
        from ``cams``: the references, then the usable free points (two views, or one at a
        stated height; a wand's set whole, every tenth set held out to judge it; an even
        sample of at most :data:`MAX_FREE_SETS` sets). Returns them and the spots kept
        (C×P)."""
        N, per_set = self.N, self.per_set
        seen_p = np.isfinite(pts_free).all(axis=2)
        F0 = free_positions(cams, pts_free, self.free_height)
        usable = np.isfinite(F0).all(axis=1)
        if self.free_height is None:
            usable &= seen_p.sum(axis=0) >= 2
        possible = F0[:, 2] > -0.05 * self.scale  # not under the floor (a floor's mirror image)
        for k, cam in enumerate(cams):  # in front of every camera that saw it (cheirality)
            depth = cam.to_camera(np.nan_to_num(F0))[:, 2]
            possible &= ~seen_p[k] | (depth > 0.05 * self.scale)
        # two views that cannot both be of the LED are dropped here; of three or more, the
        # fit's rejection finds the one that is not
        impossible = usable & ~possible & (seen_p.sum(axis=0) <= 2)
        usable &= ~impossible
        held_out = np.zeros(len(usable), bool)
        if self.wand is not None:
            whole = usable[0::2] & usable[1::2]
            out = np.zeros(len(whole), bool)
            out[np.flatnonzero(whole)[HELD_OUT_EVERY - 1::HELD_OUT_EVERY]] = True
            held_out = np.repeat(out, 2)
            usable = np.repeat(whole & ~out, 2)
        free_idx = np.flatnonzero(usable)
        if len(free_idx) > MAX_FREE_SETS * per_set:  # time and memory bounded
            sets = free_idx[::per_set]
            note = (f"{len(sets)} free sets usable: {MAX_FREE_SETS} of them, evenly spread in "
                    "time, calibrate the cameras (more add little and cost much)")
            self.notes[:] = [n for n in self.notes
                             if not n.endswith("(more add little and cost much)")]
            self.notes.append(note)
            sets = sets[np.linspace(0, len(sets) - 1, MAX_FREE_SETS).round().astype(int)]
            free_idx = (sets[:, None] + np.arange(per_set)).ravel()
        u = FreeUnknowns(
            X0=X0, pts_free=pts_free, P0=np.vstack([X0, F0[free_idx]]),
            free=np.r_[np.zeros(N, bool), np.ones(len(free_idx), bool)],
            unmeasured=np.r_[~self.measured, np.zeros((len(free_idx), 3), bool)],
            uv_all=np.concatenate([self.uv, pts_free[:, free_idx]], axis=1),
            pair_i=N + np.arange(0, len(free_idx), 2) if self.wand is not None
            else np.zeros(0, int),
            free_idx=free_idx, held_out=held_out, dropped=int(impossible.sum()),
            rejected=dict.fromkeys(self.ids, 0))
        return u, np.isfinite(u.uv_all).all(axis=2)

    def lengths(self, u: FreeUnknowns, keep):
        """The wand's lengths between LEDs that two cameras still see each."""
        if self.wand is None:
            return None
        pair_i = u.pair_i
        ok = (keep[:, pair_i].sum(axis=0) >= 2) & (keep[:, pair_i + 1].sum(axis=0) >= 2)
        return pair_i[ok], pair_i[ok] + 1, self.wand, self.wand_sigma

    def prior(self, u: FreeUnknowns, s_x):
        """Per coordinate, how well it is known (m): the references' precision where they
        were measured, nothing for a free LED, the stated height as good as exact."""
        sig = np.full((len(u.free), 3), float(s_x))
        sig[:self.N] *= self.share
        sig[u.free] = np.inf
        sig[u.unmeasured] = np.inf
        if self.free_height is not None:
            sig[u.free, 2] = 1e-3 * s_x
        return sig

    def adjust(self, u: FreeUnknowns, cams, models, keep):
        """The joint fit of the spots ``keep`` (C×P) from ``cams`` with the lens ``models``,
        the precisions estimated: (observations, (s_x m, s_px px, cameras, points))."""
        obs = _observations(u.uv_all, keep)
        s_px0 = 0.1
        return obs, estimate_precision(cams, u.P0, obs, models, s_px0, point_sigma=self.stated,
                                       free=u.free, fixed_height=self.free_height,
                                       unmeasured=u.unmeasured, lengths=self.lengths(u, keep),
                                       share=np.r_[self.share, np.ones((len(u.free) - self.N,
                                                                        3))],
                                       aspect=self.aspect)

    def reject(self, u: FreeUnknowns, cams, models, keep):
        """Fit; reject what does not fit; fit again (three rounds at most). Returns (obs, s_x,
        s_px, cameras, points, keep)."""
        N, free = self.N, u.free
        for _ in range(3):
            obs, (s_x, s_px, cams, adj) = self.adjust(u, cams, models, keep)
            self.tick()
            err = np.full(keep.shape, 0.0)
            for k, cam in enumerate(cams):
                idx = np.flatnonzero(keep[k])
                e = np.linalg.norm(cam.project(adj[idx])[0] - u.uv_all[k, idx], axis=1)
                err[k, idx] = np.nan_to_num(e, nan=np.inf)
            wrong = err.max(axis=0) > REJECT_SIGMAS * s_px
            long = wrong_lengths(adj, u.pair_i, keep, self.wand, self.wand_sigma)
            if long.any():  # a wand set whose two "LEDs" are not the bar's ends
                keep[:, u.pair_i[long]] = keep[:, u.pair_i[long] + 1] = False
                wrong[u.pair_i[long]] = wrong[u.pair_i[long] + 1] = False
                u.dropped += int(long.sum())
            if not wrong.any() and not long.any():
                break
            views = keep.sum(axis=0)
            # three views or more (or a reference, which its record holds): the worst spot is
            # the one that disagrees; two views of a free LED that disagree cannot say which
            blame = wrong & ((views >= 3) | ~free | (self.free_height is not None))
            worst = err.argmax(axis=0)
            for j in np.flatnonzero(blame):
                keep[worst[j], j] = False
                u.rejected[self.ids[worst[j]]] += 1
            pair = wrong & ~blame
            keep[:, pair] = False
            u.dropped += int(pair.sum())
            if self.free_height is None:  # a free set left with one view fixes nothing
                keep[:, N:] &= keep[:, N:].sum(axis=0) >= 2
        return obs, s_x, s_px, cams, adj, keep

    def fitted_from(self, cams, pts):
        """The pose-only fit, with rejection, from a start; and the unknowns it fitted."""
        u, keep = self.unknowns(pts, cams, reference_start(cams, self.X, self.uv))
        got = self.reject(u, list(cams), ["pose"] * len(cams), keep)
        return got, u


def _observations(uv_all, keep):
    return [(np.flatnonzero(keep[k]), uv_all[k, keep[k]]) for k in range(len(uv_all))]


def _misfit(fit, s_x: float, s_px: float) -> float:
    """How badly a pose-only fit (:meth:`FreeFit.fitted_from`'s) explains its data, on one
    scale for every start (``s_x`` m, ``s_px`` px): the squared residuals of every spot and
    every measured reference coordinate in units of those, each capped at three (a rejected
    spot counts as the cap), so that a start whose fit throws data out or strains the
    references loses to one that explains them."""
    (_, _, _, cams, adj, keep), u = fit
    total = 0.0
    for k, cam in enumerate(cams):
        seen = np.isfinite(u.uv_all[k]).all(axis=1)
        r = np.linalg.norm(cam.project(adj[seen])[0] - u.uv_all[k, seen], axis=1) / s_px
        r = np.where(keep[k, seen], np.nan_to_num(r, nan=3.0), 3.0)
        total += float(np.sum(np.minimum(r, 3.0) ** 2))
    n = len(u.X0)
    known = ~u.unmeasured[:n]
    r = np.abs(adj[:n] - u.X0)[known] / s_x
    return total + float(np.sum(np.minimum(r, 3.0) ** 2))


def fit_starts(nominal, X, uv, uv_free, spots, wand, labelled):
    """The fit's starts, each with its free points' spots, and how well each fits them (median
    reprojection, px): the deployment's cameras, and those placed from the free sets where
    they fit them far better (:data:`BETTER_START`; a hand-hung install), both moved onto the
    references first (marks define a frame of their own). A wand's ends are named per set by
    the pairwise matching where two of its cameras have it, else by the start's cameras."""
    net = network_start(nominal, spots, labelled or wand is None, wand)
    if wand is not None and (labelled or net is not None):
        check_wand_length(nominal, wand_points(spots, None if labelled else net.order,
                                               labelled), wand)
    starts = [align_to_references(list(nominal), uv, X)]
    if net is not None:
        starts.append(align_to_references(net.cameras, uv, X, scale_fixed=wand is not None))

    def points_of(cams):
        if wand is None:
            return uv_free
        if labelled:
            return wand_points(spots, None, True)
        if net is not None:  # within a few times the start's own misfit
            tol = LABEL_TOLERANCE * median_reprojection(cams, wand_points(spots, net.order,
                                                                          False))
        else:  # a share of the image (the epipolar bound of the pairwise matching)
            tol = EPIPOLAR_SHARE * float(np.median([np.hypot(c.width, c.height)
                                                    for c in nominal]))
        order = label_wand(cams, spots, wand, tol if np.isfinite(tol) else np.inf)
        if net is not None:
            tree = (net.order >= 0).any(axis=2).sum(axis=0) >= 2
            order[:, tree] = net.order[:, tree]
        return wand_points(spots, order, False)

    tries = [(cams, points_of(cams)) for cams in starts]
    errs = [median_reprojection(cams, pts) for cams, pts in tries]
    if len(tries) > 1 and not errs[1] < BETTER_START * errs[0]:
        tries, errs = tries[:1], errs[:1]
    return tries, errs


def best_fit(fit: FreeFit, tries):
    """From each start, the pose-only fit with rejection; the one whose spots then scatter
    least, which is the deeper minimum of the same data — judged with a lens (k1) fitted
    from each: a pose-only fit leaves the lenses' error in the references of both alike,
    and cannot tell the minima apart. The deployment's start is kept unless its fit is far
    worse: where both fit alike, the data's start has shown no better minimum (and, on a
    carefully hung install, can lead the lens choice astray). Returns (the chosen fit, its
    index, every fit)."""
    fits = [fit.fitted_from(cams, pts) for cams, pts in tries]
    if len(fits) == 1:
        return fits[0], 0, fits
    judged = []
    for got, u in fits:
        obs_, (s_x_, s_px_, cams_, adj_) = fit.adjust(u, got[3], ["k1"] * len(got[3]), got[5])
        judged.append(((obs_, s_x_, s_px_, cams_, adj_, got[5]), u))
    # one scale for both: the finer fit's (a start that diverged has none)
    s_x0 = float(np.nanmin([j[0][1] for j in judged] + [np.inf]))
    s_px0 = float(np.nanmin([j[0][2] for j in judged] + [np.inf]))
    m = [_misfit(j, s_x0, s_px0) for j in judged]
    m = [v if np.isfinite(v) else np.inf for v in m]
    best = 1 if m[1] < BETTER_START * m[0] else 0
    return fits[best], best, fits
