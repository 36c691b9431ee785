"""What a detector returns: :class:`Spot` for one frame, :class:`SpotBatch` for ``N`` frames,
the reasons a frame gives no spot, and the thresholds every detector shares."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spelling import Spelling


class Reason(Spelling):
    """Why a frame gives no spot. A ``str``: the value is how files, statuses and messages
    spell it, and compares equal to that string."""

    #: nothing stands above the background's noise
    NO_SPOT = "no_spot"
    #: a spot too faint to trust its sub-pixel centre
    TOO_DIM = "too_dim"
    #: the spot's centre on or within a pixel of the frame's border: part of it is off the sensor
    AT_EDGE = "at_edge"
    #: not a whole image: damaged or truncated bytes, too small a frame, a NaN
    CORRUPT_FRAME = "corrupt_frame"
    #: a frame of another size than the camera's
    WRONG_SIZE = "wrong_size"
    #: no frame at all (None in a batch)
    MISSING = "missing"


#: the reasons by their former module-level names
NO_SPOT, TOO_DIM, AT_EDGE = Reason.NO_SPOT, Reason.TOO_DIM, Reason.AT_EDGE
CORRUPT, WRONG_SIZE, MISSING = Reason.CORRUPT_FRAME, Reason.WRONG_SIZE, Reason.MISSING
REASONS = tuple(Reason)
#: a reason as the int8 code :class:`SpotBatch` stores (0: a spot), and back
_REASON_CODE = {None: 0, **{reason: code for code, reason in enumerate(Reason, 1)}}
_CODE_REASON = {v: k for k, v in _REASON_CODE.items()}


@dataclass(frozen=True)
class DetectorSettings:
    """Thresholds shared by the detectors; defaults suit 8-bit frames of a small LED.

    The noise level is estimated per frame, from the ring of pixels around the brightest one.
    """

    #: below this peak-over-background in noise sigmas there is nothing to detect
    min_snr: float = 6.0
    #: below this peak-over-background (DN) the spot is too faint to trust its sub-pixel centre
    min_contrast: float = 12.0
    #: the centroid threshold: background + this share of the peak's height above background
    threshold: float = 0.15
    #: half size of the window of ``centroid`` (11×11)
    window: int = 5
    #: a pixel at or above this value is saturated (JPEG ringing keeps 255 from surviving)
    saturation: float = 250.0
    #: spot radius (second-moment, px) beyond which ``blob`` starts to doubt a blob is the LED
    led_radius: float = 1.5
    #: a blob whose core (pixels above half its height) has a larger radius (px) is not a point
    #: source: a lamp, a sunlit patch (an LED's core stays under ~2.5 px even saturated 8×)
    max_core_radius: float = 3.0


DEFAULTS = DetectorSettings()


@dataclass(frozen=True)
class Spot:
    """One frame's detection: its centre ``u, v`` (px), or NaN and the ``reason`` there is no
    spot."""

    u: float
    v: float
    peak: float
    area: int
    saturated: bool
    reason: Reason | None = None
    #: how many blobs competed; > 1 means the detector had to choose (see ``note``)
    blobs: int = 1
    note: str = ""

    @property
    def ok(self) -> bool:
        return self.reason is None


@dataclass
class SpotBatch:
    """Detections for ``N`` frames as arrays of ``N``: the columns a survey or a locator takes
    whole (``uv`` ``N×2``), and each frame's :class:`Spot` as ``batch[i]``."""

    #: spot centre, px (docs/conventions.md, "Pixels"); NaN where ``reason_code`` ≠ 0
    u: np.ndarray
    v: np.ndarray
    #: the spot's brightest value (DN)
    peak: np.ndarray
    #: pixels above the measuring threshold
    area: np.ndarray
    saturated: np.ndarray
    #: int8: 0 for a spot, else the :class:`Reason` (``reasons`` gives them)
    reason_code: np.ndarray
    #: how many blobs competed (0 without a spot)
    blobs: np.ndarray

    def __len__(self) -> int:
        return len(self.u)

    @property
    def uv(self) -> np.ndarray:
        return np.stack([self.u, self.v], axis=-1)

    @property
    def ok(self) -> np.ndarray:
        return self.reason_code == 0

    @property
    def reasons(self) -> list[Reason | None]:
        return [_CODE_REASON[int(c)] for c in self.reason_code]

    def __getitem__(self, i: int) -> Spot:
        n = int(self.blobs[i])
        return Spot(
            float(self.u[i]), float(self.v[i]), float(self.peak[i]), int(self.area[i]),
            bool(self.saturated[i]), _CODE_REASON[int(self.reason_code[i])], n,
            f"chose 1 of {n} blobs" if n > 1 else "",
        )

    @classmethod
    def empty(cls, n: int) -> SpotBatch:
        nan = np.full(n, np.nan)
        return cls(nan, nan.copy(), np.zeros(n), np.zeros(n, int), np.zeros(n, bool),
                   np.zeros(n, np.int8), np.zeros(n, int))


def _finish(u, v, peak, area, saturated, code, blobs=None) -> SpotBatch:
    bad = code != 0
    u = np.where(bad, np.nan, u).astype(float)
    v = np.where(bad, np.nan, v).astype(float)
    blobs = np.ones(len(u), int) if blobs is None else blobs
    return SpotBatch(u, v, np.asarray(peak, float), np.asarray(area, int),
                     np.asarray(saturated, bool), code, np.where(bad, 0, blobs))

