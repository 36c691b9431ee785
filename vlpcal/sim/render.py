"""Synthetic camera frames: the project's own test bench.

A first renderer (the full simulator with error profiles is a later step): an LED spot as a
Gaussian point-spread function *integrated over each pixel* (so the sub-pixel position shows in
the pixel values), on a background with a gradient, with read and shot noise, saturation at 255,
8-bit quantisation and JPEG compression. Distractor spots (a floor reflection, a lamp) use the
same model. Deterministic for a seed. Vectorised over frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import erf, sqrt

import numpy as np
from scipy.special import erf as _erf

from ..geometry import Camera


@dataclass(frozen=True)
class SpotLook:
    """How a spot looks: PSF sigma (px) and peak height above background (DN)."""

    sigma: float = 0.9
    amplitude: float = 180.0


@dataclass(frozen=True)
class Sensor:
    """Frame-level appearance: background, its gradient (DN per px), noise, JPEG quality."""

    background: float = 18.0
    gradient: tuple[float, float] = (0.04, 0.02)
    read_noise: float = 1.5
    shot_gain: float = 0.05  # variance of shot noise per DN of signal
    jpeg_quality: int | None = 80


def _pixel_integrals(centre: np.ndarray, n: int, sigma: np.ndarray) -> np.ndarray:
    """``N×n`` share of a 1D Gaussian falling in each pixel [i − ½, i + ½]."""
    edges = np.arange(n + 1) - 0.5
    cdf = 0.5 * _erf((edges[None, :] - centre[:, None]) / (sqrt(2.0) * sigma[:, None]))
    return np.diff(cdf, axis=1)


def add_spots(img: np.ndarray, u, v, look: SpotLook | np.ndarray = SpotLook()) -> None:
    """Add one pixel-integrated Gaussian spot per frame of ``img`` (``N×H×W`` float), in place.

    ``amplitude`` is the value of a pixel whose centre is on the spot's centre. NaN positions
    add nothing (the LED is outside that frame).
    """
    n, h, w = img.shape
    u = np.broadcast_to(np.asarray(u, float), (n,))
    v = np.broadcast_to(np.asarray(v, float), (n,))
    if isinstance(look, SpotLook):
        sigma = np.full(n, look.sigma)
        amp = np.full(n, look.amplitude)
    else:
        look = np.broadcast_to(np.asarray(look, float), (n, 2))
        sigma, amp = look[:, 0], look[:, 1]
    seen = np.isfinite(u) & np.isfinite(v)
    if not seen.any():
        return
    ix = _pixel_integrals(u[seen], w, sigma[seen])
    iy = _pixel_integrals(v[seen], h, sigma[seen])
    centre_share = np.array([erf(0.5 / (sqrt(2.0) * s)) for s in sigma[seen]]) ** 2
    img[seen] += (amp[seen] / centre_share)[:, None, None] * iy[:, :, None] * ix[:, None, :]


def render(u, v, *, width: int = 160, height: int = 120, look: SpotLook = SpotLook(),
           sensor: Sensor = Sensor(), distractors=(), seed: int = 0) -> np.ndarray:
    """Render ``N`` 8-bit frames (``N×H×W``) of a spot at pixels ``(u, v)``.

    ``distractors``: ``(du, dv, SpotLook)`` spots placed relative to the LED (a reflection
    beside it, a lamp). Returns the raw 8-bit frames; :func:`encode_jpeg` makes the JPEG.
    """
    rng = np.random.default_rng(seed)
    u = np.atleast_1d(np.asarray(u, float))
    v = np.atleast_1d(np.asarray(v, float))
    n = len(u)
    rows, cols = np.mgrid[0:height, 0:width]
    base = sensor.background + sensor.gradient[0] * (cols - width / 2) \
        + sensor.gradient[1] * (rows - height / 2)
    img = np.repeat(base[None].astype(float), n, axis=0)
    add_spots(img, u, v, look)
    for du, dv, dlook in distractors:
        add_spots(img, u + du, v + dv, dlook)
    signal = np.maximum(img - sensor.background, 0.0)
    noise_sd = np.sqrt(sensor.read_noise ** 2 + sensor.shot_gain * signal)
    img += rng.standard_normal(img.shape) * noise_sd
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def encode_jpeg(frame: np.ndarray, quality: int = 80) -> bytes:
    """One 8-bit frame → JPEG bytes (grayscale frames stay single-channel)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()


def render_views(cameras: list[Camera], points, *, look: SpotLook = SpotLook(),
                 sensor: Sensor = Sensor(), seed: int = 0) -> dict[str, list[bytes | None]]:
    """JPEG frames of an LED at each world point ``N×3`` as every camera sees it.

    Returns camera id → one JPEG per point; the frame is empty background where the LED is
    outside that camera's view (the detector then reports ``no_spot``).
    """
    points = np.atleast_2d(np.asarray(points, float))
    out = {}
    for k, cam in enumerate(cameras):
        uv, _, inside = cam.project(points)
        uv = np.where(inside[:, None], uv, np.nan)
        frames = render(uv[:, 0], uv[:, 1], width=cam.width, height=cam.height, look=look,
                        sensor=sensor, seed=seed * 1009 + k)
        q = sensor.jpeg_quality
        out[cam.id] = [encode_jpeg(f, q) if q else f for f in frames]
    return out
