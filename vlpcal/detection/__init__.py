"""Spot detection: camera frames (JPEG bytes or image arrays) → the LED's sub-pixel centre.

Two entries, one contract (every detector, both entries):

- the batch, :func:`detect_spots`: ``N`` frames (an ``N×H×W`` array, or a sequence of JPEG
  bytes / ``H×W`` / ``H×W×3`` arrays / None) → :class:`SpotBatch` of ``N`` (``u, v``: ``N``
  px, NaN where ``reason_code`` ≠ 0; ``.uv`` ``N×2``; ``batch[i]`` is frame i's
  :class:`Spot`). Its two forms: :func:`detect_spot`, one frame → its :class:`Spot` (the
  batch of one), and :func:`detect_several`, ``N`` frames, ``k`` LEDs in view → ``N×k×2`` px,
  most LED-like first, NaN rows where a frame holds fewer (with ``reasons``: and a
  :class:`Reason` or None per frame).
- the live frame, :func:`detect_frame`: one frame → ``(k×2 px, Reason or None)``, row for row
  what :func:`detect_several` gives for ``[frame]`` (with ``every_reason``: the reason
  :func:`detect_spots` gives it), measured on the frame itself without building a stack.

A frame without a usable spot carries a :class:`Reason` instead of raising: ``no_spot``,
``too_dim``, ``at_edge``, ``corrupt_frame``, ``wrong_size`` or ``missing``. Pixels are
OpenCV's (u = column, v = row, the top-left pixel's centre at (0, 0); docs/conventions.md).

Detectors by name (:data:`DETECTORS`; the paper's are compared in its section 3.2):

- ``highest``: the brightest pixel (the paper's baseline, (a)).
- ``mean2``: the mean position of the two brightest pixels (the paper's "mean integer", (b)).
- ``nip``: the paper's NI-P (section 2.1), the 3-point parabola vertex around the brightest
  pixel, per axis (docs/conventions.md, "The paper's methods").
- ``nip_eq5``: NI-P with the paper's eq. 5 exactly as printed, whose offset is twice the
  parabola vertex's; kept to reproduce the paper, not for use.
- ``gauss``: the 3-point parabola through the logarithms (exact for a sampled Gaussian).
- ``centroid``: background-subtracted, thresholded, intensity-weighted centroid in an 11×11
  window around the brightest pixel.
- ``blob`` (the default, :data:`DEFAULT_DETECTOR`): picks the LED among the bright blobs and
  says when it had to choose, then takes a thresholded centroid over a local background plane
  (:mod:`.blob`).

Modules: :mod:`.results` (what comes out), :mod:`.decoding` (frames in), :mod:`.windows` (the
steps all detectors share), :mod:`.peaks` (the detectors that start at the brightest pixel),
:mod:`.blob`, :mod:`.entries` (the public functions).
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
