"""Frames in: JPEG bytes, image arrays or None → 8-bit grayscale images, a stack of them, and a
reason code for each frame that cannot be measured.

A frame is judged before it is decoded where it can be: its markers (a truncated JPEG decodes
to grey with only a warning) and the size its header declares (a small file may declare a huge
image). OpenCV (``cv2``) is imported on first use, through :data:`_cv2`, which every module of
the package shares: importing the package stays light for commands that never decode.
"""

from __future__ import annotations

import os
import threading
from collections import Counter

import numpy as np

from .results import _REASON_CODE, Reason


class _LazyCv2:
    """``cv2``, imported on first use: ``import vlpcal.detection`` stays light for the commands
    that never decode a frame. Each name is kept on first use, so later uses cost an attribute
    lookup (every module of the package shares this one object)."""

    def __getattr__(self, name):
        import cv2

        value = getattr(cv2, name)
        setattr(self, name, value)
        return value


_cv2 = _LazyCv2()


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
    with _QuietStderr():
        img, _ = _decode_jpeg(buf, tuple(shape) if shape is not None else None)
    return img


def _decode_jpeg(buf: bytes, want):
    """A JPEG's bytes (its start and end markers already checked) → ``(8-bit grayscale image or
    None, reason code)``: ``wrong_size`` when the size its header declares is not ``want``
    (H, W) — more than :data:`MAX_PIXELS` without it —, ``corrupt_frame`` without a frame
    header, both before anything is decoded (a small file may declare a huge image); None and
    0 when OpenCV cannot decode it. The caller quiets libjpeg (:class:`_QuietStderr`)."""
    size = jpeg_size(buf)
    if size is None:
        return None, _REASON_CODE[Reason.CORRUPT_FRAME]
    if size != want if want is not None else size[0] * size[1] > MAX_PIXELS:
        return None, _REASON_CODE[Reason.WRONG_SIZE]
    try:
        return _cv2.imdecode(np.frombuffer(buf, np.uint8), _cv2.IMREAD_GRAYSCALE), 0
    except _cv2.error:
        return None, 0


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
        img = _cv2.cvtColor(img[..., :3].astype(np.float32), _cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or min(img.shape) < MIN_SIZE:
        return None
    if img.dtype.kind == "f" and not np.isfinite(img).all():
        return None
    return img


def _to_stack(frames, shape=None):
    """``(stack, codes)``: the frames that can be measured as one ``N×H×W`` array, and a reason
    code per frame (0 for the measurable ones). ``shape`` (H, W) is the size expected; without
    it, the first measurable frame's size is."""
    if isinstance(frames, np.ndarray) and frames.ndim == 3:
        codes = np.zeros(len(frames), np.int8)
        if shape is not None and frames.shape[1:] != tuple(shape):
            codes[:] = _REASON_CODE[Reason.WRONG_SIZE]
        elif min(frames.shape[1:], default=0) < MIN_SIZE:
            codes[:] = _REASON_CODE[Reason.CORRUPT_FRAME]
        elif frames.dtype.kind == "f":
            codes[~np.isfinite(frames).all(axis=(1, 2))] = _REASON_CODE[Reason.CORRUPT_FRAME]
        good = codes == 0
        return (frames if good.all() else frames[good]), codes
    n = len(frames)
    codes = np.zeros(n, np.int8)
    want = tuple(shape) if shape is not None else None
    if want is not None and min(want) < MIN_SIZE:  # no spot can be measured in so small an image
        codes[:] = [_REASON_CODE[Reason.MISSING if f is None else Reason.CORRUPT_FRAME]
                    for f in frames]
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
            codes[i] = _REASON_CODE[Reason.MISSING]
            continue
        if type(f) is bytes and f[:2] == b"\xff\xd8" and f[-2:] == b"\xff\xd9":
            # a whole JPEG: decode_gray's steps but the marker checks, with the reason kept
            im, code = _decode_jpeg(f, want)
            if code:
                codes[i] = code
                continue
        else:
            im = decode_gray(f) if isinstance(f, (bytes, bytearray, memoryview)) else as_gray(f)
        if stack is not None and im is not None and im.shape == want \
                and im.dtype == stack.dtype:
            stack[i] = im  # the common case: a decoded JPEG of the camera's size
            continue
        if im is None or im.ndim != 2 or min(im.shape) < MIN_SIZE or (
                im.dtype.kind == "f" and not np.isfinite(im).all()):
            codes[i] = _REASON_CODE[Reason.CORRUPT_FRAME]
            continue
        want = want or im.shape
        if im.shape != want:
            codes[i] = _REASON_CODE[Reason.WRONG_SIZE]
        elif stack is not None:  # another dtype (a float frame): widen the stack once
            stack = stack.astype(np.result_type(stack.dtype, im.dtype))
            stack[i] = im
        else:
            images[i] = im
    return stack

def _decode_whole(frame, want):
    """The common live frame — JPEG bytes, whole (SOI to EOI), declaring the camera's size —
    decoded to grayscale; None for anything else (which the batch's checks then judge)."""
    if type(frame) is not bytes or want is None:
        return None
    img = decode_gray(frame, want)
    return img if img is not None and img.shape == want else None


def _decode_frame(frame, want):
    """One live frame decoded and checked as a batch's frames are (the same reasons for the
    same frames): ``(image or None, own, reason code)``; ``own``: the image was decoded here,
    so its caller may change it for a moment and restore it."""
    if want is not None and min(want) < MIN_SIZE:  # no spot can be measured in so small an image
        return None, False, _REASON_CODE[Reason.CORRUPT_FRAME]
    img = _decode_whole(frame, want)
    if img is not None:
        return img, True, 0
    # anything but a whole JPEG of the camera's size: the batch's checks
    codes, images = np.zeros(1, np.int8), {}
    with _QuietStderr():
        stack = _decode_into([frame], codes, want,
                             np.empty((1, *want), np.uint8) if want else None, images)
    if codes[0]:
        return None, False, int(codes[0])
    own = stack is not None
    return (stack[0] if own else images[0]), own, 0
