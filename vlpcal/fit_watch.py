"""Whether the frames fit the deployment: a wrong set-up caught at once.

A deployment of another install with the same camera ids, cameras swapped, a deployment of
another scale or a calibration gone stale give fixes that each look plausible — small
residuals, `ok` — while most moments fail to be placed at all. A right deployment places nearly
every moment two cameras see an LED, reflections and lamps included; so the share placed, over
the latest :data:`RECENT` such moments, tells a set-up that does not fit. (What a moment is,
each caller says: a locator's set of frames, or a tracker's spot.) The verdict waits until the
share is below :data:`FIT_SHARE` beyond doubt: the upper end of its Wilson interval
(:data:`CONFIDENCE_Z`), so a few failures in a short run raise nothing (nor do fewer than
:data:`LEAST` moments) and a wrong set-up is named within a few dozen moments.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

#: below this share of moments placed (of those two cameras or more saw the LED), the frames
#: do not fit the deployment
FIT_SHARE = 0.8
#: one-sided z of the confidence that the share is below :data:`FIT_SHARE` (99.5 %)
CONFIDENCE_Z = 2.58
#: the moments judged: the latest this many (a camera bumped mid-run shows) …
RECENT = 300
#: … and no verdict on fewer than this many (per LED a frame is searched for: several LEDs
#: side by side confuse their tracks' first moments)
LEAST = 30


@dataclass(frozen=True)
class Misfit:
    """Frames that do not fit a deployment: of ``moments`` (two cameras saw the LED), only
    ``placed`` were placed; ``reasons``: why the others were not (reason → count)."""

    deployment: str
    moments: int
    placed: int
    reasons: tuple[tuple[str, int], ...]
    what: str  #: what a moment is, plural ("sets seen by two cameras or more")

    @property
    def share_failed(self) -> float:
        return 1.0 - self.placed / self.moments

    def message(self) -> str:
        why = ", ".join(f"{reason.replace('_', ' ')} {n / self.moments:.0%}"
                        for reason, n in self.reasons)
        return (f"these frames do not fit {self.deployment}: {self.share_failed:.0%} of "
                f"{self.moments} {self.what} were not placed ({why}); a right deployment "
                "places nearly all. Is it the right deployment, with its cameras' ids in "
                "place, and calibrated as they hang now?")


class FitWatch:
    """Moments two cameras or more saw the LED, placed or not (and why not), as they come;
    :meth:`misfit` says when the latest of them show the frames do not fit."""

    def __init__(self, deployment: str, what: str, recent: int = RECENT, least: int = LEAST):
        self.deployment, self.what, self.least = deployment, what, least
        self._recent: deque = deque(maxlen=recent)
        self._placed = 0
        self.moments = 0  #: all moments seen
        self.placed = 0  #: of them, placed

    def add(self, placed: bool, reason: str = "") -> None:
        """One moment: placed, or not for ``reason``."""
        if len(self._recent) == self._recent.maxlen:
            self._placed -= self._recent[0][0]
        self._recent.append((bool(placed), reason))
        self._placed += bool(placed)
        self.moments += 1
        self.placed += bool(placed)

    def add_statuses(self, statuses, dropped=None) -> None:
        """A locator's fix statuses (and whether its robust fusion dropped a camera's spot
        from each fix, off the others'): those of sets two cameras or more saw are moments —
        placed when ``ok`` with no camera dropped; not when ``degenerate``, ``outside_room``,
        ``inconsistent``, or a camera was dropped (``camera_dropped``)."""
        for status, off in zip(statuses, dropped if dropped is not None else [False] * len(
                statuses)):
            if status in _SEEN_BY_TWO:
                placed = status == "ok" and not off
                self.add(placed, "camera_dropped" if status == "ok" and off else status)

    def misfit(self) -> Misfit | None:
        """The latest moments' verdict: a :class:`Misfit` when their share placed is below
        :data:`FIT_SHARE` beyond doubt, else None."""
        n = len(self._recent)
        if n < self.least or _wilson_upper(self._placed, n) >= FIT_SHARE:
            return None
        reasons = Counter(r for placed, r in self._recent if not placed)
        return Misfit(self.deployment, n, self._placed, tuple(reasons.most_common()), self.what)


_SEEN_BY_TWO = frozenset(("ok", "degenerate", "outside_room", "inconsistent"))


def _wilson_upper(k: int, n: int, z: float = CONFIDENCE_Z) -> float:
    """The upper end of the Wilson score interval of a share ``k / n``."""
    p = k / n
    centre = p + z * z / (2 * n)
    spread = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre + spread) / (1 + z * z / n)
