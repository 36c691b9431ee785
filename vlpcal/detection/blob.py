"""The ``blob`` detector (the default): choose the LED among the bright blobs, then measure it.

Choosing: when every pixel above the threshold lies within the window around the brightest
pixel, there is one blob and it is the LED; otherwise the frame is segmented and the blobs
ranked by height and compactness (:func:`_segment`): a floor reflection is dimmer and wider than
the LED, a lamp wider. Measuring (:func:`_core_centroid`): a thresholded centroid over a
background plane fitted to a ring around the spot, unbiased on saturated flat tops where every
3-point fit is pulled toward the first flat pixel, and little moved by the flank of a nearby
reflection (the paper's detectors, section 3.2, are in :mod:`.peaks`).

Two paths, side by side: the batch (a stack ``N×H×W``, vectorised over frames) and one frame at
a time (the live path), where a numpy call on a stack of one costs as much as on a stack of
hundreds. They share their steps (:mod:`.windows`, :func:`_choose`, :func:`_window_half`,
:func:`_plane_centroid`, :func:`_on_sensor`); only what must be vectorised for the batch has
a one-frame form beside it (:func:`_outside_max_one`, :func:`_flat_top_one`).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from .decoding import _cv2
from .results import _REASON_CODE, DetectorSettings, Reason, SpotBatch, _finish
from .windows import (
    _cut,
    _median,
    _medians,
    _neighbours,
    _on_border,
    _origin,
    _peak,
    _peak_one,
    _ring,
    _ring_offsets,
    _threshold,
    _windows,
    _xp,
)

#: largest half-size of the measuring window (a 15×15 window)
_MAX_HALF = 7
#: an unsaturated spot's measuring window reaches this many spot sigmas (where a Gaussian is
#: down to 6 % of its peak): wider clears the spot better, narrower keeps out a neighbouring
#: reflection; 2.35 is the best of 2.0–2.5 on the detector benchmark's sets
_REACH = 2.35
#: half size of the look around the brightest pixel (11×11) whose ring is the background of
#: the spot's shape, and inside which a saturated spot's flat top is found
_LOOK = 5
#: a saturated spot's flat top: its pixels above this share of its height over the background
#: (JPEG ringing leaves saturated pixels anywhere from ~210 to 255)
_FLAT_TOP = 0.8


# -- choosing the LED's blob (both paths) ------------------------------------------------------

def _segment(img, bg: float, thr: float, floor: float, s: DetectorSettings, most: int = 1):
    """Rank the blobs of one frame as LEDs: ``(rows, cols, tops, candidates)`` of the best
    ``most`` (most LED-like first), or None when no blob is a candidate.

    Blobs are the connected components above ``thr``; a candidate is one whose height over
    ``bg`` reaches ``floor`` (it would be a spot on its own). Each is scored by its height
    divided by ``1 + (core radius / led_radius)²``, the core being its pixels above half its
    own height; a core wider than ``max_core_radius`` is no candidate at all. A wide lamp or a
    diffuse reflection has a wide core even when it merges with the LED at the segmentation
    threshold; a JPEG speck has a tiny height. A blob cut by the frame's edge (a lamp half
    outside the view) scores a quarter.
    """
    h, w = img.shape
    mask = (img > thr).astype(np.uint8)
    k, labels, stats, _ = _cv2.connectedComponentsWithStats(mask, connectivity=8)
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


def _choose(img: np.ndarray, peak: float, sigma: float, s: DetectorSettings, most: int = 1):
    """:func:`_segment` one frame whose brightest pixel is ``peak`` (noise ``sigma``): the best
    ``most`` blobs, or None. The whole frame is segmented, so its background is the frame's
    (the median of every 4th pixel), not the peak's ring (which a wide lamp raises)."""
    fbg = _median(img[::4, ::4].ravel())
    floor = max(s.min_contrast, s.min_snr * sigma)
    return _segment(img, fbg, _threshold(peak, fbg, sigma, s), floor, s, most)


def _outside_max(stack: np.ndarray, r, c, half: int, scratch: bool = False) -> np.ndarray:
    """Each frame's maximum outside the window :func:`_windows` cuts around (r, c), and on the
    window's rim except where the rim runs along the frame's border (a spot cut by the edge of
    the image touches it there): above the threshold, there is another blob. The window is
    blanked and the frame's maximum taken: in place and restored when the stack is the
    caller's own scratch copy (``scratch``), else on a copy (a threshold image of the frames
    would cost more in reductions)."""
    n, h, w = stack.shape
    size = 2 * half + 1
    r0, c0 = _origin(r, half, h), _origin(c, half, w)
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
    dy, dx, _ = _ring_offsets(half, h, w)
    rim = stack[np.arange(n)[:, None], r0[:, None] + dy, c0[:, None] + dx].astype(float)
    rim[_on_border(r0[:, None], c0[:, None], dy, dx, h, w)] = 0.0
    return np.maximum(outside, rim.max(axis=1))


def _outside_max_one(img: np.ndarray, r: int, c: int, half: int, own: bool = False) -> float:
    """:func:`_outside_max` of one frame. ``own``: the frame may be changed for a moment (the
    window blanked in place and put back), else it is copied."""
    h, w = img.shape
    size = 2 * half + 1
    win, r0, c0 = _cut(img, r, c, half)
    dy, dx, flat = _ring_offsets(half, h, w)
    rim = win.ravel()[flat]
    if r0 == 0 or c0 == 0 or r0 + size >= h or c0 + size >= w:  # the rim meets the border
        rim = np.where(_on_border(r0, c0, dy, dx, h, w), 0, rim)
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


# -- measuring the spot (both paths) -----------------------------------------------------------

def _window_half(peak, p1, p2, p3, p4, lo):
    """Half-size of an unsaturated spot's measuring window: ``_REACH`` σ, σ from the
    log-curvature at its peak over the background ``lo`` (exact for a Gaussian); the sharper
    axis counts, as a reflection's flank flattens the curvature on its side only. Arrays, or
    one frame's floats."""
    xp = _xp(peak)

    def lg(x):
        return xp.log(xp.maximum(x - lo, 0.5))

    lp = lg(peak)
    curv = xp.maximum(2 * lp - lg(p1) - lg(p2), 2 * lp - lg(p3) - lg(p4))
    return xp.ceil(_REACH / xp.sqrt(xp.maximum(curv, 1e-3)) - 1e-9)


@cache
def _plane(half: int):
    """A (2h+1)² window's background plane, flattened: the flat indices of its border ring,
    the least-squares fit that turns the ring's values into the plane's ``[a, b_u, b_v]``
    (``K×3``), the design ``[1, u, v]`` of every pixel (``(2h+1)²×3``: the plane's values are
    ``design @ [a, b_u, b_v]``, and weights' ``@ design`` their sum and moments), and the two
    composed (``(2h+1)²×K``, ring values → the plane's value at every pixel)."""
    size = 2 * half + 1
    gy, gx = np.mgrid[0:size, 0:size].astype(float)
    ring = (gy == 0) | (gx == 0) | (gy == size - 1) | (gx == size - 1)
    fit = np.linalg.pinv(np.c_[np.ones(ring.sum()), gx[ring], gy[ring]])
    design = np.c_[np.ones(gx.size), gx.ravel(), gy.ravel()]
    return np.flatnonzero(ring), fit.T, design, design @ fit


def _plane_centroid(flat: np.ndarray, half: int, threshold: float):
    """Plane-subtracted, thresholded weights of windows flattened to ``N×(2h+1)²`` (or one
    window's ``(2h+1)²``): ``(weights' sum and moments ×3, peak over the plane, weights)``;
    the centroid from the window's top-left pixel is moments / sum, none where the sum is 0.

    The plane fitted to the ring is the background, so a gradient, vignetting or the flank of a
    neighbouring reflection is removed before the centroid; weights are ``I − plane − T`` with
    T at ``threshold`` of the remaining peak, so pixels enter at zero (no jump as a pixel
    crosses the threshold)."""
    ring, fit, design, plane = _plane(half)
    if flat.ndim == 1:  # one window (the live path): one product, whole-array reductions
        sig = flat - plane @ flat[ring]
        pk = sig.max()
        wgt = np.maximum(sig - threshold * pk, 0.0)
    else:  # N windows: each plane's 3 coefficients, then its values (N·K·S² products fewer)
        sig = flat - (flat[:, ring] @ fit) @ design.T
        pk = sig.max(axis=1)
        wgt = np.maximum(sig - threshold * pk[:, None], 0.0)
    return wgt @ design, pk, wgt


def _on_sensor(u, v, h: int, w: int):
    """Whether a spot's centre is not within a pixel of the frame's border (where part of the
    spot is off the sensor): False for a NaN centre; arrays or floats."""
    return ~((u < 1.0) | (v < 1.0) | (u > w - 2.0) | (v > h - 2.0)) if isinstance(
        u, np.ndarray) else not (u < 1.0 or v < 1.0 or u > w - 2.0 or v > h - 2.0)


def _core_centroid(stack, r, c, s: DetectorSettings):
    """:func:`_plane_centroid` of the spot whose brightest pixel is (r, c), in a window that
    clears the spot and stays close enough to exclude a neighbouring reflection's core.

    The window is centred on the brightest pixel and reaches :func:`_window_half` (at least
    3 px); a saturated spot's window is centred on its flat top (:func:`_flat_top`) and reaches
    3 px beyond it.

    Returns u, v, the peak over the plane, the pixel count above the threshold, and whether
    the spot's centre pixel is on the frame's border (``at_edge``: not measured; near the
    edge the window slides inside the frame, the ring then to one side).
    """
    n, h, w = stack.shape
    p1, p2, p3, p4 = _neighbours(stack, r, c)
    lo = _medians(_ring(stack, r, c, _LOOK))
    peak = stack[np.arange(n), r, c].astype(float)
    half = _window_half(peak, p1, p2, p3, p4, lo)
    rc, cc = r.copy(), c.copy()
    sat = np.flatnonzero(peak >= s.saturation)
    if len(sat):
        cu, cv, extent = _flat_top(stack, r[sat], c[sat], (lo + _FLAT_TOP * (peak - lo))[sat],
                                   sat)
        half[sat] = np.ceil(extent) + 3
        rc[sat], cc[sat] = np.rint(cv).astype(int), np.rint(cu).astype(int)
    half = np.clip(half, 3, _MAX_HALF).astype(int)
    u = np.full(n, np.nan)
    v = np.full(n, np.nan)
    height = np.zeros(n)
    area = np.zeros(n, int)
    edge = (rc < 1) | (cc < 1) | (rc > h - 2) | (cc > w - 2)
    for H in sorted(set(half.tolist())):  # (np.unique imports numpy.ma, slow to start)
        idx = np.flatnonzero((half == H) & ~edge)
        if not len(idx):
            continue
        win, wr0, wc0 = _windows(stack, rc[idx], cc[idx], H, idx)
        sums, height[idx], wgt = _plane_centroid(win.reshape(len(idx), -1), H, s.threshold)
        with np.errstate(invalid="ignore", divide="ignore"):
            u[idx] = wc0 + sums[:, 1] / sums[:, 0]
            v[idx] = wr0 + sums[:, 2] / sums[:, 0]
        area[idx] = (wgt > 0).sum(axis=1)
    return u, v, height, area, edge


def _flat_top(stack, r, c, level, frames):
    """The centre (u, v) of each saturated spot's flat top — its pixels at or above ``level``
    connected to (r, c) in the look around it — and its extent (px, the largest distance of
    one of its pixels from that centre, per axis)."""
    look, r0, c0 = _windows(stack, r, c, _LOOK, frames)
    flat = _grow(look >= level[:, None, None], r - r0, c - c0)
    yy, xx = np.mgrid[0:look.shape[1], 0:look.shape[2]]
    cnt = flat.sum(axis=(1, 2))
    cu = c0 + (flat * xx).sum(axis=(1, 2)) / cnt
    cv = r0 + (flat * yy).sum(axis=(1, 2)) / cnt
    du = np.abs(xx + c0[:, None, None] - cu[:, None, None])
    dv = np.abs(yy + r0[:, None, None] - cv[:, None, None])
    return cu, cv, np.max(np.where(flat, np.maximum(du, dv), 0.0), axis=(1, 2))


def _flat_top_one(look: np.ndarray, r0: int, c0: int, r: int, c: int, level: float):
    """:func:`_flat_top` of one frame, whose look around (r, c) is ``look`` at ``r0, c0``
    (OpenCV's 8-connected components: the same pixels)."""
    _, labels = _cv2.connectedComponents((look >= level).astype(np.uint8), connectivity=8)
    yy, xx = np.nonzero(labels == labels[r - r0, c - c0])
    cu, cv = c0 + xx.mean(), r0 + yy.mean()
    return cu, cv, float(np.maximum(np.abs(xx + c0 - cu), np.abs(yy + r0 - cv)).max())


def _core_centroid_one(img: np.ndarray, r: int, c: int, s: DetectorSettings):
    """:func:`_core_centroid` of one frame's spot at (r, c): ``(u, v, at_edge)``."""
    h, w = img.shape
    peak = float(img[r, c])
    p1 = float(img[r, c - 1]) if c > 0 else peak
    p2 = float(img[r, c + 1]) if c < w - 1 else peak
    p3 = float(img[r - 1, c]) if r > 0 else peak
    p4 = float(img[r + 1, c]) if r < h - 1 else peak
    look, r0, c0 = _cut(img, r, c, _LOOK)
    lo = _median(look.ravel()[_ring_offsets(_LOOK, h, w)[2]])
    half = _window_half(peak, p1, p2, p3, p4, lo)
    if peak >= s.saturation:
        cu, cv, extent = _flat_top_one(look, r0, c0, r, c, lo + _FLAT_TOP * (peak - lo))
        half = math.ceil(extent) + 3
        r, c = int(np.rint(cv)), int(np.rint(cu))
    half = min(max(half, 3), _MAX_HALF)
    if r < 1 or c < 1 or r > h - 2 or c > w - 2:
        return np.nan, np.nan, True
    win, r0, c0 = _cut(img, r, c, half)
    (tot, su, sv), _, _ = _plane_centroid(win.astype(float).ravel(), half, s.threshold)
    if not tot > 0:  # nothing over the threshold (the batch's NaN)
        return np.nan, np.nan, False
    return c0 + su / tot, r0 + sv / tot, False


# -- the two paths -----------------------------------------------------------------------------

def _detect_blob(stack, s: DetectorSettings, scratch: bool = False) -> SpotBatch:
    """``blob`` on a stack: ``N×H×W`` → :class:`SpotBatch` of ``N``; ``blobs`` says how many
    blobs competed where the frame had to be segmented. ``scratch``: the stack is the
    caller's to change for a moment (see :func:`_outside_max`)."""
    n, h, w = stack.shape
    r, c, peak, bg, sigma, code = _peak(stack, s)
    thr = _threshold(peak, bg, sigma, s)
    lone = _outside_max(stack, r, c, s.window, scratch) <= thr  # nothing above T elsewhere
    blobs = np.ones(n, int)
    top = peak.copy()
    for i in np.flatnonzero((code == 0) & ~lone):
        found = _choose(stack[i], peak[i], sigma[i], s)
        if found is None:  # nothing point-like: a lamp alone, or noise
            code[i] = _REASON_CODE[Reason.NO_SPOT]
        else:
            r[i], c[i], top[i], blobs[i] = found[0][0], found[1][0], found[2][0], found[3]
    u, v, _, area, edge = _core_centroid(stack, r, c, s)
    edge |= ~_on_sensor(u, v, h, w) & np.isfinite(u)
    code[(code == 0) & edge] = _REASON_CODE[Reason.AT_EDGE]
    code[(code == 0) & ~np.isfinite(u)] = _REASON_CODE[Reason.NO_SPOT]
    return _finish(u, v, top, area, top >= s.saturation, code, blobs)


def _detect_several_blob(stack, k: int, s: DetectorSettings) -> np.ndarray:
    """Up to ``k`` blobs of each frame of a stack, most LED-like first, each measured as
    :func:`_detect_blob` measures one: ``N×H×W`` → ``N×k×2`` px (NaN rows)."""
    r, c, peak, bg, sigma, code = _peak(stack, s)
    n, h, w = stack.shape
    out = np.full((n, k, 2), np.nan)
    rows = np.full((n, k), -1)
    cols = np.zeros((n, k), int)
    for i in np.flatnonzero(code == 0):
        found = _choose(stack[i], peak[i], sigma[i], s, k)
        if found is not None:
            m = len(found[0])
            rows[i, :m], cols[i, :m] = found[0], found[1]
    for j in range(k):
        idx = np.flatnonzero(rows[:, j] >= 0)
        if not len(idx):
            continue
        u, v, _, _, edge = _core_centroid(stack[idx], rows[idx, j], cols[idx, j], s)
        edge |= ~_on_sensor(u, v, h, w) & np.isfinite(u)
        out[idx, j, 0] = np.where(edge, np.nan, u)
        out[idx, j, 1] = np.where(edge, np.nan, v)
    return out


def _detect_frame_blob(img: np.ndarray, k: int, s: DetectorSettings, own: bool):
    """``blob`` on one decoded 8-bit frame, step by step (the batch's steps on one frame):
    ``H×W`` → ``(k×2 px, reason code of the best spot)``. ``own``: the frame is this call's to
    change for a moment (see :func:`_outside_max_one`)."""
    out = np.full((k, 2), np.nan)
    h, w = img.shape
    r, c, peak, bg, sigma, code = _peak_one(img, s)
    if code:
        return out, code
    if k == 1 and _outside_max_one(img, r, c, s.window, own) <= _threshold(peak, bg, sigma, s):
        spots = [(r, c)]
    else:
        found = _choose(img, peak, sigma, s, k)
        if found is None:  # nothing point-like: a lamp alone, or noise
            return out, _REASON_CODE[Reason.NO_SPOT]
        spots = list(zip(found[0].tolist(), found[1].tolist()))
    for j, (r, c) in enumerate(spots):
        u, v, edge = _core_centroid_one(img, r, c, s)
        if u == u and not edge and _on_sensor(u, v, h, w):
            out[j] = u, v
        elif j == 0:  # off the sensor in part (the batch's at_edge), or not measurable
            code = _REASON_CODE[Reason.AT_EDGE if edge or u == u else Reason.NO_SPOT]
    return out, code


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
