"""Spot detection: a camera frame (JPEG bytes or an image array) → the LED's sub-pixel centre.

Detectors by name (:data:`DETECTORS`):

- ``highest``: the brightest pixel (the paper's baseline, section 3.2 (a)).
- ``mean2``: the mean position of the two brightest pixels (the paper's "mean integer", (b)).
- ``nip``: the paper's NI-P (section 2.1) as DESIGN.md states it: the 3-point parabola vertex
  around the brightest pixel, per axis.
- ``nip_eq5``: NI-P with the paper's eq. 5 exactly as printed, whose offset is twice the
  parabola vertex's (see ``_vertex``); kept to reproduce the paper, not for use.
- ``gauss``: the 3-point parabola through the logarithms (exact for a sampled Gaussian).
- ``centroid``: background-subtracted, thresholded, intensity-weighted centroid in an 11×11
  window around the brightest pixel.
- ``blob`` (the default, :data:`DEFAULT_DETECTOR`): picks the LED among the bright blobs by
  brightness and compactness (a floor reflection is dimmer and wider, a lamp wider) and says
  when it had to choose, then takes a thresholded centroid over a local background plane:
  unbiased on saturated flat tops, where every 3-point fit is pulled ~0.3 px toward the first
  flat pixel (FIELD-NOTES), and little moved by the flank of a nearby reflection.

Every detector returns the same fields (:class:`Spot` for one frame, :class:`SpotBatch` for an
``N×H×W`` stack); a frame without a usable spot carries a reason instead of raising:
``no_spot``, ``too_dim``, ``at_edge`` or ``corrupt_frame``. Pixels are OpenCV's (u = column,
v = row, the top-left pixel's centre at (0, 0)).
"""

from .decoding import (
    MAX_PIXELS,
    MIN_SIZE,
    SIZE_SAMPLE,
    as_gray,
    decode_gray,
    jpeg_size,
    spread,
    usual_size,
)
from .entries import (
    DEFAULT_DETECTOR,
    DETECTORS,
    detect_frame,
    detect_several,
    detect_spot,
    detect_spots,
)
from .results import (
    AT_EDGE,
    CORRUPT,
    DEFAULTS,
    MISSING,
    NO_SPOT,
    REASONS,
    TOO_DIM,
    WRONG_SIZE,
    DetectorSettings,
    Reason,
    Spot,
    SpotBatch,
)

__all__ = [
    "AT_EDGE", "CORRUPT", "DEFAULT_DETECTOR", "DEFAULTS", "DETECTORS", "MAX_PIXELS", "MIN_SIZE",
    "MISSING", "NO_SPOT", "REASONS", "SIZE_SAMPLE", "TOO_DIM", "WRONG_SIZE", "DetectorSettings",
    "Reason", "Spot", "SpotBatch", "as_gray", "decode_gray", "detect_frame", "detect_several",
    "detect_spot", "detect_spots", "jpeg_size", "spread", "usual_size",
]
