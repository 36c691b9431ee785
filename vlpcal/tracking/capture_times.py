"""Each camera's capture times checked against the others' — a latency, a wander, a drift —
from the LED's motion (:mod:`vlpcal.latency`): the tracker's methods on them."""

from __future__ import annotations

import numpy as np

from ..fit_watch import FitWatch
from ..latency import APPLIED_SIGMAS, camera_latencies, pair_skew
from .constants import (
    GATE_SIGMAS,
    LINEAR_PERIODS,
    SEARCH_EVERY,
    SEARCH_FRAMES,
    SEARCH_RESTARTS,
    SKEW_FRAMES,
    SKEW_WAIT,
    VET_FRAMES,
)
from .path_fit import _HALF_SQUARE, _POWERS
from .records import TimesDrift


class CaptureTimes:
    """The :class:`~vlpcal.tracking.Tracker`'s checks of the cameras' capture times."""

    def misfit(self):
        """Whether the frames do not fit the deployment (:meth:`FitWatch.misfit`) — unless a
        camera's times do not fit the others': the first time they seem not to, the cameras'
        times are searched (:meth:`_search_times`) and a skew found is applied, the frames
        then judged anew."""
        misfit = self.fit.misfit()
        if misfit is None or self._searched:
            return misfit
        full = sum(len(q) >= SKEW_FRAMES // 2 for q in self._one_spot.values()) >= 2
        waited = self.fit.moments >= SKEW_WAIT * self.fit.least
        if not full and not waited:
            return None  # (too few spots to search the times by yet)
        if self._frames_since_search >= SEARCH_EVERY or not waited:
            self._frames_since_search = 0
            if self._search_times():
                self._searched = True
                return None
        if self.fit.moments < 2 * SKEW_WAIT * self.fit.least:
            return None  # (searched in vain: again on the next frames, a while)
        self._searched = True
        return misfit

    def _search_times(self) -> bool:
        """The cameras' latencies searched on their latest one-spot frames
        (:func:`~vlpcal.latency.pair_skew`): when a pair's skew is not what the latencies
        applied give it (by half a frame period or more), the latencies found are applied and
        the tracks started again (their rays were placed at the wrong times). Whether so."""
        if self.spots != 1:
            return False
        skews = self._skews()
        applied = self.latency.applied
        off = [abs(s - (applied[b] - applied[a])) >= max(0.5 * self.period, within)
               for a, b, (s, within) in skews]
        if not any(off):  # the times as corrected agree: those cameras are vetted
            self.latency.vetted[[c for a, b, _ in skews for c in (a, b)]] = True
            return False
        if self._restarts >= SEARCH_RESTARTS:
            return False  # (times whose skews keep changing are no latency: judged as they are)
        self.latency.restart(camera_latencies(len(self.cameras),
                                              [(a, b, s) for a, b, (s, _) in skews]))
        self.latency.vetted[[c for a, b, _ in skews for c in (a, b)]] = True
        self._restarts += 1
        self.tracks, self.held, self._pending = [], [], []
        self._one_spot.clear()  # (and the frames judged anew: those before had times off)
        self.fit = FitWatch(self.fit.deployment, self.fit.what, least=self.fit.least)
        return True

    def _unvetted(self) -> bool:
        """Whether a camera's times wait for a search (live: :attr:`LatencyEstimate.vetted`)
        and it and another have the one-spot frames for one (:data:`VET_FRAMES`)."""
        if self.spots != 1 or self.latency.vetted.all():
            return False
        ready = [k for k, q in self._one_spot.items() if len(q) >= VET_FRAMES]
        return len(ready) >= 2 and not self.latency.vetted[ready].all()

    def in_order(self, frames) -> list:
        """``(time, camera id, …)`` frames in the order of their capture times as the cameras'
        latencies found so far correct them (the order :meth:`update_spots` wants them in)."""
        applied = self.latency.applied
        return sorted(frames, key=lambda f: f[0] - applied[self._camera(f[1])])

    def latencies(self) -> dict:
        """Camera id → how late its capture times were found to run behind the others' (s),
        for the cameras whose times are corrected."""
        return {c.id: float(v) for c, v in zip(self.cameras, self.latency.applied) if v}

    def wandering(self) -> dict:
        """Camera id → how far (s, 1 sigma) its latency wanders from window to window beyond
        the windows' noise (:attr:`LatencyEstimate.wander`), for cameras where it passes a
        tenth of a frame period."""
        spread = np.sqrt(self.latency.wander)
        return {c.id: float(v) for c, v in zip(self.cameras, spread) if v > 0.1 * self.period}

    def search_times(self, frames) -> list[TimesDrift]:
        """Before a recording is tracked: its cameras' latencies searched on all its one-spot
        frames (``(time, camera id, spots K×2 px)``; :func:`~vlpcal.latency.pair_skew`) and
        those found applied from its first frame on — unless a pair's skew changes along the
        recording (a clock that drifts, frames numbered rather than timed): then those pairs
        are returned (and nothing applied), as their times place no frame right."""
        if self.spots != 1:  # (several LEDs: a frame with one spot may be either one's)
            return []
        self.latency.follow = True  # a whole recording: its windows move the corrections
        self.latency.vetted[:] = True  # (and its search sees all its spots)
        logs: dict = {}
        for t, cid, uvs in frames:
            k = self._camera(cid)
            uvs = np.asarray(uvs, float).reshape(-1, 2)
            uvs = uvs[np.isfinite(uvs).all(axis=1)]
            if len(uvs) == 1:
                logs.setdefault(k, []).append((t, uvs[0]))
        one = {}
        for k, seen in logs.items():
            seen = seen[::max(1, len(seen) // SEARCH_FRAMES)]  # (an even sample of a long run)
            xy = self.cameras[k].normalise(np.array([uv for _, uv in seen]) - self._offset[k])
            ok = np.isfinite(xy).all(axis=1)
            one[k] = (np.array([t for t, _ in seen])[ok], np.c_[xy[ok], np.ones(ok.sum())]
                      @ self._R[k])
        drifts = self._drifts(one)
        if drifts:
            return drifts
        skews = self._skews(one)
        if any(abs(s) >= 0.5 * self.period for _, _, (s, _) in skews):  # (within that, the
            self.latency.restart(camera_latencies(  # windows tell them better)
                len(self.cameras), [(a, b, s) for a, b, (s, _) in skews]))
        return []

    def _drifts(self, logs) -> list[TimesDrift]:
        """Pairs of cameras whose skew, searched on stretches of the recording, changes along
        it by more than a frame period and its own uncertainty."""
        if not logs:
            return []
        start = min(float(t[0]) for t, _ in logs.values() if len(t))
        end = max(float(t[-1]) for t, _ in logs.values() if len(t))
        # stretches of SKEW_FRAMES periods, a short recording's a third of it (not under a
        # third of SKEW_FRAMES: a stretch must hold enough spots to search)
        least = SKEW_FRAMES / 3 * self.period
        span = max(least, min(SKEW_FRAMES * self.period, (end - start) / 3))
        out: dict = {}
        for (a, b), seen in self._stretch_skews(logs, start, end, span).items():
            first = min(seen, key=lambda x: x[1])
            last = max(seen, key=lambda x: x[1])
            if last[1] - first[1] > max(self.period, first[2] + last[2]):
                out[a, b] = seen
        # a steady drift (a clock a fraction of a percent fast) seen on the shortest
        # stretches: a slope clear of the skews' own scatter about it, worth a frame period
        for (a, b), seen in self._stretch_skews(logs, start, end, least).items():
            if (a, b) in out or len(seen) < 4:
                continue
            t, skew = np.array([x[0] for x in seen]), np.array([x[1] for x in seen])
            slope, centre = np.polyfit(t, skew, 1)
            scatter = np.sqrt(np.sum((skew - slope * t - centre) ** 2) / (len(t) - 2))
            se = scatter / np.sqrt(np.sum((t - t.mean()) ** 2))
            if abs(slope) * (t.max() - t.min()) > self.period and abs(slope) > 4.0 * se:
                out[a, b] = seen
        return [TimesDrift(self.cameras[a].id, self.cameras[b].id,
                           tuple((t, s) for t, s, _ in sorted(seen)))
                for (a, b), seen in out.items()]

    def _stretch_skews(self, logs, start: float, end: float, span: float) -> dict:
        """(a, b) → [(middle time, skew, how surely)] of the recording's stretches ``span``
        long that tell the pair's skew."""
        edges = np.arange(start, end + span, span)
        found: dict = {}
        for lo, hi in zip(edges[:-1], edges[1:]):
            part = {k: (t[(t >= lo) & (t < hi)], d[(t >= lo) & (t < hi)])
                    for k, (t, d) in logs.items()}
            for a, b, (skew, within) in self._skews(part):
                found.setdefault((a, b), []).append((0.5 * (lo + hi), skew, within))
        return found

    def _skews(self, logs=None) -> list:
        """(a, b, (how much later b's stated times run than a's, how surely)) for pairs of
        cameras whose one-spot frames (``logs``: camera → times, world directions; default:
        the latest ones) tell it."""
        gate = 2 * GATE_SIGMAS * self.pixel_sigma
        if logs is None:  # the latest one-spot frames of each camera
            logs = {k: (np.array([t for t, _ in q]), np.array([d for _, d in q]))
                    for k, q in self._one_spot.items()}
        logs = {k: v for k, v in logs.items() if len(v[0]) >= 2}
        out = []
        for a, (ta, da) in logs.items():
            for b, (tb, db) in logs.items():
                if b <= a:
                    continue
                skew = pair_skew(ta, da, tb, db, self._C[b] - self._C[a], float(self._f[b]),
                                 gate, self.period)
                if skew is not None:
                    out.append((a, b, skew))
        return out

    def _timed(self, rays, t0: float, fit, cov, learn: bool) -> float | None:
        """A window the fit placed, judged against the cameras' latencies
        (:mod:`vlpcal.latency`): m², what their remaining uncertainty adds to its position's
        variance (its fit moves with them); None when its rays want a latency past what one
        window's linear word can tell (:data:`LINEAR_PERIODS`: its path bent to fit rays at
        wrong times — no place, and the cameras' times are searched). ``learn``: its
        information on the latencies (the path free) and the residuals' pull are added. One
        LED's tracks only (:attr:`spots` 1)."""
        if self.spots != 1:  # several LEDs: a window may hold another LED's spot a while,
            return 0.0  # and disagree for that — their times are taken as stated
        A, G, e, cams = self._timed_design(rays, t0, fit)
        AG = A.T @ G
        if len(cams) >= 2:
            S = G.T @ G - AG.T @ cov @ AG  # (cov's weights were its guess's: kept ≥ 0)
            vals, vecs = np.linalg.eigh(0.5 * (S + S.T))
            g = G.T @ e
            keep = vals > 1e-9 * max(vals.max(), 1e-300)  # (a shift common to all: not seen)
            along = vecs[:, keep].T @ g
            change = vecs[:, keep] @ (along / vals[keep])
            if np.abs(change).max(initial=0.0) > LINEAR_PERIODS * self.period \
                    and along @ (along / vals[keep]) > APPLIED_SIGMAS ** 2:  # (and sure)
                self._suspect = True
                return None
            if learn:
                placed = np.array([np.mean([r.shift for r in rays if r.camera == c])
                                   for c in cams])
                self.latency.add(cams, (vecs * np.maximum(vals, 0.0)) @ vecs.T, g, placed)
                if self.latency.windows % max(1, len(self.cameras) // 32) == 0:
                    self.latency.solve()  # (an n × n solve: not every window of a large site's)
        J = -(cov @ AG)[:3]
        return float(np.einsum("ij,jk,ik->", J, self.latency.relative(cams), J))

    def _timed_design(self, rays, t0: float, fit):
        """A window's equations at the fit ``fit`` (9), each in its spot sigmas: on the path
        (2m × 9), on the latencies of its cameras ``cams`` (2m × C: a later time places the LED
        back along its velocity), and their residuals (2m)."""
        eq = np.concatenate([r.eq for r in rays])
        rows, y, tt = eq[:, :3], eq[:, 3], eq[:, 4] - t0
        P = tt[:, None] ** _POWERS * _HALF_SQUARE
        A = (P[:, :, None] * rows[:, None, :]).reshape(-1, 9)
        f = fit.reshape(3, 3)
        depth = np.einsum("ij,ij->i", eq[:, 5:8], P @ f) - eq[:, 8]
        w = eq[:, 9] / np.maximum(depth, 1e-9)
        cams, col = np.unique(np.repeat([r.camera for r in rays], 2), return_inverse=True)
        G = np.zeros((len(eq), len(cams)))
        G[np.arange(len(eq)), col] = -np.einsum("ij,ij->i", rows, f[1] + tt[:, None] * f[2]) * w
        return A * w[:, None], G, (y - A @ fit) * w, cams
