"""One id per LED: a track one camera alone sees is held and taken up again by its path in the
image, and LEDs are named by their blink codes: the tracker's methods on them."""

from __future__ import annotations

import numpy as np

from ..blink import MAX_OBSERVATIONS, WINDOW_REPEATS, decode_phase
from .constants import (
    BIT_EDGE,
    COAST_PERIODS,
    GATE_SIGMAS,
    KNOWN_BITS,
    MISSED_BITS,
    PATH_GAP,
    PATH_SPOTS,
    TOP_SPEED,
    VIEW_MARGIN_PX,
    WINDOW,
)
from .path_fit import _slope
from .records import _Ray, _Track


class Identity:
    """The :class:`~vlpcal.tracking.Tracker`'s ids: held tracks, their rejoining, blink names."""

    def _hold(self, tr: _Track) -> None:
        """An ended track held for one that continues it (followed by its path in the image
        of the camera that saw it last)."""
        if tr.latest is None:
            tr.latest = tr.rays[-1] if tr.rays else None
        if tr.latest is not None:
            tr.held_since = tr.latest.t
            self.held.append(tr)

    def _fresh(self, tr: _Track, t: float) -> bool:
        """Whether the track's 3D state foresees its spots: not held, and no spot it took for
        longer than a window failed to place it (one camera alone seeing it: then only its path
        in an image does; a track that saw no spot at all — a blink code's dark run — keeps
        its state, whose sigma grows with the time)."""
        return tr.held_since == np.inf and (tr.tentative or not self._coasting(tr))

    def _coasting(self, tr: _Track) -> bool:
        """Whether the spots the track took for longer than a window did not place it (one
        camera alone seeing it; a track that saw no spot — a blink code's dark run — is not)."""
        return tr.last_ray - tr.unplaced_since > WINDOW * self.period

    def _path_gap(self, tr: _Track, k: int, xy, t: float):
        """How far spots at ``xy`` (J×2, time ``t``) are from the track's recent path in camera
        ``k`` — its last :data:`PATH_SPOTS` spots there, carried on at their velocity — in gate
        widths (≤ 1: it can be the same LED): the spot noise and the acceleration possible since
        (:data:`ACCELERATION`). Inf where it has no spot there for :data:`PATH_GAP` frame
        periods (the LED left the view, is hidden or dark: its path is lost)."""
        seen = [r for r in tr.rays[-3 * PATH_SPOTS:] if r.camera == k][-PATH_SPOTS:]
        if not seen or not 0 <= t - seen[-1].t <= PATH_GAP * self.period:
            return np.full(len(xy), np.inf)
        last, dt = seen[-1], t - seen[-1].t
        depth = max(float(self._R[k, 2] @ (tr.fit[:3] - self._C[k])), 1e-9)
        if len(seen) >= 2 and seen[-1].t > seen[0].t:  # its velocity there: a line's slope
            v = _slope(np.array([r.t for r in seen]), np.array([r.xy for r in seen]))
            spread = self.acceleration * dt * (dt + self.period)
        else:  # one spot: anywhere its top speed reaches
            v, spread = np.zeros(2), TOP_SPEED * dt
        sigma = np.hypot(np.sqrt(2) * self.pixel_sigma / self._f[k], spread / depth)
        return np.linalg.norm(np.asarray(xy) - last.xy - v * dt, axis=-1) / (GATE_SIGMAS * sigma)

    def _dark_now(self, tr: _Track, t: float) -> bool:
        """Whether the track's blink code, at the phase that named it, has its LED dark at
        ``t`` — surely: not within :data:`BIT_EDGE` of a bit's edge (the code's phase is
        known to an eighth of a bit, and a frame's exposure takes time)."""
        code, phase = tr.code
        slot = (t + phase) * code.bit_rate
        if min(slot % 1.0, 1.0 - slot % 1.0) < BIT_EDGE:
            return False
        return not bool(code.lit(t, phase))

    def _lit_odds(self, tr: _Track, t: float) -> float:
        """How likely the track's LED is lit at ``t`` (not surely dark, :meth:`_dark_now`):
        by its code, 1 on a lit bit and even on a dark one near its edge; without a code,
        the share of lit bits among the deployment's codes (1 when it has none)."""
        if tr.code is not None:
            return 1.0 if tr.code[0].lit(t, tr.code[1]) else 0.5
        return self._duty

    def _reacquire(self, ray: _Ray, given: set) -> _Track | None:
        """The track one camera alone still sees whose newest spot meets this ray of another
        camera as one LED (:meth:`_meet`): the second camera seeing it again (not a track
        ``given`` a spot of this frame already)."""
        best, best_score = None, 1.0
        for tr in self.tracks:
            last = tr.latest
            if tr.tentative or id(tr) in given or self._fresh(tr, ray.t) or last is None \
                    or last.camera == ray.camera \
                    or not 0 <= ray.t - last.t <= WINDOW * self.period:
                continue
            score, _ = self._meet(last, ray)
            if score < best_score:
                best, best_score = tr, score
        return best

    def _rejoin(self, tr: _Track, t: float) -> None:
        """A newly confirmed track that continues a held one takes up its id: the held track's
        path in its camera's image leads to one of this track's spots there, or — its path
        lost — it alone could have moved to where this one is (:data:`TOP_SPEED`). A held
        track whose path goes on elsewhere, or whose blink code has its LED dark when this
        one was lit, is another LED's."""
        best, link, within = None, 1.0, []
        for h in self.held:
            reach = TOP_SPEED * (t - h.fit_t) + 3 * (h.s_pos + tr.s_pos)
            if np.linalg.norm(tr.fit[:3] - h.fit[:3]) > reach:
                continue
            if h.code is not None and any(self._dark_now(h, r.t) for r in tr.rays):
                continue  # lit when the held one's code has its LED dark: another LED
            followed = {id(r) for r in h.rays}
            score = min((0.0 if id(r) in followed
                         else float(self._path_gap(h, r.camera, r.xy[None], r.t)[0])
                         for r in tr.rays if r.camera == h.latest.camera), default=np.inf)
            if score <= link:
                best, link = h, score
            elif t - h.latest.t > PATH_GAP * self.period:  # its path lost: it may be
                within.append(h)  # anywhere in reach
        linked = best is not None
        if not linked:
            if len(within) != 1:
                return
            best = within[0]
        self.held = [h for h in self.held if h is not best]
        tr.anonymous = best.anonymous
        if not linked:  # its motion alone: its id, not its blink code's name (a code says
            if tr.led == "":  # which LED it is better than a guess of where it went)
                tr.led = best.anonymous
            return
        if best.led in self._body_of or (self.bodies and best.led == best.anonymous):
            # a body's LED (or, among bodies, one not named yet): its path may go on in a
            # sibling's spot — its id, but not its name or blink history: those come from its
            # own code or the body's shape
            if tr.led == "":
                tr.led = best.anonymous
            return
        if tr.led == tr.anonymous or tr.led == "":  # not named by its own code yet: the held
            taken = best.led != best.anonymous and any(o.led == best.led for o in self.tracks)
            tr.led, tr.margin = (best.anonymous, 0) if taken else (best.led, best.margin)
            tr.code = None if taken else best.code
        tr.seen = best.seen + tr.seen

    def _blink(self, k: int, t: float, lit: set, near: set) -> None:
        """Record, for the blink code, each placed track camera ``k`` should have seen at
        ``t``: lit if it took a spot, dark if none (contested when a spot another track took
        was ``near`` it: it may have been its LED's); and name the tracks whose code is
        due."""
        cam = self.cameras[k]
        pred = self._predicted(k, t)
        m = VIEW_MARGIN_PX
        inside = (pred[:, 0] >= m) & (pred[:, 1] >= m) & (pred[:, 0] <= cam.width - 1 - m) \
            & (pred[:, 1] <= cam.height - 1 - m)
        for tr, there in zip(self.tracks, inside):
            placed = t - tr.last_two <= COAST_PERIODS * self.period
            if id(tr) in lit or (there and placed):
                tr.seen.append((t, id(tr) in lit))
                if id(tr) not in lit and id(tr) in near:
                    tr.contested.append(t)
            since = t - WINDOW_REPEATS * self._repeat
            if len(tr.seen) > 2 * MAX_OBSERVATIONS or (tr.seen and tr.seen[0][0] < since):
                tr.seen = [o for o in tr.seen[-MAX_OBSERVATIONS:] if o[0] >= since]
                tr.contested = [c for c in tr.contested if c >= tr.seen[0][0]] \
                    if tr.seen else []
            if t - tr.decoded_at >= 0.5 * self._repeat / WINDOW_REPEATS:
                tr.decoded_at = t
                self._name(tr)

    def _name(self, tr: _Track) -> None:
        """The LED a track's recent lit and dark frames name; a name held by another track goes
        to the one whose code reads more clearly."""
        if len(tr.seen) < 2:
            return
        t, lit = np.array(tr.seen).T
        led, e1, e2, phase = decode_phase(t, lit.astype(bool), self.codes)
        if led is None and tr.led == tr.anonymous:  # too short a read for the phases: the
            led, e1, e2, phase = self._by_known_phase(t, lit)  # phases the LEDs were read at
        if led is None:  # no code reads clearly among all: its own LED's (a body's shape
            # named it) may still read against a steady light, for its dark times
            own = [c for c in self.codes if c.led == tr.led]
            mine = decode_phase(t, lit.astype(bool), own)[::3] if own else (None, 0.0)
            if mine[0] is not None:
                tr.code = (own[0], mine[1])
            elif tr.code is not None:  # its code at its phase, over its last repeat: lit
                # bits it saw dark (no spot near it another track took) are another LED's
                # whose spots it took: its name is not its own
                recent = (t >= t.max() - tr.code[0].period) & ~np.isin(t, tr.contested)
                if tr.code[0].missed(t[recent], lit[recent], tr.code[1], BIT_EDGE) \
                        >= MISSED_BITS:
                    self._unname(tr)
            return
        holder = next((o for o in self.tracks if o is not tr and o.led == led), None)
        if holder is not None:
            if holder.margin >= e2 - e1:
                return
            holder.led, holder.code = holder.anonymous, None
        if tr.led != led:  # a body's LED renamed: its pose is found afresh, not carried
            for name in (tr.led, led):
                if name in self._body_of:
                    self._body_of[name].fit = None
        tr.led, tr.margin = led, e2 - e1
        tr.code = (next(c for c in self.codes if c.led == led), phase)
        self._phase_of[led] = phase

    def _by_known_phase(self, t, lit):
        """(LED, its wrong bits, the runner-up's, its phase) when every LED's code was read
        before at a phase of its own (LEDs keep theirs) and the track's frames read one of
        them at its phase without a wrong bit, over :data:`KNOWN_BITS` bits or more, and every
        other at its phase with two or more wrong: a code known in phase needs a few bits, not
        a whole repeat (a track that ended and went on as another). Else (None, …)."""
        if len(self._phase_of) < len(self.codes):
            return None, 0, 0, 0.0
        read = sorted((c.wrong(t, lit.astype(bool), self._phase_of[c.led], BIT_EDGE), c.led)
                      for c in self.codes)
        (e1, bits), led = read[0]
        e2 = read[1][0][0] if len(read) > 1 else bits
        if e1 == 0 and bits >= KNOWN_BITS and e2 >= 2:
            return led, e1, e2, self._phase_of[led]
        return None, 0, 0, 0.0

    def _unname(self, tr: _Track) -> None:
        """A track whose name its blink code no longer bears out: back to its id, read afresh."""
        if tr.led in self._body_of:
            self._body_of[tr.led].fit = None
        tr.led, tr.code, tr.margin, tr.seen, tr.contested = tr.anonymous, None, 0, [], []

    def _confirm(self, tr: _Track, t: float) -> None:
        """A track confirmed: the id of the held track it continues, else a new one."""
        self._rejoin(tr, t)
        if not tr.anonymous:
            while f"T{self._next}" in self._named:  # an id the deployment gives an LED
                self._next += 1
            tr.anonymous = f"T{self._next}"
            self._next += 1
            if not tr.led:
                tr.led = tr.anonymous
