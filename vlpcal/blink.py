"""LED identity from blink codes: each LED lights to its own on/off pattern, repeated,
at a stated bit rate; a track's spots (lit) and the frames where a camera should have seen it but
did not (dark) are read against every pattern at every phase, and the pattern they fit best,
clearly better than any other, names the LED.

The LEDs are not synchronised with the cameras or with each other, so the phase is unknown and
searched (an eighth of a bit apart); a frame caught at a bit's edge may read either way, so the
decision counts the bit slots each pattern gets wrong and asks the best to be clearly ahead of
the next, in counts: no threshold in seconds or pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: phases tried per bit
PHASES_PER_BIT = 8
#: at most this many bits in a pattern
MAX_BITS = 64
#: a track's code is read over its last this many repeats of the longest code …
WINDOW_REPEATS = 3.0
#: … and at most this many observations (the latest)
MAX_OBSERVATIONS = 4096


@dataclass(frozen=True)
class BlinkCode:
    """One LED's identity: ``pattern`` of ``1`` (lit) and ``0`` (dark), repeated at
    ``bit_rate`` bits per second."""

    led: str
    pattern: str
    bit_rate: float

    @property
    def period(self) -> float:
        """s: one repeat of the pattern."""
        return len(self.pattern) / self.bit_rate

    def lit(self, t, phase: float = 0.0) -> np.ndarray:
        """Whether the LED is lit at times ``t`` (s), its pattern started at ``-phase``."""
        bits = np.array([c == "1" for c in self.pattern])
        slot = np.floor((np.asarray(t, float) + phase) * self.bit_rate).astype(np.int64)
        return bits[np.mod(slot, len(bits))]

    def wrong(self, t, lit, phase: float, edge: float) -> tuple[int, int]:
        """(bits the observations read otherwise than the code at ``phase``, bits read)
        (:meth:`_votes`; a tie reads neither way)."""
        votes, want = self._votes(t, lit, phase, edge)
        read = votes != 0
        return int(np.sum(read & ((votes > 0) != want))), int(np.sum(read))

    def missed(self, t, lit, phase: float, edge: float) -> int:
        """How many of its lit bits the observations saw dark (:meth:`_votes`): a track that
        follows another LED misses the bits where that one is dark."""
        votes, want = self._votes(t, lit, phase, edge)
        return int(np.sum(want & (votes < 0)))

    def _votes(self, t, lit, phase: float, edge: float) -> tuple[np.ndarray, np.ndarray]:
        """Per bit the observations (times ``t``, ``lit`` or not) fall in, at ``phase``: their
        vote (lit minus dark, leaving out those within ``edge`` of a bit — a share of one — of
        its edges) and whether the code has it lit."""
        at = (np.asarray(t, float) + phase) * self.bit_rate
        away = np.minimum(at % 1.0, 1.0 - at % 1.0) >= edge
        slots, which = np.unique(np.floor(at[away]).astype(np.int64), return_inverse=True)
        votes = np.bincount(which, np.where(np.asarray(lit, bool)[away], 1, -1), len(slots))
        return votes, self.lit((slots + 0.5) / self.bit_rate - phase, phase)


def _middle_of_best(wrong) -> int:
    """The phase in the middle of the longest run of phases (circular) that get the fewest
    slots wrong: the phase that fits is known to that run, best at its middle."""
    best = wrong == wrong.min()
    n = len(best)
    if best.all():
        return 0
    start = int(np.argmin(best))  # a phase outside every run: runs do not wrap past it
    order = np.roll(np.arange(n), -start)
    run, longest, at = 0, 0, 0
    for i, k in enumerate(order):
        run = run + 1 if best[k] else 0
        if run > longest:
            longest, at = run, i
    return int(order[at - (longest - 1) // 2])


def check_codes(codes: list[BlinkCode]) -> str | None:
    """What is wrong with a set of codes, in words (None: nothing): each pattern of 0 and 1,
    2–64 bits, lit at least once, and no two LEDs whose patterns are the same up to a shift
    (they could not be told apart)."""
    for c in codes:
        if not (2 <= len(c.pattern) <= MAX_BITS and set(c.pattern) <= {"0", "1"}):
            return (f"{c.led}: pattern: expected 2–{MAX_BITS} characters of 0 (dark) and 1 "
                    f"(lit), got {c.pattern[:70]!r}")
        if "1" not in c.pattern:
            return f"{c.led}: pattern: expected the LED lit at least once, got {c.pattern!r}"
    seen: dict = {}
    for c in codes:
        p = c.pattern
        key = (min(p[i:] + p[:i] for i in range(len(p))), round(c.bit_rate, 9))
        if key in seen:
            return (f"{c.led}: pattern {p!r} is {seen[key]}'s, up to a shift, at the same bit "
                    "rate: they cannot be told apart (expected a pattern no other LED has, in "
                    "any phase)")
        seen[key] = c.led
    return None


def decode(t, lit, codes: list[BlinkCode]) -> tuple[str | None, int, int]:
    """:func:`decode_phase` without the phase."""
    return decode_phase(t, lit, codes)[:3]


def decode_phase(t, lit, codes: list[BlinkCode]) -> tuple[str | None, int, int, float]:
    """Which LED a track is, from its observations: times ``t`` (s) and whether it was ``lit``
    then. Each code is tried at :data:`PHASES_PER_BIT` phases a bit; per code and phase the bit
    slots it gets wrong are counted (a slot: one bit's time, its observations by majority).
    Returns (the LED, the best code's wrong slots, the runner-up's), the LED None unless the
    observations span a whole repeat of the best code and its wrong slots are clearly fewer
    than the runner-up's (by 3, and by twice its own) — a steady light among the runners;
    and the phase (s) at which the best code fits (:meth:`BlinkCode.lit`'s)."""
    t = np.asarray(t, float)
    lit = np.asarray(lit, bool)
    if not len(codes) or len(t) < 2:
        return None, 0, 0, 0.0
    order = np.argsort(t, kind="stable")[-MAX_OBSERVATIONS:]  # the latest, in time order
    t, lit = t[order], lit[order]
    scores = []
    steady = BlinkCode("", "11", codes[0].bit_rate)  # a light that never blinks: no LED here
    for code in [*codes, steady]:
        bits = np.array([c == "1" for c in code.pattern])
        n = len(bits)
        phases = np.arange(n * PHASES_PER_BIT) / (PHASES_PER_BIT * code.bit_rate)
        slot = np.floor((t[None, :] + phases[:, None]) * code.bit_rate).astype(np.int64)
        signed = np.where(bits[np.mod(slot, n)] == lit[None, :], 1, -1)
        # per phase, per slot (a run of equal slots along time): the majority of its
        # observations; the work is phases × observations, whatever the bit rate
        end = np.ones(slot.shape, bool)
        end[:, :-1] = slot[:, 1:] != slot[:, :-1]
        rows, cols = np.nonzero(end)
        total = np.cumsum(signed, axis=1)[rows, cols]
        before = np.r_[0, total[:-1]]
        before[np.r_[True, rows[1:] != rows[:-1]]] = 0
        wrong = np.bincount(rows, (total - before) < 0, len(phases))
        best = _middle_of_best(wrong)
        span = (t.max() - t.min()) >= code.period
        scores.append((int(wrong[best]), span, code.led, float(phases[best])))
    order = sorted(range(len(scores)), key=lambda i: scores[i][0])
    (e1, span, led, phase), e2 = scores[order[0]], scores[order[1]][0]
    if led and span and e2 - e1 >= 3 + 2 * e1:
        return led, e1, e2, phase
    return None, e1, e2, 0.0
