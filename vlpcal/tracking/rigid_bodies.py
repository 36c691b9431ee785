"""Bodies: several LEDs on one robot, its pose fitted to their rays at their own capture times,
its layout checked against the tracks: the tracker's methods on them."""

from __future__ import annotations

from collections import deque

import numpy as np

from ..bodies import angles, fit_pose, gives_full_pose, pose_from_points, rotation
from .constants import (
    BODY_MEASURE,
    BRIDGE_WINDOWS,
    DEGENERATE_SHARE,
    FIT_SIGMAS,
    GATE_SIGMAS,
    LAYOUT_LEAST,
    LAYOUT_MOMENTS,
    LOST_PERIODS,
    SHAPE_SLACK,
    SHAPE_VOTES,
    WINDOW,
)
from .path_fit import _apart, _carried
from .records import LayoutMisfit, TrackUpdate, _BodyState, _Track


class RigidBodies:
    """The :class:`~vlpcal.tracking.Tracker`'s bodies: poses and layouts."""

    def _on_body(self, tr: _Track, t: float):
        """A body's LED, named, where the body's latest pose carried to ``t`` puts it — its
        position, velocity and their sigmas as :meth:`_extrapolated` gives them — when that
        pose is of the last window: the body's other LEDs place it even while its own track
        is stale (dark, or one camera alone sees it). None otherwise."""
        state = self._body_of.get(tr.led)
        if state is None or tr.tentative:
            return None
        return self._posed(state, tr.led, t)

    def _posed(self, state: _BodyState, led: str, t: float):
        """Where the body's latest pose, of the last windows, carried to ``t`` puts its LED
        ``led``: (position, velocity, their sigmas); None when it has no such pose."""
        if state.fit is None or abs(t - state.fit_t) > 2 * WINDOW * self.period:
            return None
        f, var = state.fit, np.diag(state.cov)
        dt = t - state.fit_t
        yaw = f[9] + f[10] * dt
        b = state.body.leds[led]
        R = rotation(yaw, f[11], f[12])
        lever = float(np.linalg.norm(b[:2]))
        spin = self.acceleration / max(lever, 1e-9)
        s_yaw = _carried(np.sqrt(var[9]), np.sqrt(var[10]), dt, spin)
        s_pos = float(np.hypot(_carried(np.sqrt(var[:3].mean()), np.sqrt(var[3:6].mean()), dt,
                                        self.acceleration), lever * s_yaw))
        s_vel = float(np.hypot(np.sqrt(var[3:6].mean()), self.acceleration * dt))
        vel = f[3:6] + f[10] * np.cross([0.0, 0.0, 1.0], R @ b)
        return f[:3] + f[3:6] * dt + R @ b, vel, s_pos, s_vel

    def _shaped(self, state: _BodyState, seen: dict, t: float) -> bool:
        """Whether the body's LED tracks placed now lie as far apart as its LEDs do (within
        their sigmas): a track named by a misread code is not its LED. How far apart they lay
        is kept (:meth:`layout_misfits`)."""
        body, good = state.body, True
        now = [(led, tr) for led, tr in seen.items() if t - tr.last_two <= WINDOW * self.period]
        for i, (a, ta) in enumerate(now):
            pa, _, sa, _ = self._extrapolated(ta, t)
            for b, tb in now[i + 1:]:
                pb, _, sb, _ = self._extrapolated(tb, t)
                want = body.apart(a, b)
                fits = _apart(pa, sa, pb, sb, want)[0]
                lay = float(np.linalg.norm(pa - pb))
                # measured well, for the layout it is held to or the distance it measures
                # (a layout too small is judged as readily as one too large)
                if 3 * np.sqrt(3 * (sa ** 2 + sb ** 2)) <= SHAPE_SLACK * max(want, lay):
                    seen_apart = state.apart.setdefault(tuple(sorted((a, b))),
                                                        deque(maxlen=LAYOUT_MOMENTS))
                    seen_apart.append(lay)
                    if len(seen_apart) % LAYOUT_LEAST == 0:  # judged afresh now and then
                        state.misfit = bool(self._layout_misfits(state))
                good = good and fits
        return good

    def layout_misfits(self) -> list[LayoutMisfit]:
        """The bodies whose LEDs' tracks, placed, lay apart otherwise than the deployment's
        ``bodies:`` block has them: the median over :data:`LAYOUT_LEAST` moments or more off
        by more than a body's own measure (:data:`BODY_MEASURE`) and three of its standard
        errors (from the measures' spread) — a layout in other units or measured wrong, or
        cameras of another scale (rays alone cannot tell a plan scaled about the cameras'
        height). Such a body has no rows while its verdict stands."""
        return [m for state in self.bodies for m in self._layout_misfits(state)]

    @staticmethod
    def _layout_misfits(state: _BodyState) -> list[LayoutMisfit]:
        out = []
        for (a, b), seen in sorted(state.apart.items()):
            want, lay = state.body.apart(a, b), float(np.median(seen))
            spread = 1.4826 * float(np.median(np.abs(np.asarray(seen) - lay)))
            sure = 3 * 1.2533 * spread / np.sqrt(len(seen))  # a median's standard error
            if len(seen) >= LAYOUT_LEAST and abs(lay - want) > BODY_MEASURE * want + sure:
                out.append(LayoutMisfit(state.body.id, (a, b), lay, want, len(seen)))
        return out

    def _by_shape(self, tr: _Track, t: float) -> None:
        """A track no code names yet, on a body one of whose other LEDs a track already
        names (placed now): the body's LED that lies at the right distance from every named
        one (:meth:`_beside`) — alone, and for
        :data:`SHAPE_VOTES` placements running, names it (the body's shape tells which LED it
        is)."""
        fits = []
        for state in self.bodies:
            named = {o.led: o for o in self.tracks if o.led in state.body.leds and o is not tr
                     and t - o.last_two <= WINDOW * self.period}  # placed now
            if named:
                fits += [(led, named) for led in state.body.leds
                         if led not in named and self._beside(tr, led, named)]
        # exactly one of the body's LEDs not placed now fits; if another track still holds
        # that name (a track of it not placed now), that track keeps it and this one waits
        if len(fits) != 1 or any(o.led == fits[0][0] for o in self.tracks if o is not tr):
            tr.shape_votes = (None, 0)
            return
        led, named = fits[0]
        # … and no other track no code names lies there too (another robot's LED passing
        # at that distance from the named one), nor does the body's pose put it elsewhere
        if any(o is not tr and not o.tentative and o.led == o.anonymous and o.fit is not None
               and t - o.last_two <= WINDOW * self.period and self._beside(o, led, named)
               for o in self.tracks) or not self._where_posed(tr, led, t):
            tr.shape_votes = (None, 0)
            return
        votes = tr.shape_votes[1] + 1 if tr.shape_votes[0] == led else 1
        tr.shape_votes = (led, votes)
        if votes >= SHAPE_VOTES:
            tr.led, tr.margin, tr.code = led, 0, None

    def _where_posed(self, tr: _Track, led: str, t: float) -> bool:
        """Whether the track's latest fit lies where its body's latest pose, of the last
        windows, puts ``led`` (within :data:`GATE_SIGMAS` of the two's sigmas); True when
        the body has no such pose."""
        guess = self._posed(self._body_of[led], led, tr.fit_t)
        if guess is None:
            return True
        pos, _, s_pos, _ = guess
        return bool(np.linalg.norm(tr.fit[:3] - pos) <= GATE_SIGMAS * np.hypot(s_pos, tr.s_pos))

    def _beside(self, tr: _Track, led: str, named: dict) -> bool:
        """Whether the track's latest fit lies where its body's LED ``led`` does beside the
        ``named`` tracks then: as far from each as on the body, within their sigmas
        (:func:`_apart`) — a slack of :data:`SHAPE_SLACK` of the distance or less."""
        body = self._body_of[led].body
        for other, o in named.items():
            want = body.apart(led, other)
            pos, _, s_o, _ = self._extrapolated(o, tr.fit_t)
            fits, slack = _apart(tr.fit[:3], tr.s_pos, pos, s_o, want)
            if slack > SHAPE_SLACK * want or not fits:
                return False
        return True

    def _body_due(self, tr: _Track, t: float) -> None:
        """A ray of a body's LED at ``t``: the body's row of that time is due."""
        state = self._body_of.get(tr.led)
        if state is not None and not (state.due and state.due[-1] == t):
            state.due.append(t)

    def _body_row(self, state: _BodyState, t: float) -> TrackUpdate | None:
        """The body's pose at ``t`` (:func:`vlpcal.bodies.fit_pose`) from every ray of its
        LEDs' live tracks (named by their codes or the body's shape) in the window about
        ``t``; None when fewer than two of its LEDs were seen in it, or they do not fit."""
        body = state.body
        reach = self.half
        ahead = min(self._lag, reach)
        lo, hi = t - 2 * reach + ahead, t + ahead
        rays, points, seen = [], [], {}
        for tr in self.tracks:  # per LED one track (a held one's path may be a sibling's)
            b = body.leds.get(tr.led)
            if b is None or tr.tentative or tr.led in seen:
                continue
            mine = [r for r in tr.rays if lo <= r.t <= hi]
            if not body.full_pose and mine and mine[0].t > t - 0.5 * reach:
                # back from a dark run, its window's rays all after t: its rays before the
                # window join them, so the heading at t is held between the two, not carried
                # on the one LED's rays alone (with three LEDs the others hold it, and the
                # older rays' motion model costs more than it gives)
                mine = [r for r in tr.rays if t - BRIDGE_WINDOWS * WINDOW * self.period
                        <= r.t <= hi]
            rays += mine
            points += [b] * len(mine)
            if mine:
                seen[tr.led] = tr
        if len(seen) < 2 or not self._shaped(state, seen, t) or state.misfit:
            return None  # (a layout not the robot's gives poses skewed by it)
        prior = None
        # rad/s²: the turn's rate changes no faster than its LEDs' acceleration allows
        spin = self.acceleration / max(float(np.max(np.linalg.norm(
            np.array(list(body.leds.values())), axis=1))), 1e-9)
        if state.fit is not None and abs(t - state.fit_t) <= LOST_PERIODS * self.period:
            dt = t - state.fit_t  # the last pose, carried to t
            f = state.fit
            guess = np.r_[f[:3] + f[3:6] * dt, f[3:6], np.zeros(3), f[9] + f[10] * dt, f[10],
                          f[11:13], 0.0]
            # … and its state there joins the fit, loosened threefold (the rays it held are
            # among these), widened by the motion it cannot foresee (as a track's)
            var = np.diag(state.cov)
            s2 = np.zeros(14)
            s2[:3] = _carried(np.sqrt(var[:3]), np.sqrt(var[3:6]), dt, self.acceleration) ** 2
            s2[3:6] = var[3:6] + (self.acceleration * dt) ** 2
            s2[9] = _carried(np.sqrt(var[9]), np.sqrt(var[10]), dt, spin) ** 2
            s2[10] = var[10] + (spin * dt) ** 2
            info = np.zeros(14)
            on = s2 > 0
            info[on] = 1.0 / (9.0 * s2[on])
            prior = (guess, info)
            guess_before = guess.copy()
        else:  # where its LEDs' tracks are
            led_ids = list(seen)
            pos, ang = pose_from_points([body.leds[k] for k in led_ids],
                                        [self._extrapolated(seen[k], t)[0] for k in led_ids])
            guess = np.r_[pos, np.zeros(6), ang[0], 0.0, ang[1:], 0.0]
        points = np.array(points)
        # the full pose from three LEDs or more not on one line, seen now; else the heading,
        # the tilt held (a level body's, or the last full fit's)
        full = body.full_pose and gives_full_pose([body.leds[k] for k in seen])
        if not full:
            guess[11:13] = (state.fit[11:13] if body.full_pose and state.fit is not None
                          else 0.0)
        keep = np.ones(len(rays), bool)
        for _ in range(3):  # a ray far off the others' pose (a lamp a track took): left out
            eq = np.concatenate([r.eq for r, k in zip(rays, keep) if k])
            fit, resid, cov, res = fit_pose(eq[:, :3], eq[:, 3], eq[:, 4] - t, eq[:, 5:8],
                                          eq[:, 8], eq[:, 9], np.repeat(points[keep], 2, axis=0),
                                          guess, full, self.acceleration, spin,
                                          self.pixel_sigma, prior)
            if fit is None:
                break
            off = np.hypot(res[0::2], res[1::2]) > GATE_SIGMAS
            if not off.any():
                break
            keep[np.flatnonzero(keep)[off]] = False
            guess = fit
            if len({tuple(b) for b in points[keep]}) < 2:
                return None
        if fit is None or not resid <= FIT_SIGMAS * self.pixel_sigma:
            return None
        if prior is not None and not self._follows(guess_before, s2, fit, cov):
            return None  # a pose its last one could not have moved to: a swapped LED
        # its LEDs where their own tracks, placed now, put them, within the track's sigma
        # (not the pose's too: a pose turned half round, its sigma 0.1 m, passed that): else
        # a ray was another's
        R = rotation(fit[9], fit[11], fit[12])
        for led, tr in seen.items():
            if t - tr.last_two > WINDOW * self.period:
                continue
            pos, _, s_led, _ = self._extrapolated(tr, t)
            off = float(np.linalg.norm(fit[:3] + R @ body.leds[led] - pos))
            if off > GATE_SIGMAS * np.sqrt(3) * s_led:
                return None
        rays = [r for r, k in zip(rays, keep) if k]
        sigma = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)))
        if not (sigma < DEGENERATE_SHARE * self._size
                and not self.deployment.outside(fit[:3], sigma)[0]):
            return None
        if t >= state.fit_t:
            state.fit, state.fit_t, state.cov = fit, t, cov
        cams = sorted({r.camera for r in rays})
        if full:  # one rotation has two sets of Z-Y-X angles: |pitch| ≤ π/2
            fit[9], fit[11], fit[12] = angles(rotation(fit[9], fit[11], fit[12]))
        pitch, roll = (fit[11], fit[12]) if full else (np.nan, np.nan)
        return TrackUpdate(t, body.id, fit[:3].copy(), fit[3:6].copy(), sigma,
                           "+".join(self.cameras[k].id for k in cams),
                           "ok" if len(cams) >= 2 else "one_camera",
                           (float(fit[9]), float(pitch), float(roll),
                            float(np.sqrt(max(cov[9, 9], 0.0)))))

    @staticmethod
    def _follows(before, s2, fit, cov) -> bool:
        """Whether a body's pose fitted now is one its last pose, carried here (``before``,
        its variances ``s2``), could have moved to: position and heading each within
        :data:`GATE_SIGMAS` of the two's sigmas. Two LEDs' names swapped fit a pose turned
        half round, each ray well — only the motion tells it is not the body."""
        var = np.diag(cov)
        d_pos = float(np.linalg.norm(fit[:3] - before[:3]))
        s_pos = float(np.sqrt(s2[:3].sum() + var[:3].sum()))
        d_yaw = abs(float(np.angle(np.exp(1j * (fit[9] - before[9])))))
        s_yaw = float(np.sqrt(s2[9] + var[9]))
        return d_pos <= GATE_SIGMAS * s_pos and d_yaw <= GATE_SIGMAS * s_yaw
