"""The ``blob`` detector: choose the LED among the bright blobs, then measure it.

Its batch path (a stack ``N×H×W``) and its one-frame path (the live path) stand side by side.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from .decoding import _cv2
from .results import _REASON_CODE, AT_EDGE, NO_SPOT, TOO_DIM, DetectorSettings, SpotBatch, _finish
from .windows import (
    _RING,
    _cut,
    _median,
    _medians,
    _neighbours,
    _peak,
    _ring,
    _ring_offsets,
    _windows,
)


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



# -- one frame at a time (the live path) -------------------------------------------------------

@cache
def _ring_flat(half: int, h: int, w: int) -> np.ndarray:
    """:func:`_ring_offsets` as flat indices into a ``min(2h+1, h) × min(2h+1, w)`` window."""
    dy, dx = _ring_offsets(half, h, w)
    return dy * min(2 * half + 1, w) + dx



def _detect_frame_blob(img: np.ndarray, k: int, s: DetectorSettings, own: bool):
    """``blob`` on one decoded 8-bit frame: ``(k×2 px, reason code of the best spot)``.
    ``own``: the frame is this call's to change for a moment (see :func:`_outside_max_one`)."""
    out = np.full((k, 2), np.nan)
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
