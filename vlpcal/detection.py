"""Spot detection: a camera frame (JPEG bytes or an image array) → the LED's sub-pixel centre.

Detectors by name (:data:`DETECTORS`):

- ``highest``: the brightest pixel (the paper's baseline, section 3.2 (a)).
- ``mean2``: the mean position of the two brightest pixels (the paper's "mean integer", (b)).
- ``nip``: the paper's NI-P (section 2.1, eqs. 4–6): the 3-point parabola vertex around the
  brightest pixel, per axis.
- ``gauss``: the 3-point parabola through the logarithms (exact for a sampled Gaussian).
- ``centroid``: background-subtracted, thresholded, intensity-weighted centroid in an 11×11
  window around the brightest pixel.
- ``blob`` (the default, :data:`DEFAULT_DETECTOR`): segments every bright blob, picks the LED by
  brightness and compactness (a floor reflection is dimmer and wider, a lamp wider), and takes
  the thresholded centroid of that blob: unbiased on saturated flat tops, where every 3-point
  fit is pulled ~0.3 px toward the first flat pixel (FIELD-NOTES).

Every detector returns the same fields (:class:`Spot` for one frame, :class:`SpotBatch` for an
``N×H×W`` stack); a frame without a usable spot carries a reason instead of raising:
``no_spot``, ``too_dim``, ``at_edge`` or ``corrupt_frame``. Pixels are OpenCV's (u = column,
v = row, the top-left pixel's centre at (0, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Reasons a frame gives no spot.
NO_SPOT, TOO_DIM, AT_EDGE, CORRUPT = "no_spot", "too_dim", "at_edge", "corrupt_frame"
REASONS = (NO_SPOT, TOO_DIM, AT_EDGE, CORRUPT)
_REASON_CODE = {None: 0, NO_SPOT: 1, TOO_DIM: 2, AT_EDGE: 3, CORRUPT: 4}
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
    #: a second blob counts when its peak reaches this share of the brightest one's height
    candidate_share: float = 0.25


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


# -- decoding ----------------------------------------------------------------------------------

def decode_gray(data) -> np.ndarray | None:
    """JPEG bytes → 8-bit grayscale (luma) image, or None when the bytes are not a whole JPEG.

    A truncated JPEG decodes to a grey-filled image with only a warning, so the end-of-image
    marker is checked first (trailing zero padding, as some cameras send, is allowed).
    """
    import cv2

    if isinstance(data, np.ndarray):
        return data
    buf = bytes(data) if not isinstance(data, bytes) else data
    if len(buf) < 4 or buf[:2] != b"\xff\xd8" or buf.rstrip(b"\x00")[-2:] != b"\xff\xd9":
        return None
    try:
        img = cv2.imdecode(np.frombuffer(buf, np.uint8), cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        return None
    return img


def as_gray(image) -> np.ndarray | None:
    """Image array (H×W, H×W×3 BGR) or JPEG bytes → 2D float-compatible array, None if corrupt."""
    if isinstance(image, (bytes, bytearray, memoryview)):
        return decode_gray(image)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        import cv2

        img = cv2.cvtColor(img[..., :3].astype(np.uint8), cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.size == 0:
        return None
    return img


# -- shared steps (vectorised over a stack) ----------------------------------------------------

def _noise(stack: np.ndarray) -> np.ndarray:
    """Per-frame noise sigma (DN) from a 1-in-16 pixel subsample.

    The median absolute difference of horizontally adjacent pixels (over √2): a smooth
    background gradient does not inflate it. Floor of 1 DN (8-bit quantisation and JPEG
    smoothing make smaller estimates meaningless).
    """
    a = stack[:, ::4, 0:-1:4].reshape(len(stack), -1).astype(np.float32)
    b = stack[:, ::4, 1::4].reshape(len(stack), -1).astype(np.float32)
    return np.maximum(1.4826 * np.median(np.abs(b - a), axis=1) / np.sqrt(2.0), 1.0).astype(float)


#: half size of the square ring (15×15) whose median is the background under the spot
_RING = 7


def _peak(stack: np.ndarray, s: DetectorSettings):
    """Brightest pixel (row, column, value), local background, noise sigma and reason codes.

    The background is the median of a ring of pixels around the brightest one: local, so a
    gradient or vignetting across the frame neither hides a spot nor invents one.
    """
    r, c, peak = _argmax(stack)
    win, _, _ = _windows(stack, r, c, _RING)
    ring = np.concatenate([win[:, 0, :], win[:, -1, :], win[:, 1:-1, 0], win[:, 1:-1, -1]], 1)
    bg = np.median(ring, axis=1)
    sigma = _noise(stack)
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
    f = stack.astype(float) if stack.dtype != float else stack
    return (f[i, r, np.maximum(c - 1, 0)], f[i, r, np.minimum(c + 1, w - 1)],
            f[i, np.maximum(r - 1, 0), c], f[i, np.minimum(r + 1, h - 1), c])


def _vertex(p1, p, p2):
    """NI-P, eqs. 4–6: ``(P2 − P1) / (2 (2P − P1 − P2))``; 0 where the three are flat."""
    den = 2.0 * (2.0 * p - p1 - p2)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den > 0, (p2 - p1) / den, 0.0)
    return np.clip(off, -0.5, 0.5)


def _windows(stack: np.ndarray, r, c, half: int):
    """``N×(2h+1)×(2h+1)`` windows around (r, c), clamped inside the frame, and their origins."""
    n, h, w = stack.shape
    size = 2 * half + 1
    r0 = np.clip(r - half, 0, max(h - size, 0))
    c0 = np.clip(c - half, 0, max(w - size, 0))
    off = np.arange(min(size, h))[:, None], np.arange(min(size, w))[None, :]
    rows = r0[:, None, None] + off[0]
    cols = c0[:, None, None] + off[1]
    return stack[np.arange(n)[:, None, None], rows, cols].astype(float), r0, c0


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
    elif method in ("nip", "gauss"):
        p1, p2, p3, p4 = _neighbours(stack, r, c)
        if method == "gauss":
            # log of the height above background: a Gaussian becomes an exact parabola
            def lg(x):
                return np.log(np.maximum(x - bg + 0.5, 0.5))
            p, p1, p2, p3, p4 = lg(peak), lg(p1), lg(p2), lg(p3), lg(p4)
        else:
            p = peak
        u = c + _vertex(p1, p, p2)
        v = r + _vertex(p3, p, p4)
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


#: threshold levels (share of the peak's height) at which ``blob`` re-checks its centroid
_SPLIT_LEVELS = (0.35, 0.6)
#: a centroid that moves more than this (px) when the threshold rises is contaminated by a
#: neighbouring blob (a reflection merged into the LED's): the higher level is kept
_SPLIT_SHIFT = 0.3


def _segment_one(img, bg, thr_share, s: DetectorSettings):
    """Blobs of one frame above ``bg + share · height``: the chosen one and the candidate count.

    Returns ``(u, v, top, area, radius, bbox, candidates)`` of the best-scoring candidate, or
    None when nothing is above the threshold.
    """
    import cv2

    h, w = img.shape
    height = float(img.max()) - bg
    thr = bg + thr_share * height
    mask = (img > thr).astype(np.uint8)
    k, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if k <= 1:
        return None
    # per-component sums over the thresholded pixels only (bincount), no loop over pixels
    nz = np.flatnonzero(mask)
    lab = labels.ravel()[nz]
    f = img.ravel()[nz].astype(float)
    wgt = f - thr
    uu, vv = (nz % w).astype(float), (nz // w).astype(float)
    wsum = np.bincount(lab, wgt, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.bincount(lab, wgt * uu, k) / wsum
        mv = np.bincount(lab, wgt * vv, k) / wsum
        var = (np.bincount(lab, wgt * uu * uu, k) + np.bincount(lab, wgt * vv * vv, k)) / wsum
        radius = np.sqrt(np.maximum(var - mu * mu - mv * mv, 0.0))
    top = np.zeros(k)
    np.maximum.at(top, lab, f)
    excess = top - bg
    cand = np.flatnonzero(excess >= s.candidate_share * height)
    cand = cand[cand > 0]
    score = excess[cand] / (1.0 + (radius[cand] / s.led_radius) ** 2)
    j = int(cand[np.argmax(score)])
    return mu[j], mv[j], top[j], int(stats[j, 4]), radius[j], stats[j, :4], len(cand)


def _detect_blob(stack, s: DetectorSettings) -> SpotBatch:
    """``blob``: the centroid of the LED's blob, chosen among all bright blobs of the frame.

    Fast path (vectorised): when every pixel above the threshold lies inside the window around
    the brightest pixel and the window's centroid does not move when the threshold is raised,
    the answer is that window's centroid. Otherwise the
    frame is segmented (OpenCV connected components), each candidate blob is scored by its
    height over background divided by ``1 + (radius / led_radius)²`` and the best is kept. A
    centroid that shifts when the threshold rises (a reflection merged into the LED's blob) is
    replaced by the one at the higher threshold (:data:`_SPLIT_LEVELS`).
    """
    n, h, w = stack.shape
    r, c, peak, bg, sigma, code = _peak(stack, s)
    thr = bg + np.maximum(s.threshold * (peak - bg), 3.0 * sigma)
    u, v, _, area, radius, touches, _ = _window_centroid(stack, r, c, thr, s.window)
    total = (stack > thr[:, None, None]).sum(axis=(1, 2))
    hi = bg + _SPLIT_LEVELS[-1] * (peak - bg)
    u_hi, v_hi = _window_centroid(stack, r, c, hi, s.window)[:2]
    steady = np.hypot(u - u_hi, v - v_hi) <= _SPLIT_SHIFT
    simple = (total == area) & ~touches & steady
    out = SpotBatch(u, v, peak, area, peak >= s.saturation, code, np.ones(n, int))
    for i in np.flatnonzero((code == 0) & ~simple):
        img = stack[i]
        # the whole frame is segmented, so its background is the frame's, not the peak's ring
        # (which a wide lamp raises)
        fbg = float(np.median(img[::4, ::4]))
        share = max(s.threshold, 3.0 * sigma[i] / max(peak[i] - fbg, 1e-9))
        found = _segment_one(img, fbg, share, s)
        for level in _SPLIT_LEVELS:
            if found is None or level <= share:
                break
            higher = _segment_one(img, fbg, level, s)
            if higher is None or np.hypot(higher[0] - found[0], higher[1] - found[1]) \
                    <= _SPLIT_SHIFT:
                break
            found = higher[:6] + (max(found[6], higher[6]),)
        if found is None:
            out.reason_code[i] = _REASON_CODE[NO_SPOT]
            continue
        out.u[i], out.v[i], out.peak[i], out.area[i], _, (x0, y0, bw, bh), out.blobs[i] = found
        out.saturated[i] = out.peak[i] >= s.saturation
        if x0 == 0 or y0 == 0 or x0 + bw == w or y0 + bh == h:
            out.reason_code[i] = _REASON_CODE[AT_EDGE]
    return _finish(out.u, out.v, out.peak, out.area, out.saturated, out.reason_code, out.blobs)


DETECTORS = ("highest", "mean2", "nip", "gauss", "centroid", "blob")


def detect_spots(frames, method: str = DEFAULT_DETECTOR,
                 settings: DetectorSettings = DEFAULTS) -> SpotBatch:
    """Detect the spot in every frame.

    ``frames``: an ``N×H×W`` array, or a sequence of JPEG bytes / image arrays (frames that do
    not decode, or whose size differs from the first good frame, get ``corrupt_frame``).
    """
    if method not in DETECTORS:
        raise ValueError(f"unknown detector {method!r}; expected one of {', '.join(DETECTORS)}")
    if isinstance(frames, np.ndarray) and frames.ndim == 3:
        stack, good = frames, None
    else:
        images = [as_gray(f) for f in frames]
        shapes = [im.shape for im in images if im is not None]
        if not shapes:
            out = SpotBatch.empty(len(images))
            out.reason_code[:] = _REASON_CODE[CORRUPT]
            return out
        good = np.array([im is not None and im.shape == shapes[0] for im in images])
        stack = np.stack([im for im, g in zip(images, good) if g])
    if method == "centroid":
        res = _detect_centroid(stack, settings)
    elif method == "blob":
        res = _detect_blob(stack, settings)
    else:
        res = _detect_peak(stack, settings, method)
    if good is None or good.all():
        return res
    out = SpotBatch.empty(len(good))
    out.reason_code[:] = _REASON_CODE[CORRUPT]
    for name in ("u", "v", "peak", "area", "saturated", "reason_code", "blobs"):
        getattr(out, name)[good] = getattr(res, name)
    return out


def detect_spot(frame, method: str = DEFAULT_DETECTOR,
                settings: DetectorSettings = DEFAULTS) -> Spot:
    """Detect the spot in one frame (JPEG bytes or an H×W / H×W×3 image array)."""
    img = as_gray(frame)
    if img is None:
        return Spot(np.nan, np.nan, 0.0, 0, False, CORRUPT, 0)
    return detect_spots(img[None], method, settings)[0]
