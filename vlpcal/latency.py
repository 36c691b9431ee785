"""Each camera's latency, learned from the rays of a moving LED.

A camera whose capture times run late (a slower link absorbed into its clock estimate, a
mis-stated ``times.csv``) sees the LED where it was earlier than its times say: with the LED
moving, its rays disagree with the others' along the path. Left alone, a quadratic path fitted
to such rays hides the disagreement in a wrong depth (two cameras, the motion along their
baseline) and the rows come out wrong with a small sigma. Here each window of a track that two
cameras or more placed adds what it says about its cameras' latencies — the information left
for them once the path's own unknowns are free (a Schur complement) and the residual's pull —
and the sum, over windows that do not share rays, gives every camera's latency relative to the
others'. The tracker places each camera's rays at the times this corrects, and a row's sigma
holds what the latencies' remaining uncertainty costs it.

A latency common to all cameras moves every time alike and is nowhere seen: the latencies are
told relative to the cameras' middle one (the lower median of those the rays have measured),
so one camera late among agreeing ones is the one corrected.
"""

from __future__ import annotations

import numpy as np

#: a camera's latency before its rays say, 1 sigma, in frame periods (clocks that agree to a
#: few frames; the rays soon say more)
PRIOR_PERIODS = 6.0
#: a camera's latency counts as measured once its rays' information passes this many times
#: the prior's
MEASURED = 10.0
#: a latency is applied (its camera's times corrected) once it is this many of its sigmas from
#: nothing: a correction within its own noise would cost more than it gains (a relative
#: half-millisecond moves a fix's height a millimetre)
APPLIED_SIGMAS = 3.0


class LatencyEstimate:
    """The cameras' latencies (s, how late each one's stated capture times run behind the
    others'), from windows' information on them. ``prior``: s, 1 sigma before any window;
    ``step``: s, the most a correction moves at a time."""

    def __init__(self, cameras: int, prior: float, step: float):
        self.prior, self.step = float(prior), float(step)
        self.information = np.zeros((cameras, cameras))  #: 1/s², summed over windows
        self.pull = np.zeros(cameras)  #: information × the latencies the windows point to
        self.value = np.zeros(cameras)  #: s: the latest estimate
        self.covariance = np.eye(cameras) * self.prior ** 2  #: s²: of ``value``
        #: s: what each camera's times are corrected by: its ``value`` once it is sure
        #: (:data:`APPLIED_SIGMAS`), else nothing
        self.applied = np.zeros(cameras)
        self._start = np.zeros(cameras)  #: s: the prior's centre
        self.windows = 0
        self.held = False  #: held where a run before put them (:meth:`restart`)
        #: the corrections follow the windows' estimate (else only a search or a run before
        #: sets them: a live stream's windows, with frames late or dropped under load, are
        #: not trusted to move a camera's times)
        self.follow = True
        #: per camera: its times checked against another's by a search of the spots (or a
        #: whole recording's windows trusted): until then a row counts its latency as unknown
        #: to the prior's spread, whatever the windows say (their word is linear only near
        #: the right times)
        self.vetted = np.zeros(cameras, bool)
        #: s², per camera: how far its latency wanders from window to window beyond what the
        #: windows' noise explains (a clock that runs fast, frames late under load): what a
        #: row adds for it, as the one latency estimated cannot follow it
        self.wander = np.zeros(cameras)
        #: over windows, s the window's information on each camera's latency (its diagonal):
        #: Σ s sᵀ and Σ s × (chi² − its expectation) — a camera k whose latency wanders by
        #: τ_k² adds τ_k² s_k to a window's chi², so the τ² are these sums' least squares
        self._scatter = np.zeros((cameras, cameras))
        self._excess = np.zeros(cameras)
        self._chi2 = np.zeros(2)  # Σ (chi² − expectation), Σ degrees of freedom

    def restart(self, applied, information=None, wander=None) -> None:
        """Start again from latencies ``applied`` (s; a search of the spots found them): what
        windows said before, with their times off, is forgotten. With ``information`` (a
        run before measured them so): they are held — no window moves them — at the
        uncertainty it gives (and ``wander``, s², the run's :attr:`wander`)."""
        self.wander = np.zeros(len(self.value)) if wander is None else np.array(wander, float)
        self._scatter[:], self._excess[:], self._chi2[:] = 0.0, 0.0, 0.0
        self._start = np.asarray(applied, float).copy()
        self.value, self.applied = self._start.copy(), self._start.copy()
        self.windows = 0
        self.held = information is not None
        self.vetted |= self.held
        self.information = np.zeros_like(self.information) if information is None \
            else np.array(information, float)
        self.pull = self.information @ self._start
        self.covariance = np.linalg.inv(self.information
                                        + np.eye(len(self.value)) / self.prior ** 2)

    def add(self, cams, information, pull, placed) -> None:
        """One window's word on cameras ``cams`` (indices, C): its C×C information on their
        latencies, its pull (information × the change it wants, C), for rays placed with
        latencies ``placed`` (C, s). (Latencies held: none.)"""
        if self.held:
            return
        cams = np.asarray(cams)
        self._scattered(cams, information, pull, placed)
        self.information[np.ix_(cams, cams)] += information
        self.pull[cams] += information @ placed + pull
        self.windows += 1

    def _scattered(self, cams, information, pull, placed) -> None:
        """One window's disagreement with the latencies so far, beyond what its noise and
        theirs explain (chi² less its expectation), summed per camera by the information the
        window has on each: a latency that holds still leaves it near nought."""
        vals, vecs = np.linalg.eigh(information)
        keep = vals > 1e-9 * max(vals.max(initial=0.0), 1e-300)
        if not keep.any():
            return
        vals, vecs = vals[keep], vecs[:, keep]
        want = placed + vecs @ (vecs.T @ pull / vals)  # the latencies this window points to
        off = vecs.T @ (want - self.value[cams])
        chi2 = float(vals @ off ** 2)
        known = float(np.trace(information @ self.covariance[np.ix_(cams, cams)]))
        if known > 0.5 * keep.sum():  # (the latencies so far less sure than this window:
            return  # its disagreement is theirs)
        expected = keep.sum() + known
        s = np.diag(information)
        self._scatter[np.ix_(cams, cams)] += np.outer(s, s)
        self._excess[cams] += s * (chi2 - expected)
        self._chi2 += (chi2 - expected, keep.sum())

    def solve(self) -> None:
        """The latencies the windows so far give, relative to their cameras' middle one."""
        if self.held:
            return
        n = len(self.value)
        prior = 1.0 / self.prior ** 2
        cov = np.linalg.inv(self.information + np.eye(n) * prior)
        value = cov @ (self.pull + prior * self._start)
        measured = self.information.diagonal() > MEASURED * prior
        if measured.any():  # the rays tell the latencies' differences only: they move from
            change = value - self._start  # where they started as their middle one does not
            middle = np.sort(change[measured])[(int(measured.sum()) - 1) // 2]
            value = self._start + np.where(measured, change - middle, 0.0)
        self.value, self.covariance = value, cov
        excess, dof = self._chi2
        self.wander = np.zeros(n)
        if excess > 3.0 * np.sqrt(2.0 * max(dof, 1.0)):  # (beyond the chi²'s own spread)
            seen = self._scatter.diagonal() > 0
            fit = np.linalg.lstsq(self._scatter[np.ix_(seen, seen)], self._excess[seen],
                                  rcond=None)[0]
            self.wander[seen] = np.maximum(fit, 0.0)
        # from clocks taken to agree, a correction within its own noise costs more than it
        # gains; from latencies found before, the estimate is the best word
        sure = np.abs(value - self._start) > APPLIED_SIGMAS * np.sqrt(
            self._relative(cov).diagonal()) if not self._start.any() else True
        if not self.follow:  # (the windows' word weighs in the sigmas only)
            return
        want = np.where(sure & measured, value, self._start)
        # a window's word is linear in the latencies only near the times its rays were
        # placed at: the correction moves by a frame period at most per solve
        self.applied = self.applied + np.clip(want - self.applied, -self.step, self.step)

    def relative(self, cams) -> np.ndarray:
        """The covariance (s²) of cameras ``cams``' latencies relative to their mean: what a
        window of theirs can be wrong by (a shift common to them moves its time only)."""
        cams = np.asarray(cams)
        left = (self.value - self.applied)[cams]  # a latency not applied: all of it
        cov = self.covariance[np.ix_(cams, cams)] + np.diag(
            np.where(self.vetted[cams], 0.0, self.prior ** 2) + self.wander[cams])
        return self._relative(cov) + np.diag(left ** 2)

    @staticmethod
    def _relative(cov) -> np.ndarray:
        m = np.eye(len(cov)) - 1.0 / len(cov)
        return m @ cov @ m

    def measured(self) -> np.ndarray:
        """Per camera: whether its rays have measured its latency."""
        return self.information.diagonal() > MEASURED / self.prior ** 2


#: the skew searched between two cameras' times: this many frame periods either way …
SEARCH_PERIODS = 30
#: … in steps of this share of a period, then finer around the best
SEARCH_STEP = 0.25
#: a pair's skew is believed when this share of its first camera's spots that have the
#: second's about then met them there, at least :data:`SEARCH_LEAST` of them, and clearly more
#: than at any skew :data:`SEARCH_APART` frame periods away
SEARCH_MET, SEARCH_LEAST, SEARCH_APART = 0.8, 20, 2.0
#: … and when the skews that meet about as well span less than this share of those searched
SEARCH_WIDEST = 0.25


def pair_skew(times_a, dirs_a, times_b, dirs_b, baseline, f_b: float, gate: float,
              period: float) -> tuple[float, float] | None:
    """How much later camera b's stated times run than camera a's, and how surely (the half
    width of the skews that meet as well; s), from their spots of one
    LED alone: at the right skew, each of a's rays (``times_a`` N, world directions ``dirs_a``
    N×3) and b's ray of the same moment (b's frames ``times_b`` M, ``dirs_b`` M×3, one spot
    each, interpolated between frames) lie in one plane with the baseline (b's centre less
    a's, 3) — within ``gate`` px at b's focal length ``f_b``. None when no skew is clearly the
    one: too few spots together, or others meet nearly as well (the motion along the
    baseline, or across it only briefly)."""
    if len(times_b) < 2 or not len(times_a):
        return None
    normal = np.cross(baseline, dirs_a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)

    def met(skews):
        target = times_a[:, None] + skews[None, :]  # N × S: b's time of each of a's spots
        i1 = np.clip(np.searchsorted(times_b, target), 1, len(times_b) - 1)
        t0, t1 = times_b[i1 - 1], times_b[i1]
        near = (t0 <= target) & (target <= t1) & (t1 - t0 <= 2.5 * period)
        frac = np.where(t1 > t0, (target - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
        d = dirs_b[i1 - 1] + (dirs_b[i1] - dirs_b[i1 - 1]) * frac[..., None]
        off = np.abs(np.einsum("nk,nsk->ns", normal, d)) / np.linalg.norm(d, axis=-1)
        return (near & (f_b * off <= gate)).sum(axis=0), near.sum(axis=0)

    reach = SEARCH_PERIODS * period
    step = SEARCH_STEP * period
    coarse = np.arange(-reach, reach + 1e-12, step)
    counts, _ = met(coarse)
    i = int(np.argmax(counts))
    top = int(counts[i])
    lo = hi = i  # the plateau around the best (a path across the epipolar planes slowly
    while lo > 0 and counts[lo - 1] >= top - 3 * np.sqrt(top):  # meets over a spread of
        lo -= 1  # skews): its middle
    while hi < len(coarse) - 1 and counts[hi + 1] >= top - 3 * np.sqrt(top):
        hi += 1
    apart = SEARCH_APART * period
    elsewhere = counts[(coarse < coarse[lo] - apart) | (coarse > coarse[hi] + apart)]
    if hi - lo > SEARCH_WIDEST * len(coarse) or not len(elsewhere):
        return None  # (as well met at skews far apart: the LED barely moved across the planes)
    rival = int(elsewhere.max())
    fine = np.arange(coarse[lo] - step, coarse[hi] + step + 1e-12, 0.05 * period)
    fc, fn = met(fine)
    j = int(np.argmax(fc))
    if fc[j] < SEARCH_LEAST or fc[j] < SEARCH_MET * fn[j] or fc[j] - rival <= 3 * np.sqrt(top):
        return None
    best = fine[fc >= fc[j] - np.sqrt(fc[j])]
    return float(np.median(best)), float(0.5 * (best.max() - best.min()) + 0.05 * period)


def camera_latencies(n: int, skews) -> np.ndarray:
    """Per camera latency (s, relative to the cameras' middle one) from pairs' skews
    ``(a, b, b's times later than a's)``: least squares over the pairs; cameras in no pair, 0."""
    skews = list(skews)
    value = np.zeros(n)
    if not skews:
        return value
    M = np.zeros((len(skews) + 1, n))
    y = np.zeros(len(skews) + 1)
    for i, (a, b, s) in enumerate(skews):
        M[i, b], M[i, a], y[i] = 1.0, -1.0, s
    seen = sorted({c for a, b, _ in skews for c in (a, b)})
    M[-1, seen] = 1.0  # (their mean 0: the gauge, set to their middle one below)
    value = np.linalg.lstsq(M, y, rcond=None)[0]
    middle = np.sort(value[seen])[(len(seen) - 1) // 2]
    value[seen] -= middle
    return value
