"""A wand survey: two LEDs a known length apart on a rigid bar, waved through the room — its
spots as points, its length checked against the deployment's cameras, its sets whose ends the
fit does not put a wand apart, and its held-out length error (what motion-capture suites
report after a wand wave)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..triangulation import reprojection_errors, triangulate
from .calibration import format_length
from .errors import SurveyError
from .free_checks import MIN_SHARED, REJECT_SIGMAS
from .free_start import free_positions

#: a wand's length, relative: a bar cut and measured to a millimetre per metre
WAND_PRECISION = 1e-3
#: a stated wand length and the one the deployment's cameras show must agree within this
#: factor (a unit slip is a thousand; a hand-hung install's scale is off by a few per cent)
WAND_SCALE_RATIO = 3.0
#: a wand whose held-out sets miss its length by more than this share of it, on average, does
#: not fit (a good survey misses by a few thousandths)
WAND_MISFIT = 0.1
#: free sets whose two LEDs two cameras see, at least, for a wand survey (its length is held
#: on them, and a tenth are held out to measure it)
MIN_WAND_SETS = 20
#: a wand's spots are told apart within this many times the fitted spots' precision
LABEL_TOLERANCE = 5.0
#: every this many wand sets, one is held out of the fit and judged by its length
HELD_OUT_EVERY = 10


@dataclass
class WandError:
    """How far the fitted cameras put a wand's two LEDs from its length, on sets the fit never
    saw (m): what motion-capture suites report after a wand wave. Sets whose spots do not
    meet in a point (a reflection taken for an end) are counted apart, as the fit's own
    rejection would treat them."""

    sets: int
    mean: float  #: of |length − wand|
    p95: float
    rms: float
    per_camera: dict  #: camera id → mean |length − wand| over the held-out sets it saw
    discarded: int = 0  #: held-out sets whose spots disagree beyond the fit's rejection


def wand_errors(cameras, uv, wand: float, ids, pixel_sigma: float = np.inf) -> WandError:
    """The length errors of a wand's sets ``uv`` C×2M×2 (LEDs at 2m, 2m + 1), each LED
    triangulated from the cameras that saw it (sets with an LED seen by fewer than two: not
    judged; with a spot more than :data:`REJECT_SIGMAS` × ``pixel_sigma`` px off: discarded)."""
    seen = np.isfinite(uv).all(axis=2)
    two = seen.sum(axis=0) >= 2
    ok = two[0::2] & two[1::2]
    e = np.full(len(ok), np.nan)
    bad = np.zeros(len(ok), bool)
    if ok.any():
        cols = np.flatnonzero(np.repeat(ok, 2))
        P = triangulate(cameras, uv[:, cols]).X
        r = reprojection_errors(cameras, uv[:, cols], P)
        worst = np.nanmax(np.where(np.isfinite(r), r, 0.0), axis=0)
        bad[ok] = (worst[0::2] > REJECT_SIGMAS * pixel_sigma) | \
            (worst[1::2] > REJECT_SIGMAS * pixel_sigma)
        e[ok] = np.abs(np.linalg.norm(P[0::2] - P[1::2], axis=1) - wand)
    e[bad] = np.nan
    good = np.isfinite(e)
    per = {}
    for k, cid in enumerate(ids):
        mine = good & (seen[k, 0::2] | seen[k, 1::2])
        per[cid] = float(e[mine].mean()) if mine.any() else float("nan")
    if not good.any():
        return WandError(0, float("nan"), float("nan"), float("nan"), per, int(bad.sum()))
    return WandError(int(good.sum()), float(e[good].mean()),
                     float(np.percentile(e[good], 95)), float(np.sqrt(np.mean(e[good] ** 2))),
                     per, int(bad.sum()))


def wand_points(spots, order, labelled: bool) -> np.ndarray:
    """A wand's spots C×M×2×2 as C×2M×2 points (set m's LEDs at 2m, 2m + 1), each camera's
    slots put in the LEDs' order (``order`` C×M×2 from :func:`.network.network_start`;
    unknown: not used) unless the spots are ``labelled``."""
    if labelled:
        lab = spots
    else:
        idx = np.maximum(order, 0)[..., None].repeat(2, axis=-1)
        lab = np.take_along_axis(spots, idx, axis=2)
        lab[order < 0] = np.nan
    return lab.reshape(lab.shape[0], -1, 2)


def check_wand_length(nominal, points, wand: float) -> None:
    """Refuse a wand length the deployment's cameras contradict many times over (a length in
    millimetres, or another bar's): its ends triangulated with the planned cameras, whose
    scale a hand-hung install keeps to a few per cent, lie a median distance apart that the
    stated length must be within :data:`WAND_SCALE_RATIO` of (``points``: C×2M×2, a set's
    LEDs at 2m, 2m + 1)."""
    X = free_positions(nominal, points, None)
    d = np.linalg.norm(X[0::2] - X[1::2], axis=1)
    d = d[np.isfinite(d)]
    if len(d) < MIN_SHARED:
        return
    seen = float(np.median(d))
    if not 1 / WAND_SCALE_RATIO < wand / seen < WAND_SCALE_RATIO:
        raise SurveyError(f"the wand's two LEDs appear about {format_length(seen)} apart under "
                          f"the deployment's cameras (the median of {len(d)} sets), not "
                          f"{format_length(wand)}: is its length in metres, and the "
                          "deployment this site's?")


def wrong_lengths(adj, pair_i, keep, wand, wand_sigma) -> np.ndarray:
    """Per wand set (``pair_i``: its first LED's index), whether the fit puts its two LEDs
    further from the wand's length than its sets' own scatter allows (median absolute
    deviation, and the bar's precision, times :data:`REJECT_SIGMAS`)."""
    if wand is None or not len(pair_i):
        return np.zeros(len(pair_i), bool)
    active = (keep[:, pair_i].sum(axis=0) >= 2) & (keep[:, pair_i + 1].sum(axis=0) >= 2)
    res = np.abs(np.linalg.norm(adj[pair_i] - adj[pair_i + 1], axis=1) - wand)
    if not active.any():
        return np.zeros(len(pair_i), bool)
    scatter = 1.4826 * float(np.median(res[active]))
    return active & (res > REJECT_SIGMAS * max(scatter, wand_sigma))


def check_both_seen(spots) -> None:
    """Refuse a wand survey whose free sets rarely show both LEDs to two cameras (``spots``
    C×M×2×2): a survey of one LED, or one LED unlit."""
    both = int((np.isfinite(spots[..., 0]).all(axis=2).sum(axis=0) >= 2).sum())
    if both < MIN_WAND_SETS:
        raise SurveyError(
            f"{both} of the {spots.shape[1]} free sets show the wand's two LEDs to two "
            f"cameras (expected {MIN_WAND_SETS} at least): this looks like a survey of one "
            "LED — calibrate it without the wand's length, or check that both LEDs are lit "
            "and in view; nothing was written")


def check_wand_error(error: WandError, wand: float, held_out: int, s_px: float) -> None:
    """Refuse a wand whose held-out sets (``held_out`` of them) miss its length by more than
    :data:`WAND_MISFIT` of it on average: the second spot is not the wand's other LED. Said
    before the references are left out in turn, each a joint fit."""
    if error.mean <= WAND_MISFIT * wand:
        return
    said = (f"{error.sets} held-out sets put its ends {format_length(error.mean)} "
            f"from its {format_length(wand)} on average" if error.sets else
            "no held-out set shows its two ends meeting")
    raise SurveyError(f"the wand does not fit the cameras: {said} (of "
                      f"{held_out} held out, {error.discarded} whose "
                      f"spots do not meet; the spots fit to ±{s_px:.2g} px): the second "
                      "spot is not the wand's other LED "
                      "(a reflection, another light, a survey of one LED), or the LEDs' "
                      "names are swapped for a camera; nothing was written")
