"""The steps every detector shares, vectorised over a stack ``N×H×W``: the brightest pixel,
the windows and rings of pixels around it, the local background and noise, the reason codes."""

from __future__ import annotations

from functools import cache

import numpy as np

from .results import _REASON_CODE, NO_SPOT, TOO_DIM, DetectorSettings


def _medians(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=-1)`` (the same values and dtype, for arrays without NaN) by a
    partition: np.median's NaN check imports ``numpy.ma``, 9 ms of every command's start."""
    m = a.shape[-1] // 2
    dtype = a.dtype if a.dtype.kind == "f" else np.float64
    if a.shape[-1] % 2:
        return np.partition(a, m, axis=-1)[..., m].astype(dtype)
    p = np.partition(a, (m - 1, m), axis=-1)
    return (p[..., m - 1].astype(dtype) + p[..., m]) * 0.5


def _median(values: np.ndarray) -> float:
    """The median of a 1-D array, as a float (:func:`_medians`)."""
    return float(_medians(values))


def _noise(ring: np.ndarray) -> np.ndarray:
    """Per-frame noise sigma (DN) from the ring of pixels around the spot (``N×K``, in order
    around the ring): the median absolute difference of neighbours on the ring over √2, which
    a smooth background gradient does not inflate. Floor of 1 DN (8-bit quantisation and JPEG
    smoothing make smaller estimates meaningless)."""
    diff = np.abs(np.diff(ring, axis=1))
    return np.maximum(1.4826 * _medians(diff) / np.sqrt(2.0), 1.0).astype(float)


#: half size of the square ring (15×15) whose median is the background under the spot
_RING = 7


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



@cache
def _ring_offsets(half: int, h: int, w: int):
    """Row and column offsets of the border of a (2h+1)² window from its top-left corner,
    in order around it (neighbours on the ring are neighbours in the frame)."""
    sy, sx = min(2 * half + 1, h), min(2 * half + 1, w)
    top = [(0, x) for x in range(sx)]
    right = [(y, sx - 1) for y in range(1, sy)]
    bottom = [(sy - 1, x) for x in range(sx - 2, -1, -1)]
    left = [(y, 0) for y in range(sy - 2, 0, -1)]
    dy, dx = np.array(top + right + bottom + left).T
    return dy, dx


def _ring(stack: np.ndarray, r, c, half: int) -> np.ndarray:
    """``N×K`` values on the border of the window :func:`_windows` would cut (as float)."""
    n, h, w = stack.shape
    size = 2 * half + 1
    r0 = np.clip(r - half, 0, max(h - size, 0))
    c0 = np.clip(c - half, 0, max(w - size, 0))
    dy, dx = _ring_offsets(half, h, w)
    return stack[np.arange(n)[:, None], r0[:, None] + dy, c0[:, None] + dx].astype(np.float32)



def _windows(stack: np.ndarray, r, c, half: int, frames=None):
    """``N×(2h+1)×(2h+1)`` windows around (r, c), clamped inside the frame, and their origins;
    of the frames ``frames`` (indices; all by default), without copying whole frames."""
    n, h, w = stack.shape
    frames = np.arange(n) if frames is None else np.asarray(frames)
    size = 2 * half + 1
    r0 = np.clip(r - half, 0, max(h - size, 0))
    c0 = np.clip(c - half, 0, max(w - size, 0))
    off = np.arange(min(size, h))[:, None], np.arange(min(size, w))[None, :]
    rows = r0[:, None, None] + off[0]
    cols = c0[:, None, None] + off[1]
    return stack[frames[:, None, None], rows, cols].astype(float), r0, c0


def _classify(peak, bg, sigma, s: DetectorSettings) -> np.ndarray:
    """Reason codes from the peak's height above background (no_spot, too_dim or none)."""
    excess = peak - bg
    code = np.zeros(len(peak), np.int8)
    code[excess < s.min_contrast] = _REASON_CODE[TOO_DIM]
    code[excess < s.min_snr * sigma] = _REASON_CODE[NO_SPOT]
    return code



def _cut(img: np.ndarray, r: int, c: int, half: int):
    """The (2h+1)² window around (r, c), clamped inside the frame as :func:`_windows` clamps
    it, and its origin."""
    h, w = img.shape
    size = 2 * half + 1
    r0 = min(max(r - half, 0), max(h - size, 0))
    c0 = min(max(c - half, 0), max(w - size, 0))
    return img[r0:r0 + size, c0:c0 + size], r0, c0

