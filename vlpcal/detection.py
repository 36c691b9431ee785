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

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from functools import cache

import numpy as np

#: Reasons a frame gives no spot.
NO_SPOT, TOO_DIM, AT_EDGE, CORRUPT = "no_spot", "too_dim", "at_edge", "corrupt_frame"
#: a frame of another size than the camera's, and no frame at all (None in a batch)
WRONG_SIZE, MISSING = "wrong_size", "missing"
REASONS = (NO_SPOT, TOO_DIM, AT_EDGE, CORRUPT, WRONG_SIZE, MISSING)
_REASON_CODE = {None: 0, NO_SPOT: 1, TOO_DIM: 2, AT_EDGE: 3, CORRUPT: 4, WRONG_SIZE: 5,
                MISSING: 6}
_CODE_REASON = {v: k for k, v in _REASON_CODE.items()}

DEFAULT_DETECTOR = "blob"


@dataclass(frozen=True)
class DetectorSettings:
    """Thresholds shared by the detectors; defaults suit 8-bit frames of a small LED.

    The noise level is estimated per frame from a pixel subsample (see ``_noise``).
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
    """One frame's detection. ``u, v`` are NaN when ``reason`` says why there is no spot."""

    u: float
    v: float
    peak: float
    area: int
    saturated: bool
    reason: str | None = None
    #: how many blobs competed; > 1 means the detector had to choose (see ``note``)
    blobs: int = 1
    note: str = ""

    @property
    def ok(self) -> bool:
        return self.reason is None


@dataclass
class SpotBatch:
    """Detections for ``N`` frames as arrays (NaN ``u, v`` where ``reason`` is set)."""

    u: np.ndarray
    v: np.ndarray
    peak: np.ndarray
    area: np.ndarray
    saturated: np.ndarray
    reason_code: np.ndarray
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
    def reasons(self) -> list[str | None]:
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


class _LazyCv2:
    """``cv2``, imported on first use (``import vlpcal.detection`` stays light)."""

    def __getattr__(self, name):
        import cv2

        globals()["_cv2"] = cv2
        return getattr(cv2, name)


_cv2 = _LazyCv2()


# -- decoding ----------------------------------------------------------------------------------

#: pixels a JPEG may declare when no frame size is expected (a 1 kB file can declare
#: 32000 × 32000 and cost a gigabyte to decode)
MAX_PIXELS = 2 ** 26
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def jpeg_size(buf: bytes) -> tuple[int, int] | None:
    """(height, width) that a JPEG's frame header declares, read from its markers without
    decoding (None if there is no frame header before the data)."""
    i, n = 2, len(buf)
    while i + 4 <= n:
        if buf[i] != 0xFF:
            return None
        marker = buf[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        length = (buf[i + 2] << 8) | buf[i + 3]
        if marker in _SOF:
            if i + 9 > n:
                return None
            return (buf[i + 5] << 8) | buf[i + 6], (buf[i + 7] << 8) | buf[i + 8]
        if marker == 0xDA or length < 2:  # the scan data before any frame header
            return None
        i += 2 + length
    return None


#: frames of one camera whose headers :func:`usual_size` reads, spread over its frames
SIZE_SAMPLE = 9


def spread(items, most: int = SIZE_SAMPLE) -> list:
    """Up to ``most`` of ``items`` spread evenly from the first to the last (all when fewer)."""
    items = list(items)
    if len(items) <= most:
        return items
    return [items[round(k * (len(items) - 1) / (most - 1))] for k in range(most)]


def usual_size(frames) -> tuple[int, int] | None:
    """(height, width) that more than half of ``frames`` (JPEG bytes; None or unreadable ones
    not counted) declare in their headers, or None when no size is: a camera's size judged
    from its frames, not from its first one — one damaged frame set (a 1 kB JPEG declaring
    32000 × 32000) is its own rows' status, not the camera's size."""
    from collections import Counter

    sizes = Counter(size for size in (jpeg_size(f) if isinstance(f, (bytes, bytearray))
                                      else None for f in frames) if size is not None)
    if not sizes:
        return None
    size, count = sizes.most_common(1)[0]
    return size if count > sum(sizes.values()) / 2 else None


class _QuietStderr:
    """libjpeg writes its warnings about damaged data ("Corrupt JPEG data: 9 extraneous
    bytes") straight to file descriptor 2, past Python: a damaged frame gets a status, not a
    line on the user's terminal. The descriptor is redirected around a batch of decodes.

    One null descriptor serves the process (opening ``/dev/null`` per live frame cost more than
    the rest of this), and threads share one redirection: the first in saves the real stderr,
    the last out restores it (two threads each saving and restoring their own would leave
    stderr on the null device when their turns interleave)."""

    _lock = threading.Lock()
    _depth = 0
    _null: int | None = None
    _saved: int | None = None

    def __enter__(self):
        cls = type(self)
        with cls._lock:
            if cls._depth == 0:
                try:
                    if cls._null is None:
                        cls._null = os.open(os.devnull, os.O_WRONLY)
                    cls._saved = os.dup(2)
                    os.dup2(cls._null, 2)
                except OSError:  # no redirection then (warnings may show); no descriptor lost
                    if cls._saved is not None:
                        os.close(cls._saved)
                    cls._saved = None
            cls._depth += 1
        return self

    def __exit__(self, *exc):
        cls = type(self)
        with cls._lock:
            cls._depth -= 1
            if cls._depth == 0 and cls._saved is not None:
                os.dup2(cls._saved, 2)
                os.close(cls._saved)
                cls._saved = None


def decode_gray(data, shape=None) -> np.ndarray | None:
    """JPEG bytes → 8-bit grayscale (luma) image, or None when the bytes are not a whole JPEG
    or declare another size than ``shape`` (H, W) — more than :data:`MAX_PIXELS` without it —
    read from the header before anything is decoded.

    A truncated JPEG decodes to a grey-filled image with only a warning, so the end-of-image
    marker is checked first (trailing zero padding, as some cameras send, is allowed).
    """
    if isinstance(data, np.ndarray):
        return data
    buf = bytes(data) if not isinstance(data, bytes) else data
    if len(buf) < 4 or not buf.startswith(b"\xff\xd8") or not (
            buf.endswith(b"\xff\xd9") or buf.rstrip(b"\x00").endswith(b"\xff\xd9")):
        return None
    size = jpeg_size(buf)
    if size is None or (tuple(shape) != size if shape is not None
                        else size[0] * size[1] > MAX_PIXELS):
        return None
    try:
        with _QuietStderr():
            img = _cv2.imdecode(np.frombuffer(buf, np.uint8), _cv2.IMREAD_GRAYSCALE)
    except _cv2.error:
        return None
    return img


#: frames decoded into one stack at a time: ~5 MB at 160 × 120, which stays in the CPU's cache
_CHUNK = 256

#: the smallest frame side a spot can be measured in (the background ring is 15 × 15)
MIN_SIZE = 16


def as_gray(image) -> np.ndarray | None:
    """Image array (H×W, H×W×3 BGR) or JPEG bytes → 2D array, None if it cannot be a frame.

    Values are taken as 8-bit digital numbers (DN, 0–255), as the thresholds in
    :class:`DetectorSettings` are; a frame smaller than :data:`MIN_SIZE` or with a NaN is
    corrupt.
    """
    if isinstance(image, (bytes, bytearray, memoryview)):
        return decode_gray(image)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        import cv2

        img = cv2.cvtColor(img[..., :3].astype(np.float32), cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or min(img.shape) < MIN_SIZE:
        return None
    if img.dtype.kind == "f" and not np.isfinite(img).all():
        return None
    return img


# -- shared steps (vectorised over a stack) ----------------------------------------------------

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


def _vertex(p1, p, p2, printed: bool = False):
    """NI-P's sub-pixel offset from the brightest pixel P and its neighbours P1, P2.

    DESIGN.md's NI-P is the 3-point parabola vertex ``(P2 − P1) / (2 (2P − P1 − P2))``. The
    paper's eq. 5 as printed — lines of slope ±step through P1 and P2, with
    step = ((P − P1) + (P − P2)) / 2 (eq. 1) — gives twice that offset,
    ``(P2 − P1) / (2P − P1 − P2)`` (``printed=True``, the ``nip_eq5`` detector). 0 where flat.
    """
    den = (1.0 if printed else 2.0) * (2.0 * p - p1 - p2)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den > 0, (p2 - p1) / den, 0.0)
    limit = 1.0 if printed else 0.5
    return np.clip(off, -limit, limit)


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


def _outside_max(stack: np.ndarray, r, c, half: int, scratch: bool = False) -> np.ndarray:
    """Each frame's maximum outside the window :func:`_windows` cuts around (r, c), and on the
    window's rim except where the rim runs along the frame's border (a spot cut by the edge of
    the image touches it there). The window is blanked and the frame's maximum taken: in place
    and restored when the stack is the caller's own scratch copy (``scratch``), else on a copy.
    No threshold image of the frames (whose reductions cost more than this)."""
    n, h, w = stack.shape
    size = 2 * half + 1
    r0 = np.clip(r - half, 0, max(h - size, 0))
    c0 = np.clip(c - half, 0, max(w - size, 0))
    index = (np.arange(n)[:, None, None], (r0[:, None] + np.arange(min(size, h)))[:, :, None],
             (c0[:, None] + np.arange(min(size, w)))[:, None, :])
    if scratch:
        kept = stack[index]
        stack[index] = 0
        outside = stack.reshape(n, -1).max(axis=1)
        stack[index] = kept
    else:
        rest = stack.copy()
        rest[index] = 0
        outside = rest.reshape(n, -1).max(axis=1)
    dy, dx = _ring_offsets(half, h, w)
    ry, rx = r0[:, None] + dy, c0[:, None] + dx
    rim = stack[np.arange(n)[:, None], ry, rx].astype(float)
    rim[(ry == 0) | (ry == h - 1) | (rx == 0) | (rx == w - 1)] = 0.0
    return np.maximum(outside, rim.max(axis=1))


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


def _finish(u, v, peak, area, saturated, code, blobs=None) -> SpotBatch:
    bad = code != 0
    u = np.where(bad, np.nan, u).astype(float)
    v = np.where(bad, np.nan, v).astype(float)
    blobs = np.ones(len(u), int) if blobs is None else blobs
    return SpotBatch(u, v, np.asarray(peak, float), np.asarray(area, int),
                     np.asarray(saturated, bool), code, np.where(bad, 0, blobs))


# -- the detectors (stack N×H×W → SpotBatch) ---------------------------------------------------

def _detect_peak(stack, s: DetectorSettings, method: str) -> SpotBatch:
    """``highest``, ``mean2``, ``nip`` and ``gauss``: all start at the brightest pixel."""
    n, h, w = stack.shape
    r, c, peak, bg, sigma, code = _peak(stack, s)
    u, v = c.astype(float), r.astype(float)
    if method == "mean2":
        flat = stack.reshape(n, -1)
        two = np.argpartition(flat, -2, axis=1)[:, -2:]
        u, v = (two % w).mean(axis=1), (two // w).mean(axis=1)
    elif method in ("nip", "nip_eq5", "gauss"):
        p1, p2, p3, p4 = _neighbours(stack, r, c)
        if method == "gauss":
            # log of the height above background: a Gaussian becomes an exact parabola
            def lg(x):
                return np.log(np.maximum(x - bg + 0.5, 0.5))
            p, p1, p2, p3, p4 = lg(peak), lg(p1), lg(p2), lg(p3), lg(p4)
        else:
            p = peak
        printed = method == "nip_eq5"
        u = c + _vertex(p1, p, p2, printed)
        v = r + _vertex(p3, p, p4, printed)
        edge = (c == 0) | (c == w - 1) | (r == 0) | (r == h - 1)
        code[(code == 0) & edge] = _REASON_CODE[AT_EDGE]
    area = (stack.reshape(n, -1) > (bg + s.threshold * (peak - bg))[:, None]).sum(axis=1)
    return _finish(u, v, peak, area, peak >= s.saturation, code)


def _window_centroid(stack, r, c, thr, half):
    """Thresholded centroid in a window around (r, c); weights ``I − T`` so that pixels enter
    the sum at zero weight (no jump as a pixel crosses the threshold).

    Returns u, v, the weight sum, the pixel count above T, the second-moment radius, whether the
    blob touches the window's border, and whether that border is the frame's edge.
    """
    n, h, w = stack.shape
    win, r0, c0 = _windows(stack, r, c, half)
    wgt = np.maximum(win - thr[:, None, None], 0.0)
    tot = wgt.sum(axis=(1, 2))
    ax_u = np.arange(win.shape[2], dtype=float)
    ax_v = np.arange(win.shape[1], dtype=float)
    su, sv = wgt.sum(axis=1), wgt.sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu, mv = (su * ax_u).sum(1) / tot, (sv * ax_v).sum(1) / tot
        var = ((su * ax_u ** 2).sum(1) + (sv * ax_v ** 2).sum(1)) / tot - mu ** 2 - mv ** 2
    above = wgt > 0
    touches = above[:, 0, :].any(1) | above[:, -1, :].any(1) | above[:, :, 0].any(1) \
        | above[:, :, -1].any(1)
    frame_edge = (r0 == 0) | (c0 == 0) | (r0 + win.shape[1] == h) | (c0 + win.shape[2] == w)
    radius = np.sqrt(np.maximum(var, 0.0))
    return c0 + mu, r0 + mv, tot, above.sum(axis=(1, 2)), radius, touches, frame_edge


def _detect_centroid(stack, s: DetectorSettings) -> SpotBatch:
    """``centroid``: the thresholded centroid in a window around the brightest pixel."""
    r, c, peak, bg, sigma, code = _peak(stack, s)
    thr = bg + np.maximum(s.threshold * (peak - bg), 3.0 * sigma)
    u, v, tot, area, _, touches, frame_edge = _window_centroid(stack, r, c, thr, s.window)
    code[(code == 0) & touches & frame_edge] = _REASON_CODE[AT_EDGE]
    code[(code == 0) & ~(tot > 0)] = _REASON_CODE[NO_SPOT]
    return _finish(u, v, peak, area, peak >= s.saturation, code)


def _segment(img, bg: float, thr: float, floor: float, s: DetectorSettings, most: int = 1):
    """Rank the blobs of one frame as LEDs: ``(rows, cols, tops, candidates)`` of the best
    ``most`` (most LED-like first), or None when no blob is a candidate.

    Blobs are the connected components above ``thr``; a candidate is one whose height over
    ``bg`` reaches ``floor`` (it would be a spot on its own). Each is scored by its height
    divided by ``1 + (core radius / led_radius)²``, the core being its pixels above half its
    own height; a core wider than ``max_core_radius`` is no candidate at all. A wide lamp or a
    diffuse reflection has a wide core even when it merges with the LED at the segmentation
    threshold; a JPEG speck has a tiny height. A blob cut by the
    frame's edge (a lamp half outside the view) scores a quarter.
    """
    import cv2

    h, w = img.shape
    mask = (img > thr).astype(np.uint8)
    k, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if k <= 1:
        return None
    # per-component sums over the thresholded pixels only (bincount), no loop over pixels
    nz = np.flatnonzero(mask)
    lab = labels.ravel()[nz]
    f = img.ravel()[nz].astype(float)
    top = np.zeros(k)
    np.maximum.at(top, lab, f)
    wgt = np.maximum(f - (bg + 0.5 * (top[lab] - bg)), 0.0)
    uu, vv = (nz % w).astype(float), (nz // w).astype(float)
    wsum = np.bincount(lab, wgt, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.bincount(lab, wgt * uu, k) / wsum
        mv = np.bincount(lab, wgt * vv, k) / wsum
        var = (np.bincount(lab, wgt * uu * uu, k) + np.bincount(lab, wgt * vv * vv, k)) / wsum
        radius = np.sqrt(np.maximum(var - mu * mu - mv * mv, 0.0))
    cand = np.flatnonzero((top - bg >= floor) & ~(radius > s.max_core_radius))
    cand = cand[cand > 0]
    if not len(cand):
        return None
    score = (top[cand] - bg) / (1.0 + (np.nan_to_num(radius[cand]) / s.led_radius) ** 2)
    x0, y0, bw, bh = stats[cand, 0], stats[cand, 1], stats[cand, 2], stats[cand, 3]
    cut = (x0 == 0) | (y0 == 0) | (x0 + bw == w) | (y0 + bh == h)
    score[cut] /= 4.0  # a blob cut by the frame's edge looks compact and cannot be measured
    best = cand[np.argsort(-score, kind="stable")[:most]]
    # each chosen blob's brightest pixel
    order = np.lexsort((-f, lab))
    first = np.searchsorted(lab[order], best)
    at = nz[order[first]]
    return at // w, at % w, top[best], len(cand)


def _segment_one(img, bg: float, thr: float, floor: float, s: DetectorSettings):
    """Choose the LED among the blobs of one frame: ``(row, col, top, candidates)`` or None
    (:func:`_segment`'s best)."""
    found = _segment(img, bg, thr, floor, s)
    if found is None:
        return None
    rows, cols, tops, n = found
    return int(rows[0]), int(cols[0]), float(tops[0]), n


#: largest half-size of the measuring window of ``blob`` (a 15×15 window)
_MAX_HALF = 7
#: an unsaturated spot's measuring window reaches this many spot sigmas (where a Gaussian is
#: down to 6 % of its peak): wider clears the spot better, narrower keeps out a neighbouring
#: reflection; 2.35 is the best of 2.0–2.5 on the detector benchmark's sets
_REACH = 2.35


def _grow(allowed: np.ndarray, r, c) -> np.ndarray:
    """The part of each ``allowed`` mask (``N×h×w``) 8-connected to pixel (r, c) of its frame.

    Geodesic dilation by whole-array shifts, vectorised over frames (no loop over pixels).
    """
    n, h, w = allowed.shape
    seed = np.zeros_like(allowed)
    seed[np.arange(n), r, c] = True
    seed &= allowed
    for _ in range(max(h, w)):
        grown = seed.copy()
        grown[:, 1:, :] |= seed[:, :-1, :]
        grown[:, :-1, :] |= seed[:, 1:, :]
        grown[:, :, 1:] |= grown[:, :, :-1]
        grown[:, :, :-1] |= grown[:, :, 1:]
        grown &= allowed
        if np.array_equal(grown, seed):
            break
        seed = grown
    return seed


@cache
def _plane_design(half: int):
    """Pixel grids of a (2h+1)² window, its border ring, and the least-squares operator that
    turns the ring's values into a plane's (a, b_u, b_v)."""
    size = 2 * half + 1
    gy, gx = np.mgrid[0:size, 0:size].astype(float)
    ring = (gy == 0) | (gx == 0) | (gy == size - 1) | (gx == size - 1)
    A = np.c_[np.ones(ring.sum()), gx[ring], gy[ring]]
    return gx, gy, ring, np.linalg.pinv(A).T


def _core_centroid(stack, r, c, s: DetectorSettings):
    """Plane-subtracted, thresholded centroid of the spot whose brightest pixel is (r, c).

    The window is centred on the brightest pixel and reaches 2.35 σ (at least 3 px), σ the
    spot's width from the log-curvature at its peak; a saturated spot's window is centred on its
    flat top and reaches 3 px beyond it. So the border ring clears the spot, and stays close
    enough to exclude a neighbouring reflection's core. A plane fitted to the ring is the
    background, so a gradient, vignetting or the flank of a neighbouring reflection is removed
    before the centroid; weights are ``I − plane − T`` with T at ``threshold`` of the remaining
    peak, so pixels enter at zero.

    Returns u, v, the peak over the plane, the pixel count above T, and whether the spot sits
    on the frame's border (``at_edge``).
    """
    n, h, w = stack.shape
    # an unsaturated spot's window reaches _REACH σ, σ from the log-curvature at its peak;
    # the sharper axis counts, as a reflection's flank flattens the curvature on its side only
    p1, p2, p3, p4 = _neighbours(stack, r, c)
    lo = _medians(_ring(stack, r, c, 5))  # the background around an 11×11 look
    peak = stack[np.arange(n), r, c].astype(float)

    def lg(x):
        return np.log(np.maximum(x - lo, 0.5))

    lp = lg(peak)
    curv = np.maximum(2 * lp - lg(p1) - lg(p2), 2 * lp - lg(p3) - lg(p4))
    half = np.ceil(_REACH / np.sqrt(np.maximum(curv, 1e-3)) - 1e-9)
    rc, cc = r.copy(), c.copy()
    # a saturated spot: centre on its flat top, the pixels above 80 % of its height connected
    # to (r, c) (JPEG ringing leaves saturated pixels anywhere from ~210 to 255)
    sat = np.flatnonzero(peak >= s.saturation)
    if len(sat):
        look, r0, c0 = _windows(stack, r[sat], c[sat], 5, sat)
        level = (lo + 0.8 * (peak - lo))[sat, None, None]
        flat = _grow(look >= level, r[sat] - r0, c[sat] - c0)
        yy, xx = np.mgrid[0:look.shape[1], 0:look.shape[2]]
        cnt = flat.sum(axis=(1, 2))
        cu = c0 + (flat * xx).sum(axis=(1, 2)) / cnt
        cv = r0 + (flat * yy).sum(axis=(1, 2)) / cnt
        du = np.abs(xx + c0[:, None, None] - cu[:, None, None])
        dv = np.abs(yy + r0[:, None, None] - cv[:, None, None])
        extent = np.max(np.where(flat, np.maximum(du, dv), 0.0), axis=(1, 2))
        half[sat] = np.ceil(extent) + 3
        rc[sat], cc[sat] = np.rint(cv).astype(int), np.rint(cu).astype(int)
    half = np.clip(half, 3, _MAX_HALF).astype(int)
    u = np.full(n, np.nan)
    v = np.full(n, np.nan)
    height = np.zeros(n)
    area = np.zeros(n, int)
    # near the frame's edge the window slides inside the frame (the ring then lies to one
    # side); a spot whose centre pixel is on the border row or column cannot be measured
    edge = (rc < 1) | (cc < 1) | (rc > h - 2) | (cc > w - 2)
    for H in sorted(set(half.tolist())):  # (np.unique imports numpy.ma: 9 ms of a start)
        idx = np.flatnonzero((half == H) & ~edge)
        if not len(idx):
            continue
        win, wr0, wc0 = _windows(stack, rc[idx], cc[idx], H, idx)
        gx, gy, ring, fit = _plane_design(int(H))
        coef = win[:, ring] @ fit  # N×3: the background plane of each frame
        sig = win - (coef[:, 0, None, None] + coef[:, 1, None, None] * gx
                     + coef[:, 2, None, None] * gy)
        pk = sig.max(axis=(1, 2))
        wgt = np.maximum(sig - (s.threshold * pk)[:, None, None], 0.0)
        tot = wgt.sum(axis=(1, 2))
        u[idx] = wc0 + (wgt * gx).sum(axis=(1, 2)) / tot
        v[idx] = wr0 + (wgt * gy).sum(axis=(1, 2)) / tot
        height[idx] = pk
        area[idx] = (wgt > 0).sum(axis=(1, 2))
    return u, v, height, area, edge


def _detect_blob(stack, s: DetectorSettings, scratch: bool = False) -> SpotBatch:
    """``blob``: choose the LED's blob, then measure it with :func:`_core_centroid`.

    Choice, fast path (vectorised): when every pixel above the threshold lies within the
    11×11 window around the brightest pixel there is one blob and it is the LED. Otherwise the
    frame is segmented (OpenCV connected components) and the LED chosen among the candidate
    blobs by height and compactness (:func:`_segment_one`); ``blobs`` says how many competed.
    """
    n, h, w = stack.shape
    r, c, peak, bg, sigma, code = _peak(stack, s)
    thr = bg + np.maximum(s.threshold * (peak - bg), 3.0 * sigma)
    lone = _outside_max(stack, r, c, s.window, scratch) <= thr  # nothing above T elsewhere
    blobs = np.ones(n, int)
    top = peak.copy()
    for i in np.flatnonzero((code == 0) & ~lone):
        img = stack[i]
        # the whole frame is segmented, so its background is the frame's, not the peak's ring
        # (which a wide lamp raises)
        fbg = _median(img[::4, ::4].ravel())
        floor = max(s.min_contrast, s.min_snr * sigma[i])
        found = _segment_one(img, fbg, fbg + max(s.threshold * (peak[i] - fbg), 3 * sigma[i]),
                             floor, s)
        if found is None:  # nothing point-like: a lamp alone, or noise
            code[i] = _REASON_CODE[NO_SPOT]
        else:
            r[i], c[i], top[i], blobs[i] = found
    u, v, _, area, edge = _core_centroid(stack, r, c, s)
    # a centre within a pixel of the border: part of the spot is off the sensor
    with np.errstate(invalid="ignore"):
        edge |= (u < 1.0) | (v < 1.0) | (u > w - 2.0) | (v > h - 2.0)
    code[(code == 0) & edge] = _REASON_CODE[AT_EDGE]
    code[(code == 0) & ~np.isfinite(u)] = _REASON_CODE[NO_SPOT]
    return _finish(u, v, top, area, top >= s.saturation, code, blobs)


DETECTORS = ("highest", "mean2", "nip", "nip_eq5", "gauss", "centroid", "blob")


def _to_stack(frames, shape=None):
    """``(stack, codes)``: the frames that can be measured as one ``N×H×W`` array, and a reason
    code per frame (0 for the measurable ones). ``shape`` (H, W) is the size expected; without
    it, the first measurable frame's size is."""
    if isinstance(frames, np.ndarray) and frames.ndim == 3:
        codes = np.zeros(len(frames), np.int8)
        if shape is not None and frames.shape[1:] != tuple(shape):
            codes[:] = _REASON_CODE[WRONG_SIZE]
        elif min(frames.shape[1:], default=0) < MIN_SIZE:
            codes[:] = _REASON_CODE[CORRUPT]
        elif frames.dtype.kind == "f":
            codes[~np.isfinite(frames).all(axis=(1, 2))] = _REASON_CODE[CORRUPT]
        good = codes == 0
        return (frames if good.all() else frames[good]), codes
    n = len(frames)
    codes = np.zeros(n, np.int8)
    want = tuple(shape) if shape is not None else None
    if want is not None and min(want) < MIN_SIZE:  # no spot can be measured in so small an image
        codes[:] = [_REASON_CODE[MISSING if f is None else CORRUPT] for f in frames]
        return None, codes
    # with the size known, decoded frames go straight into the stack; else they are collected
    stack = np.empty((n, *want), np.uint8) if want is not None else None
    images = {}
    with _QuietStderr():
        stack = _decode_into(frames, codes, want, stack, images)
    good = codes == 0
    if not good.any():
        return None, codes
    if stack is None:
        return np.stack([images[i] for i in sorted(images)]), codes
    return (stack if good.all() else stack[good]), codes


def _decode_into(frames, codes, want, stack, images):
    """Decode ``frames`` into ``stack`` (the size known) or ``images`` (index → image),
    setting ``codes`` for the frames that cannot be measured; returns the stack (widened
    when a float frame came)."""
    for i, f in enumerate(frames):
        if f is None:
            codes[i] = _REASON_CODE[MISSING]
            continue
        if type(f) is bytes and f[:2] == b"\xff\xd8" and f[-2:] == b"\xff\xd9":
            # a whole JPEG: decode it here (decode_gray's checks, inlined for speed), after
            # its header's size is checked (a small file may declare a huge image)
            size = jpeg_size(f)
            if size is None or (size != want if want is not None
                                else size[0] * size[1] > MAX_PIXELS):
                codes[i] = _REASON_CODE[WRONG_SIZE if size is not None else CORRUPT]
                continue
            try:
                im = _cv2.imdecode(np.frombuffer(f, np.uint8), _cv2.IMREAD_GRAYSCALE)
            except _cv2.error:
                im = None
        else:
            im = decode_gray(f) if isinstance(f, (bytes, bytearray, memoryview)) else as_gray(f)
        if stack is not None and im is not None and im.shape == want \
                and im.dtype == stack.dtype:
            stack[i] = im  # the common case: a decoded JPEG of the camera's size
            continue
        if im is None or im.ndim != 2 or min(im.shape) < MIN_SIZE or (
                im.dtype.kind == "f" and not np.isfinite(im).all()):
            codes[i] = _REASON_CODE[CORRUPT]
            continue
        want = want or im.shape
        if im.shape != want:
            codes[i] = _REASON_CODE[WRONG_SIZE]
        elif stack is not None:  # another dtype (a float frame): widen the stack once
            stack = stack.astype(np.result_type(stack.dtype, im.dtype))
            stack[i] = im
        else:
            images[i] = im
    return stack


def detect_spots(frames, method: str = DEFAULT_DETECTOR,
                 settings: DetectorSettings = DEFAULTS, shape=None) -> SpotBatch:
    """Detect the spot in every frame.

    ``frames``: an ``N×H×W`` array, or a sequence of JPEG bytes / image arrays / None. A frame
    that does not decode, is too small or holds a NaN gets ``corrupt_frame``; one whose size is
    not ``shape`` (H, W; default: the first good frame's) ``wrong_size``; None ``missing``.
    (A colour image counts as one frame only inside a sequence.)
    """
    if method not in DETECTORS:
        raise ValueError(f"unknown detector {method!r}; expected one of {', '.join(DETECTORS)}")
    if not isinstance(frames, np.ndarray) and len(frames) > _CHUNK:
        if shape is None:  # every chunk measures against the same size: the first good frame's
            first = next((im for im in (as_gray(f) for f in frames if f is not None)
                          if im is not None and im.ndim == 2), None)
            shape = None if first is None else first.shape
        # decoded and measured a cache-sized chunk at a time (~25 % faster than one big stack)
        parts = [detect_spots(frames[k:k + _CHUNK], method, settings, shape)
                 for k in range(0, len(frames), _CHUNK)]
        return SpotBatch(*(np.concatenate([getattr(p, name) for p in parts]) for name in
                           ("u", "v", "peak", "area", "saturated", "reason_code", "blobs")))
    stack, codes = _to_stack(frames, shape)
    good = codes == 0
    out = SpotBatch.empty(len(good))
    out.reason_code[:] = codes
    if not good.any():
        return out
    if method == "centroid":
        res = _detect_centroid(stack, settings)
    elif method == "blob":
        # a stack built here from a list of frames is ours to blank and restore in place
        res = _detect_blob(stack, settings, scratch=not isinstance(frames, np.ndarray))
    else:
        res = _detect_peak(stack, settings, method)
    if good.all():
        return res
    for name in ("u", "v", "peak", "area", "saturated", "reason_code", "blobs"):
        getattr(out, name)[good] = getattr(res, name)
    return out


def detect_several(frames, k: int, method: str = DEFAULT_DETECTOR,
                   settings: DetectorSettings = DEFAULTS, shape=None, reasons: bool = False):
    """Up to ``k`` spots in every frame, most LED-like first (several LEDs in view, issue 16):
    ``N×k×2`` pixels, NaN where a frame holds fewer. ``blob`` ranks the frame's blobs by
    height and compactness (:func:`_segment`) and measures each as it measures one; the other
    detectors find one spot. Frames as :func:`detect_spots` takes them. With ``reasons``,
    ``(spots, reason per frame)``: None, or why a frame could not be measured (``corrupt_frame``,
    ``wrong_size``, ``missing``; a frame without a spot has None and NaN rows)."""
    if reasons:
        codes = np.zeros(len(frames), np.int8)
        uv = _detect_several(frames, k, method, settings, shape, codes)
        return uv, [_CODE_REASON[int(c)] if c in (_REASON_CODE[CORRUPT],
                                                   _REASON_CODE[WRONG_SIZE],
                                                   _REASON_CODE[MISSING]) else None
                    for c in codes]
    return _detect_several(frames, k, method, settings, shape, None)


def _detect_several(frames, k, method, settings, shape, codes_out) -> np.ndarray:
    if method not in DETECTORS:
        raise ValueError(f"unknown detector {method!r}; expected one of {', '.join(DETECTORS)}")
    k = max(1, int(k))
    n_all = len(frames)
    out = np.full((n_all, k, 2), np.nan)
    if k == 1 or method != "blob":
        found = detect_spots(frames, method, settings, shape)
        out[:, 0] = found.uv
        if codes_out is not None:
            codes_out[:] = found.reason_code
        return out
    if not isinstance(frames, np.ndarray) and n_all > _CHUNK:
        for a in range(0, n_all, _CHUNK):
            part = None if codes_out is None else codes_out[a:a + _CHUNK]
            out[a:a + _CHUNK] = _detect_several(frames[a:a + _CHUNK], k, method, settings,
                                                shape, part)
        return out
    stack, codes = _to_stack(frames, shape)
    if codes_out is not None:
        codes_out[:] = codes
    if stack is None or not (codes == 0).any():
        return out
    where = np.flatnonzero(codes == 0)
    s = settings
    r, c, peak, bg, sigma, code = _peak(stack, s)
    n, h, w = stack.shape
    rows = np.full((n, k), -1)
    cols = np.zeros((n, k), int)
    for i in np.flatnonzero(code == 0):
        img = stack[i]
        fbg = _median(img[::4, ::4].ravel())
        floor = max(s.min_contrast, s.min_snr * sigma[i])
        found = _segment(img, fbg, fbg + max(s.threshold * (peak[i] - fbg), 3 * sigma[i]),
                         floor, s, k)
        if found is not None:
            m = len(found[0])
            rows[i, :m], cols[i, :m] = found[0], found[1]
    for j in range(k):
        idx = np.flatnonzero(rows[:, j] >= 0)
        if not len(idx):
            continue
        u, v, _, _, edge = _core_centroid(stack[idx], rows[idx, j], cols[idx, j], s)
        with np.errstate(invalid="ignore"):
            edge |= (u < 1.0) | (v < 1.0) | (u > w - 2.0) | (v > h - 2.0)
        out[where[idx], j, 0] = np.where(edge, np.nan, u)
        out[where[idx], j, 1] = np.where(edge, np.nan, v)
    return out


def detect_spot(frame, method: str = DEFAULT_DETECTOR,
                settings: DetectorSettings = DEFAULTS) -> Spot:
    """Detect the spot in one frame (JPEG bytes or an H×W / H×W×3 image array)."""
    if method not in DETECTORS:
        raise ValueError(f"unknown detector {method!r}; expected one of {', '.join(DETECTORS)}")
    img = as_gray(frame)
    if img is None:
        return Spot(np.nan, np.nan, 0.0, 0, False, CORRUPT, 0)
    return detect_spots(img[None], method, settings)[0]


# -- one frame at a time (the live path) -------------------------------------------------------

@cache
def _ring_flat(half: int, h: int, w: int) -> np.ndarray:
    """:func:`_ring_offsets` as flat indices into a ``min(2h+1, h) × min(2h+1, w)`` window."""
    dy, dx = _ring_offsets(half, h, w)
    return dy * min(2 * half + 1, w) + dx


def _cut(img: np.ndarray, r: int, c: int, half: int):
    """The (2h+1)² window around (r, c), clamped inside the frame as :func:`_windows` clamps
    it, and its origin."""
    h, w = img.shape
    size = 2 * half + 1
    r0 = min(max(r - half, 0), max(h - size, 0))
    c0 = min(max(c - half, 0), max(w - size, 0))
    return img[r0:r0 + size, c0:c0 + size], r0, c0


def detect_frame(frame, k: int = 1, method: str = DEFAULT_DETECTOR,
                 settings: DetectorSettings = DEFAULTS, shape=None, every_reason: bool = False):
    """Up to ``k`` spots of one frame (JPEG bytes or an image array), most LED-like first:
    ``(k×2 px with NaN rows, reason)`` as :func:`detect_several` gives for ``[frame]``, with
    ``reason`` None unless the frame could not be measured (``corrupt_frame``, ``wrong_size``).
    ``every_reason``: the reason :func:`detect_spots` gives the frame's best spot instead
    (``no_spot``, ``too_dim`` and ``at_edge`` too), as the locator reports each camera.

    The live path takes frames one at a time, where a stack of one costs what a stack of
    hundreds does in numpy calls (~0.6 ms). ``blob`` is measured here step by step on the
    frame itself (:func:`_detect_blob`'s steps, equal to it to rounding: tested); the other
    detectors go through the batch."""
    k = max(1, int(k))
    if method != "blob":
        if every_reason and k == 1:
            spot = detect_spots([frame], method, settings, shape)[0]
            return np.array([[spot.u, spot.v]]), spot.reason
        uv, why = detect_several([frame], k, method, settings, shape, reasons=True)
        if every_reason and why[0] is None:
            why = [detect_spots([frame], method, settings, shape)[0].reason]
        return uv[0], why[0]
    uv, code = _detect_frame_blob(frame, k, settings, shape)
    if not every_reason and code not in _UNMEASURED:
        code = 0
    return uv, _CODE_REASON[code]


#: the reasons :func:`detect_frame` gives without ``every_reason``: no frame to measure
_UNMEASURED = (_REASON_CODE[CORRUPT], _REASON_CODE[WRONG_SIZE], _REASON_CODE[MISSING])


def _detect_frame_blob(frame, k: int, s: DetectorSettings, shape):
    """:func:`detect_frame` with ``blob``: ``(k×2 px, reason code of the best spot)``."""
    out = np.full((k, 2), np.nan)
    # decoded and checked as a batch's frames are (the same reasons for the same frames)
    want = tuple(shape) if shape is not None else None
    if want is not None and min(want) < MIN_SIZE:
        return out, _REASON_CODE[CORRUPT]  # no spot can be measured in so small an image
    img = _decode_whole(frame, want)
    own = img is not None  # decoded here: this call's to change and restore
    if img is None:  # anything but a whole JPEG of the camera's size: the batch's checks
        codes, images = np.zeros(1, np.int8), {}
        with _QuietStderr():
            stack = _decode_into([frame], codes, want,
                                 np.empty((1, *want), np.uint8) if want else None, images)
        if codes[0]:
            return out, int(codes[0])
        own = stack is not None
        img = stack[0] if own else images[0]
    if img.dtype != np.uint8 or not img.flags.c_contiguous:  # a float frame: the batch
        if k == 1:
            spot = detect_spots(img[None], "blob", s)[0]
            return np.array([[spot.u, spot.v]]), _REASON_CODE[spot.reason]
        uv = detect_several(img[None], k, "blob", s)[0]
        return uv, int(detect_spots(img[None], "blob", s).reason_code[0])
    h, w = img.shape
    flat = int(img.argmax())
    r, c = divmod(flat, w)
    peak = float(img.flat[flat])
    win, r0, c0 = _cut(img, r, c, _RING)
    ring = win.ravel()[_ring_flat(_RING, h, w)].astype(np.int16)
    bg = _median(ring)
    sigma = max(1.4826 * _median(np.abs(ring[1:] - ring[:-1])) / np.sqrt(2.0), 1.0)
    if peak - bg < s.min_snr * sigma:
        return out, _REASON_CODE[NO_SPOT]
    if peak - bg < s.min_contrast:
        return out, _REASON_CODE[TOO_DIM]
    thr = bg + max(s.threshold * (peak - bg), 3.0 * sigma)
    if k == 1 and _outside_max_one(img, r, c, s.window, own) <= thr:
        spots = [(r, c)]
    else:
        fbg = _median(img[::4, ::4].ravel())
        floor = max(s.min_contrast, s.min_snr * sigma)
        found = _segment(img, fbg, fbg + max(s.threshold * (peak - fbg), 3 * sigma), floor,
                         s, k)
        if found is None:  # nothing point-like: a lamp alone, or noise
            return out, _REASON_CODE[NO_SPOT]
        spots = list(zip(found[0].tolist(), found[1].tolist()))
    code = 0
    for j, (r, c) in enumerate(spots):
        u, v, edge = _core_centroid_one(img, r, c, s)
        if 1.0 <= u <= w - 2.0 and 1.0 <= v <= h - 2.0 and not edge:
            out[j] = u, v
        elif j == 0:  # off the sensor in part (the batch's at_edge), or not measurable
            code = _REASON_CODE[AT_EDGE if edge or u == u else NO_SPOT]
    return out, code


def _decode_whole(frame, want):
    """The common live frame — JPEG bytes, whole (SOI to EOI), declaring the camera's size —
    decoded to grayscale; None for anything else (which the batch's checks then judge)."""
    if type(frame) is not bytes or want is None:
        return None
    img = decode_gray(frame, want)
    return img if img is not None and img.shape == want else None


def _outside_max_one(img: np.ndarray, r: int, c: int, half: int, own: bool = False) -> float:
    """:func:`_outside_max` of one frame: its maximum outside the window around (r, c) and on
    the window's rim where the rim is not the frame's border. ``own``: the frame may be changed
    for a moment (the window blanked in place and put back), else it is copied (19 kB at
    160 × 120)."""
    h, w = img.shape
    size = 2 * half + 1
    win, r0, c0 = _cut(img, r, c, half)
    rim = win.ravel()[_ring_flat(half, h, w)]
    if r0 == 0 or c0 == 0 or r0 + size >= h or c0 + size >= w:  # the rim meets the border
        dy, dx = _ring_offsets(half, h, w)
        rim = np.where((r0 + dy == 0) | (r0 + dy == h - 1) | (c0 + dx == 0)
                       | (c0 + dx == w - 1), 0, rim)
    if own:
        saved = win.copy()
        win[...] = 0
        rest = img.flat[img.argmax()]
        win[...] = saved
    else:
        copy = img.copy()
        copy[r0:r0 + size, c0:c0 + size] = 0
        rest = copy.max()
    return float(max(rest, rim.max()))


@cache
def _plane_flat(half: int):
    """:func:`_plane_design` flattened: the ring's flat indices, the operator that turns the
    ring's values into the plane's value at every pixel of the window, and the ``(2h+1)²×3``
    design [1, u, v] whose product with weights gives their sum and moments."""
    gx, gy, ring, fit = _plane_design(half)
    design = np.c_[np.ones(gx.size), gx.ravel(), gy.ravel()]
    return np.flatnonzero(ring), design @ fit.T, design


def _core_centroid_one(img: np.ndarray, r: int, c: int, s: DetectorSettings):
    """:func:`_core_centroid` of one frame's spot at (r, c): ``(u, v, at_edge)``, NaN when
    its centre pixel is on the frame's border (``at_edge``)."""
    import math

    h, w = img.shape
    peak = float(img[r, c])
    p1 = float(img[r, c - 1]) if c > 0 else peak
    p2 = float(img[r, c + 1]) if c < w - 1 else peak
    p3 = float(img[r - 1, c]) if r > 0 else peak
    p4 = float(img[r + 1, c]) if r < h - 1 else peak
    look, lr0, lc0 = _cut(img, r, c, 5)
    lo = _median(look.ravel()[_ring_flat(5, h, w)])

    def lg(x):
        return math.log(max(x - lo, 0.5))

    lp = lg(peak)
    curv = max(2 * lp - lg(p1) - lg(p2), 2 * lp - lg(p3) - lg(p4))
    half = math.ceil(_REACH / math.sqrt(max(curv, 1e-3)) - 1e-9)
    if peak >= s.saturation:  # centred on the flat top (see _core_centroid)
        level = lo + 0.8 * (peak - lo)
        _, labels = _cv2.connectedComponents((look >= level).astype(np.uint8), connectivity=8)
        yy, xx = np.nonzero(labels == labels[r - lr0, c - lc0])
        cu, cv = lc0 + xx.mean(), lr0 + yy.mean()
        extent = float(np.maximum(np.abs(xx + lc0 - cu), np.abs(yy + lr0 - cv)).max())
        half = math.ceil(extent) + 3
        r, c = int(np.rint(cv)), int(np.rint(cu))
    half = min(max(half, 3), _MAX_HALF)
    if r < 1 or c < 1 or r > h - 2 or c > w - 2:
        return np.nan, np.nan, True
    win, r0, c0 = _cut(img, r, c, half)
    ring, plane, design = _plane_flat(half)
    flat = win.astype(float).ravel()
    sig = flat - plane @ flat[ring]
    tot, su, sv = np.maximum(sig - s.threshold * sig.max(), 0.0) @ design
    if not tot > 0:  # nothing over the threshold (the batch's NaN)
        return np.nan, np.nan, False
    return c0 + su / tot, r0 + sv / tot, False
