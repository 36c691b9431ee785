"""The steps every detector shares: the brightest pixel, the windows and rings of pixels around
it, the local background and noise, the reason a frame gives no spot.

Each step takes a stack ``N×H×W`` (the batch, vectorised over frames); the steps the live path
needs on one frame also take one ``H×W`` image or plain numbers and then work on Python floats,
where a numpy call on a tiny array costs more than the arithmetic. Either way it is one
function, so a change is made once.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from .results import _REASON_CODE, DetectorSettings, Reason

#: half size of the square ring (15×15) whose median is the background under the spot
_RING = 7


class _Scalar:
    """The math module under numpy's names: a formula written once for arrays (``np``) also
    runs on one frame's Python floats (this), where numpy's cost per call would outweigh the
    arithmetic."""

    log = staticmethod(math.log)
    sqrt = staticmethod(math.sqrt)
    ceil = staticmethod(math.ceil)
    maximum = staticmethod(max)


def _xp(x):
    """``np`` for arrays, :class:`_Scalar` for plain numbers."""
    return np if isinstance(x, np.ndarray) else _Scalar


def _medians(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=-1)`` (the same values and dtype, for arrays without NaN) by a
    partition: np.median's NaN check imports ``numpy.ma``, which every command would pay for at
    start."""
    m = a.shape[-1] // 2
    dtype = a.dtype if a.dtype.kind == "f" else np.float64
    if a.shape[-1] % 2:
        return np.partition(a, m, axis=-1)[..., m].astype(dtype)
    p = np.partition(a, (m - 1, m), axis=-1)
    return (p[..., m - 1].astype(dtype) + p[..., m]) * 0.5


def _median(values: np.ndarray) -> float:
    """The median of a 1-D array, as a float (:func:`_medians`)."""
    return float(_medians(values))


def _noise(ring: np.ndarray):
    """Noise sigma (DN) from the ring of pixels around the spot, in order around the ring
    (``N×K`` → ``N``; one frame's ``K`` → a float): the median absolute difference of
    neighbours on the ring (a normal's MAD × 1.4826, over √2 for a difference of two pixels),
    which a smooth background gradient does not inflate. Floor of 1 DN (8-bit quantisation and
    JPEG smoothing make smaller estimates meaningless)."""
    if ring.ndim == 1:
        return max(1.4826 * _median(np.abs(ring[1:] - ring[:-1])) / np.sqrt(2.0), 1.0)
    diff = np.abs(ring[:, 1:] - ring[:, :-1])
    return np.maximum(1.4826 * _medians(diff) / np.sqrt(2.0), 1.0).astype(float)


def _classify(peak, bg, sigma, s: DetectorSettings):
    """Reason codes from the peak's height above background: ``no_spot`` under ``min_snr``
    noise sigmas, ``too_dim`` under ``min_contrast``, else 0 (arrays, or one frame's floats)."""
    excess = peak - bg
    if not isinstance(excess, np.ndarray):
        return (_REASON_CODE[Reason.NO_SPOT] if excess < s.min_snr * sigma
                else _REASON_CODE[Reason.TOO_DIM] if excess < s.min_contrast else 0)
    code = np.zeros(len(peak), np.int8)
    code[excess < s.min_contrast] = _REASON_CODE[Reason.TOO_DIM]
    code[excess < s.min_snr * sigma] = _REASON_CODE[Reason.NO_SPOT]
    return code


def _threshold(peak, bg, sigma, s: DetectorSettings):
    """The level a spot's pixels are counted above: ``threshold`` of the peak's height over
    ``bg``, and at least 3 noise sigmas over it (arrays, or one frame's floats)."""
    return bg + _xp(peak).maximum(s.threshold * (peak - bg), 3.0 * sigma)


def _peak(stack: np.ndarray, s: DetectorSettings):
    """Brightest pixel (row, column, value), local background, noise sigma and reason codes.

    The background is the median of a ring of pixels around the brightest one: local, so a
    gradient or vignetting across the frame neither hides a spot nor invents one.
    """
    r, c, peak = _argmax(stack)
    ring = _ring(stack, r, c, _RING)
    bg = _medians(ring)
    sigma = _noise(ring)
    return r, c, peak, bg, sigma, _classify(peak, bg, sigma, s)


def _peak_one(img: np.ndarray, s: DetectorSettings):
    """:func:`_peak` of one ``H×W`` image, as Python numbers."""
    h, w = img.shape
    flat = int(img.argmax())
    r, c = divmod(flat, w)
    peak = float(img.flat[flat])
    win, _, _ = _cut(img, r, c, _RING)
    ring = win.ravel()[_ring_offsets(_RING, h, w)[2]].astype(np.int16)
    bg = _median(ring)
    sigma = _noise(ring)
    return r, c, peak, bg, sigma, _classify(peak, bg, sigma, s)


def _argmax(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row, column and value of each frame's brightest pixel (the first one on ties)."""
    n, h, w = stack.shape
    flat = stack.reshape(n, -1)
    idx = flat.argmax(axis=1)
    return idx // w, idx % w, flat[np.arange(n), idx].astype(float)


def _neighbours(stack, r, c):
    """Brightest pixel's 4-neighbours (P1 left, P2 right, P3 up, P4 down), clamped at the edge."""
    n, h, w = stack.shape
    i = np.arange(n)
    return (stack[i, r, np.maximum(c - 1, 0)].astype(float),
            stack[i, r, np.minimum(c + 1, w - 1)].astype(float),
            stack[i, np.maximum(r - 1, 0), c].astype(float),
            stack[i, np.minimum(r + 1, h - 1), c].astype(float))


def _origin(r, half: int, side: int):
    """First row (or column) of the (2h+1)-pixel window around row ``r``, slid inside a frame
    ``side`` pixels across (near the edge the window lies to one side of ``r``); arrays or
    one number."""
    last = max(side - 2 * half - 1, 0)
    if isinstance(r, np.ndarray):
        return np.clip(r - half, 0, last)
    return min(max(r - half, 0), last)


@cache
def _ring_offsets(half: int, h: int, w: int):
    """The border of a (2h+1)² window, in order around it (neighbours on the ring are
    neighbours in the frame): row and column offsets from its top-left corner, and the same
    pixels as flat indices into the window (clamped to an ``h × w`` frame)."""
    sy, sx = min(2 * half + 1, h), min(2 * half + 1, w)
    top = [(0, x) for x in range(sx)]
    right = [(y, sx - 1) for y in range(1, sy)]
    bottom = [(sy - 1, x) for x in range(sx - 2, -1, -1)]
    left = [(y, 0) for y in range(sy - 2, 0, -1)]
    dy, dx = np.array(top + right + bottom + left).T
    return dy, dx, dy * sx + dx


def _on_border(r0, c0, dy, dx, h: int, w: int):
    """Which ring pixels (offsets ``dy, dx`` from a window at ``r0, c0``; ``N×1`` origins or
    one) lie on the frame's border rows and columns."""
    ry, rx = r0 + dy, c0 + dx
    return (ry == 0) | (ry == h - 1) | (rx == 0) | (rx == w - 1)


def _ring(stack: np.ndarray, r, c, half: int) -> np.ndarray:
    """``N×K`` values on the border of the window :func:`_windows` would cut (as float)."""
    n, h, w = stack.shape
    r0, c0 = _origin(r, half, h), _origin(c, half, w)
    dy, dx, _ = _ring_offsets(half, h, w)
    return stack[np.arange(n)[:, None], r0[:, None] + dy, c0[:, None] + dx].astype(np.float32)


def _windows(stack: np.ndarray, r, c, half: int, frames=None):
    """``N×(2h+1)×(2h+1)`` windows around (r, c), clamped inside the frame, and their origins;
    of the frames ``frames`` (indices; all by default), without copying whole frames."""
    n, h, w = stack.shape
    frames = np.arange(n) if frames is None else np.asarray(frames)
    size = 2 * half + 1
    r0, c0 = _origin(r, half, h), _origin(c, half, w)
    off = np.arange(min(size, h))[:, None], np.arange(min(size, w))[None, :]
    rows = r0[:, None, None] + off[0]
    cols = c0[:, None, None] + off[1]
    return stack[frames[:, None, None], rows, cols].astype(float), r0, c0


def _cut(img: np.ndarray, r: int, c: int, half: int):
    """:func:`_windows` of one ``H×W`` image: its window around (r, c) (a view) and origin."""
    h, w = img.shape
    size = 2 * half + 1
    r0, c0 = _origin(r, half, h), _origin(c, half, w)
    return img[r0:r0 + size, c0:c0 + size], r0, c0
