"""The public entries: frames in, spots out — :func:`detect_spots` for a batch (with its forms
:func:`detect_spot` and :func:`detect_several`), :func:`detect_frame` for a live frame. Their
shared contract is in the package's docstring (:mod:`vlpcal.detection`)."""

from __future__ import annotations

import numpy as np

from .blob import _detect_blob, _detect_frame_blob, _detect_several_blob
from .decoding import _CHUNK, _decode_frame, _to_stack, as_gray
from .peaks import _detect_centroid, _detect_peak
from .results import (
    _CODE_REASON,
    _REASON_CODE,
    DEFAULTS,
    DetectorSettings,
    Reason,
    Spot,
    SpotBatch,
)

#: the detectors by name (the package's docstring says what each does)
DETECTORS = ("highest", "mean2", "nip", "nip_eq5", "gauss", "centroid", "blob")
#: the one that copes with saturation, reflections and lamps (:mod:`.blob`)
DEFAULT_DETECTOR = "blob"


def _check(method: str) -> None:
    if method not in DETECTORS:
        raise ValueError(f"unknown detector {method!r}; expected one of {', '.join(DETECTORS)}")


def detect_spots(frames, method: str = DEFAULT_DETECTOR,
                 settings: DetectorSettings = DEFAULTS, shape=None) -> SpotBatch:
    """The batch entry: the spot in every frame, ``N`` frames → :class:`SpotBatch` of ``N``.

    ``frames``: an ``N×H×W`` array, or a sequence of ``N`` JPEG bytes / ``H×W`` or ``H×W×3``
    image arrays / None. A frame that does not decode, is too small or holds a NaN gets
    ``corrupt_frame``; one whose size is not ``shape`` (H, W; default: the first good frame's)
    ``wrong_size``; None ``missing``. (A colour image counts as one frame only inside a
    sequence.)
    """
    _check(method)
    if not isinstance(frames, np.ndarray) and len(frames) > _CHUNK:
        if shape is None:  # every chunk measures against the same size: the first good frame's
            first = next((im for im in (as_gray(f) for f in frames if f is not None)
                          if im is not None and im.ndim == 2), None)
            shape = None if first is None else first.shape
        # decoded and measured a chunk at a time, which stays in the CPU's cache
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
    """The batch with several LEDs in view: up to ``k`` spots in every frame, most LED-like
    first, ``N`` frames → ``N×k×2`` px, NaN rows where a frame holds fewer. ``blob`` ranks each
    frame's blobs by height and compactness and measures each as it measures one; the other
    detectors find one spot. Frames as :func:`detect_spots` takes them. With ``reasons``,
    ``(spots, N reasons)``: None, or why a frame could not be measured (``corrupt_frame``,
    ``wrong_size``, ``missing``; a frame without a spot has None and NaN rows)."""
    if reasons:
        codes = np.zeros(len(frames), np.int8)
        uv = _detect_several(frames, k, method, settings, shape, codes)
        return uv, [_CODE_REASON[int(c)] if c in _UNMEASURED else None for c in codes]
    return _detect_several(frames, k, method, settings, shape, None)


def _detect_several(frames, k, method, settings, shape, codes_out) -> np.ndarray:
    """:func:`detect_several`, each frame's reason code written into ``codes_out``."""
    _check(method)
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
    out[codes == 0] = _detect_several_blob(stack, k, settings)
    return out


def detect_spot(frame, method: str = DEFAULT_DETECTOR,
                settings: DetectorSettings = DEFAULTS) -> Spot:
    """The batch of one: one frame (JPEG bytes or an ``H×W`` / ``H×W×3`` image array) → its
    :class:`Spot`."""
    _check(method)
    img = as_gray(frame)
    if img is None:
        return Spot(np.nan, np.nan, 0.0, 0, False, Reason.CORRUPT_FRAME, 0)
    return detect_spots(img[None], method, settings)[0]


def detect_frame(frame, k: int = 1, method: str = DEFAULT_DETECTOR,
                 settings: DetectorSettings = DEFAULTS, shape=None, every_reason: bool = False):
    """The live entry: up to ``k`` spots of one frame (JPEG bytes or an image array), most
    LED-like first, one frame → ``(k×2 px with NaN rows, reason)``, as :func:`detect_several`
    gives for ``[frame]``: ``reason`` None unless the frame could not be measured
    (``corrupt_frame``, ``wrong_size``, ``missing``). ``every_reason``: the reason
    :func:`detect_spots` gives the frame's best spot instead (``no_spot``, ``too_dim`` and
    ``at_edge`` too), as the locator reports each camera.

    A live path takes frames one at a time, where the numpy calls on a stack of one cost what
    they cost on a stack of hundreds: ``blob`` is measured here on the frame itself, by the
    batch's steps in their one-frame form (:mod:`.blob`; the same results, tested); the other
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
    img, own, code = _decode_frame(frame, tuple(shape) if shape is not None else None)
    if img is None:
        return np.full((k, 2), np.nan), _CODE_REASON[code]
    if img.dtype != np.uint8 or not img.flags.c_contiguous:  # a float frame: the batch
        if k == 1:
            spot = detect_spots(img[None], "blob", settings)[0]
            uv, code = np.array([[spot.u, spot.v]]), _REASON_CODE[spot.reason]
        else:
            uv = detect_several(img[None], k, "blob", settings)[0]
            code = int(detect_spots(img[None], "blob", settings).reason_code[0])
    else:
        uv, code = _detect_frame_blob(img, k, settings, own)
    if not every_reason and code not in _UNMEASURED:
        code = 0
    return uv, _CODE_REASON[code]


#: the reasons :func:`detect_frame` gives without ``every_reason``: no frame to measure
_UNMEASURED = tuple(_REASON_CODE[r] for r in (Reason.CORRUPT_FRAME, Reason.WRONG_SIZE,
                                               Reason.MISSING))

