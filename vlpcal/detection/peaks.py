"""The detectors that start at the brightest pixel: ``highest``, ``mean2``, ``nip``,
``nip_eq5``, ``gauss`` and ``centroid`` (stack ``N×H×W`` → :class:`SpotBatch` of ``N``).

The first three are the paper's (section 3.2 compares them; NI-P is its section 2.1), kept as
the baseline every other detector is measured against on the same frames.
"""

from __future__ import annotations

import numpy as np

from .results import _REASON_CODE, DetectorSettings, Reason, SpotBatch, _finish
from .windows import _neighbours, _peak, _threshold, _windows


def _vertex(p1, p, p2, printed: bool = False):
    """NI-P's sub-pixel offset from the brightest pixel P and its neighbours P1, P2 (the paper's
    section 2.1).

    NI-P is the 3-point parabola vertex ``(P2 − P1) / (2 (2P − P1 − P2))``
    (docs/conventions.md, "The paper's methods"), exact on a sampled parabola. The paper's
    eq. 5 as printed — lines of slope ±step through P1 and P2, with
    step = ((P − P1) + (P − P2)) / 2 (eq. 1) — gives twice that offset,
    ``(P2 − P1) / (2P − P1 − P2)`` (``printed=True``, the ``nip_eq5`` detector). 0 where flat.
    """
    den = (1.0 if printed else 2.0) * (2.0 * p - p1 - p2)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den > 0, (p2 - p1) / den, 0.0)
    limit = 1.0 if printed else 0.5
    return np.clip(off, -limit, limit)


def _detect_peak(stack, s: DetectorSettings, method: str) -> SpotBatch:
    """``highest``, ``mean2``, ``nip``, ``nip_eq5`` and ``gauss``: the brightest pixel, and
    the sub-pixel offset its neighbours give (``at_edge`` when it has none on one side)."""
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
        code[(code == 0) & edge] = _REASON_CODE[Reason.AT_EDGE]
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
    thr = _threshold(peak, bg, sigma, s)
    u, v, tot, area, _, touches, frame_edge = _window_centroid(stack, r, c, thr, s.window)
    code[(code == 0) & touches & frame_edge] = _REASON_CODE[Reason.AT_EDGE]
    code[(code == 0) & ~(tot > 0)] = _REASON_CODE[Reason.NO_SPOT]
    return _finish(u, v, peak, area, peak >= s.saturation, code)

