"""Simulated installs: *true* cameras (what hangs on the ceiling) vs *nominal* cameras (what the
installer believes), and the frames the true cameras take of an LED anywhere in the room.

Everything is drawn from a seed: the same profile, seed and points give the same bytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import erf

from ..geometry import Camera, rodrigues, rotation_vector
from .render import _pixel_integrals, encode_jpeg

#: tags of the random streams, so that no two draw the same numbers (numpy drops a trailing
#: 0 of a seed sequence: every tag is non-zero)
STREAM_INSTALL, STREAM_FRAMES, STREAM_TAPE, STREAM_PATH = 101, 202, 303, 404


@dataclass(frozen=True)
class InstallErrors:
    """How far a real install is from the nominal one: 1-sigma per camera unless noted."""

    position: float = 0.0  #: m, horizontal mounting offset per axis
    height: float = 0.0  #: m, mounting height
    tilt: float = 0.0  #: rad, about each horizontal axis (levelling)
    yaw: float = 0.0  #: rad, about the vertical
    focal: float = 0.0  #: relative error of the true focal length against the nominal one
    aspect: float = 0.0  #: fy / fx − 1, the same for every camera (sensor window scaling)
    principal: float = 0.0  #: px, principal point offset per axis
    k1: tuple[float, float] = (0.0, 0.0)  #: radial distortion, (mean, sd)
    k2: tuple[float, float] = (0.0, 0.0)  #: (mean, sd)
    tangential: float = 0.0  #: sd of p1 and p2


@dataclass(frozen=True)
class Appearance:
    """How the LED and the room look in a frame (digital numbers, DN, of an 8-bit image)."""

    #: DN of a spot centred on a pixel, LED seen on the optical axis from ``reference_distance``
    led_peak: float = 220.0
    reference_distance: float = 2.3  #: m
    emission_order: float = 1.0  #: the LED faces up and radiates as cosᵐ (1 = Lambertian)
    psf_sigma: float = 0.8  #: px, point-spread function on the optical axis
    psf_growth: float = 0.0  #: relative PSF growth at the image corner (cheap lenses blur there)
    vignetting: float = 0.0  #: 0–1: share of the natural cos⁴ fall-off the lens shows
    background: float = 18.0  #: DN
    gradient: tuple[float, float] = (0.03, 0.02)  #: DN per px along u and v
    read_noise: float = 1.5  #: DN
    shot_gain: float = 0.05  #: DN² of shot-noise variance per DN of signal
    jpeg_quality: int = 80
    led_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: B, G, R gains of the LED
    background_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: B, G, R of the floor
    #: floor reflection: its peak as a share of the LED's (0: none) and its blur (× PSF sigma)
    reflection: float = 0.0
    reflection_blur: float = 2.5
    #: a fixed bright light in the room: (x, y, z m, peak DN, sigma px), or None
    lamp: tuple | None = None


@dataclass(frozen=True)
class Profile:
    """A named simulated deployment: nominal layout, install errors, appearance, survey noise."""

    name: str
    description: str
    nominal: tuple[Camera, ...]
    room: tuple
    ceiling_height: float
    errors: InstallErrors = InstallErrors()
    look: Appearance = Appearance()
    #: m, 1-sigma of a tape-measured survey position per axis
    tape: float = 0.003
    #: floor polygons nobody walks or drives over (a deployment's ``site.keep_out``): survey
    #: points, test points and the paths of a carried or driven LED stay out of them
    keep_out: tuple = ()
    #: where each value comes from (parameter → source), shown by ``vlpcal simulate --describe``
    sources: dict = field(default_factory=dict, compare=False, hash=False)


@dataclass(frozen=True)
class Scene:
    """One simulated install: what is really there and what the installer believes."""

    profile: Profile
    true: tuple[Camera, ...]
    nominal: tuple[Camera, ...]
    seed: int


def perturb(cam: Camera, e: InstallErrors, rng: np.random.Generator) -> Camera:
    """The camera as really installed: the nominal one with errors drawn from ``e``."""
    dx, dy = rng.normal(0.0, e.position, 2)
    dz = rng.normal(0.0, e.height)
    tx, ty = rng.normal(0.0, e.tilt, 2)
    yaw = rng.normal(0.0, e.yaw)
    # small rotations applied in the world frame, after the nominal orientation
    R = cam.R @ rodrigues((tx, ty, yaw)).T
    f = cam.fx * (1.0 + rng.normal(0.0, e.focal))
    pc = rng.normal(0.0, e.principal, 2)
    # the lens's distortion: the nominal coefficients plus the drawn ones
    drawn = (rng.normal(*e.k1), rng.normal(*e.k2), *rng.normal(0.0, e.tangential, 2), 0.0)
    dist = tuple(a + b for a, b in zip(cam.dist, drawn))
    return replace(cam, fx=f, fy=f * (1.0 + e.aspect) * cam.fy / cam.fx,
                   cx=cam.cx + pc[0], cy=cam.cy + pc[1], dist=dist,
                   position=(cam.position[0] + dx, cam.position[1] + dy, cam.position[2] + dz),
                   rotation=rotation_vector(R))


def make_scene(profile: Profile, seed: int = 0) -> Scene:
    """Draw a true install of ``profile`` (deterministic for ``seed``)."""
    rng = np.random.default_rng([seed, STREAM_INSTALL])
    true = tuple(perturb(c, profile.errors, rng) for c in profile.nominal)
    return Scene(profile, true, tuple(profile.nominal), seed)


# -- rendering -------------------------------------------------------------------------------------

def _vignette(cam: Camera, strength: float) -> np.ndarray:
    """H×W factor 1 − strength · (1 − cos⁴θ), θ each pixel's angle off the optical axis."""
    if strength == 0:
        return np.ones((cam.height, cam.width))
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    r2 = ((u - cam.cx) / cam.fx) ** 2 + ((v - cam.cy) / cam.fy) ** 2
    return 1.0 - strength * (1.0 - 1.0 / (1.0 + r2) ** 2)


def _spots(n, h, w, u, v, sigma, amp) -> np.ndarray:
    """``n×h×w`` pixel-integrated Gaussian spots (amplitude = a centred pixel's value)."""
    img = np.zeros((n, h, w))
    ok = np.isfinite(u) & np.isfinite(v) & (amp > 0)
    if ok.any():
        ix = _pixel_integrals(u[ok], w, sigma[ok])
        iy = _pixel_integrals(v[ok], h, sigma[ok])
        share = erf(0.5 / (math.sqrt(2.0) * sigma[ok])) ** 2
        img[ok] = (amp[ok] / share)[:, None, None] * iy[:, :, None] * ix[:, None, :]
    return img


def led_brightness(cam: Camera, points: np.ndarray, look: Appearance) -> np.ndarray:
    """Light the LED at each point sends into the camera, as the peak DN of an in-focus spot:
    inverse square of the distance, cosᵐ of the emission angle (the LED faces up), cos of the
    angle off the optical axis (the aperture seen obliquely) and the lens's vignetting."""
    d = cam.center - points
    dist = np.linalg.norm(d, axis=1)
    cos_emit = np.clip(d[:, 2] / dist, 0.0, 1.0)
    cos_cam = np.clip(-(d @ cam.axis) / dist, 0.0, 1.0)
    vig = 1.0 - look.vignetting * (1.0 - cos_cam ** 4)
    return look.led_peak * (look.reference_distance / dist) ** 2 \
        * cos_emit ** look.emission_order * cos_cam * vig


def _led_light(cam: Camera, points, look: Appearance, distractors: bool, carrier_radius,
               on) -> tuple[np.ndarray, np.ndarray]:
    """One LED per frame (``points`` N×3, lit where ``on``): the light it puts on each pixel
    (``N×H×W``, its floor mirror image included) and whether its centre is in the image."""
    n, h, w = len(points), cam.height, cam.width
    uv, front, inside = cam.project(points)
    uv = np.where(front[:, None], uv, np.nan)
    r2 = ((uv[:, 0] - cam.cx) / (w / 2)) ** 2 + ((uv[:, 1] - cam.cy) / (h / 2)) ** 2
    sigma = look.psf_sigma * (1.0 + look.psf_growth * np.clip(r2, 0, 2) / 2)
    # a blurred spot spreads the same light: its peak falls as 1/σ²
    amp = np.where(front & on, led_brightness(cam, points, look), 0.0) \
        * (look.psf_sigma / sigma) ** 2
    xc = cam.to_camera(points)
    with np.errstate(invalid="ignore", divide="ignore"):
        in_lens = (xc[:, 0] ** 2 + xc[:, 1] ** 2) / xc[:, 2] ** 2 < cam.max_radius2
    near = front & in_lens & (uv[:, 0] > -4 * sigma) & (uv[:, 0] < w - 1 + 4 * sigma) \
        & (uv[:, 1] > -4 * sigma) & (uv[:, 1] < h - 1 + 4 * sigma)
    amp = np.where(near, amp, 0.0)
    light = _spots(n, h, w, uv[:, 0], uv[:, 1], sigma, amp)
    if distractors and look.reflection > 0:
        # the LED's mirror image in the floor, dimmer and blurred by the floor's roughness
        mirror = points * [1.0, 1.0, -1.0]
        muv, mfront, _ = cam.project(mirror)
        mamp = np.where(mfront & ~_under_carrier(cam, points, carrier_radius),
                        amp * look.reflection, 0.0)
        light += _spots(n, h, w, muv[:, 0], muv[:, 1], sigma * look.reflection_blur, mamp)
    return light, inside


def render_camera(cam: Camera, points, look: Appearance, rngs, distractors: bool = True,
                  carrier_radius=0.0, on=None) -> tuple[np.ndarray, np.ndarray]:
    """Colour frames (``N×H×W×3`` uint8, BGR) of the LED at each point as ``cam`` sees it.

    Returns the frames and whether the LED's centre is in the image. The LED is a pixel-
    integrated Gaussian (so the sub-pixel position shows); an LED outside the view leaves its
    tail at the edge, as a real one does. ``carrier_radius`` (m, scalar or one per point): what
    carries the LED (a robot's body) covers the floor within this radius of the LED's foot, and
    with it the floor's mirror image of the LED wherever that falls there.

    Several LEDs in each frame: ``points`` ``N×K×3`` (and ``carrier_radius`` one per LED or
    scalar), ``on`` ``N×K`` whether each is lit (a blink code's bit; default all); the second
    value is then ``N×K``.
    """
    pts = np.asarray(points, float)
    several = pts.ndim == 3
    pts = pts if several else np.atleast_2d(pts)[:, None]
    n, n_led = pts.shape[:2]
    h, w = cam.height, cam.width
    lit = np.ones((n, n_led), bool) if on is None else np.asarray(on, bool).reshape(n, n_led)
    radius = np.asarray(carrier_radius, float)
    radius = np.broadcast_to(radius if several or radius.ndim == 0 else radius[:, None],
                             (n, n_led))
    led = np.zeros((n, h, w))
    inside = np.zeros((n, n_led), bool)
    for k in range(n_led):
        light, inside[:, k] = _led_light(cam, pts[:, k], look, distractors, radius[:, k],
                                         lit[:, k])
        led += light
    extra = np.zeros((n, h, w))
    if distractors and look.lamp is not None:
        x, y, z, peak, lsig = look.lamp
        luv, lfront, _ = cam.project([[x, y, z]])
        if lfront[0]:
            extra += _spots(n, h, w, np.full(n, luv[0, 0]), np.full(n, luv[0, 1]),
                            np.full(n, float(lsig)), np.full(n, float(peak)))
    v, u = np.mgrid[0:h, 0:w]
    base = (look.background + look.gradient[0] * (u - w / 2) + look.gradient[1] * (v - h / 2)) \
        * _vignette(cam, look.vignetting)
    frames = np.empty((n, h, w, 3), np.uint8)
    # each frame's noise from its own stream: a frame does not depend on its neighbours
    normal = np.stack([g.standard_normal((h, w, 3)) for g in rngs])
    for c in range(3):
        signal = base[None] * look.background_colour[c] + (led + extra) * look.led_colour[c]
        noise_sd = np.sqrt(look.read_noise ** 2 + look.shot_gain * np.maximum(signal, 0.0))
        signal = signal + normal[..., c] * noise_sd
        frames[..., c] = np.clip(np.rint(signal), 0, 255)
    return frames, (inside if several else inside[:, 0])


#: pixels rendered at once (a chunk of frames): bounds the float arrays a chunk needs to
#: ~16 MB each, whatever the image size
CHUNK_PIXELS = 2 ** 21
#: a robot's body around its LED (m): a small AGV, 40 cm across; it hides the floor under the LED
ROBOT_RADIUS = 0.2


def _under_carrier(cam: Camera, points, radius) -> np.ndarray:
    """Whether the floor point that mirrors each LED into ``cam`` lies within ``radius`` of the
    LED's foot: on the line from the camera to the mirror image, a share h / (H + h) of the
    way from the LED's foot towards the camera's (h the LED's height, H the camera's)."""
    h = np.maximum(points[:, 2], 0.0)
    c = np.asarray(cam.center, float)
    reach = np.linalg.norm(c[:2] - points[:, :2], axis=1) * h / np.maximum(c[2] + h, 1e-300)
    return reach < np.broadcast_to(np.asarray(radius, float), h.shape)


def render_scene(scene: Scene, points, seed: int = 0, distractors: bool = True,
                 chunk: int | None = None, carrier_radius=0.0, on=None,
                 only_seen: bool = False) -> tuple[dict, np.ndarray]:
    """JPEG frames of an LED at each world point ``N×3`` from every true camera
    (``carrier_radius``: :func:`render_camera`'s, scalar or one per point).

    Returns ``(frames, seen)``: camera id → one JPEG per point, and ``C×N`` whether the LED's
    centre was inside each camera's image. Deterministic for (scene, points, seed); frame i
    depends only on point i, its index and the seed.

    Several LEDs in each frame (a wand's two): ``points`` ``N×K×3``, ``on`` ``N×K`` whether
    each is lit (default all); ``seen`` is then ``C×N×K`` (lit and inside). ``only_seen``: a
    frame no LED is seen in is not rendered (None in its place) — a survey keeps only the
    frames that show the LED, and with many cameras most frames show nothing, so skipping them
    makes the cost follow the sightings, not cameras × points; the frames rendered are the
    same bytes either way.
    """
    pts = np.asarray(points, float)
    several = pts.ndim == 3
    pts = pts if several else np.atleast_2d(pts)[:, None]
    n, n_led = pts.shape[:2]
    lit = np.ones((n, n_led), bool) if on is None else np.asarray(on, bool).reshape(n, n_led)
    radius = np.broadcast_to(np.asarray(carrier_radius, float), n)
    look = scene.profile.look
    frames, seen = {}, []
    for k, cam in enumerate(scene.true):
        inside = cam.project(pts.reshape(-1, 3))[2].reshape(n, n_led) & lit
        todo = np.flatnonzero(inside.any(axis=1)) if only_seen else np.arange(n)
        jpegs: list = [None] * n
        step = chunk or max(1, CHUNK_PIXELS // (cam.width * cam.height))
        for s in range(0, len(todo), step):
            idx = todo[s:s + step]
            rngs = [np.random.default_rng([scene.seed, seed, STREAM_FRAMES, k + 1, i + 1])
                    for i in idx]
            # one LED keeps the N×3 call, so that its frames are the bytes they always were
            imgs, _ = render_camera(cam, pts[idx] if several else pts[idx, 0], look, rngs,
                                    distractors, radius[idx, None] if several else radius[idx],
                                    lit[idx] if several else (None if on is None
                                                              else lit[idx, 0]))
            for i, img in zip(idx, imgs):
                jpegs[i] = encode_jpeg(img, look.jpeg_quality)
        frames[cam.id] = jpegs
        seen.append(inside if several else inside[:, 0])
    return frames, np.array(seen)


def in_frame(scene: Scene, origin, yaw: float) -> Scene:
    """The same install described in another floor frame: ``origin`` (x, y, m) becomes
    (0, 0) and the direction ``yaw`` (rad from +x) the new +x — the frame a wand survey's
    marks define. Cameras (true and nominal), room, keep-outs and the lamp move with it."""
    c, s = math.cos(yaw), math.sin(yaw)
    Rz = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world → frame
    o = np.array([origin[0], origin[1], 0.0])

    def point(p):
        return Rz @ (np.asarray(p, float) - o)

    def camera(cam: Camera) -> Camera:
        return replace(cam, position=tuple(point(cam.position)),
                       rotation=tuple(rotation_vector(cam.R @ Rz.T)))

    def polygon(poly):
        return tuple(tuple(point([x, y, 0.0])[:2]) for x, y in poly)

    prof = scene.profile
    look = prof.look
    if look.lamp is not None:
        look = replace(look, lamp=(*point(look.lamp[:3]), *look.lamp[3:]))
    prof = replace(prof, nominal=tuple(camera(c) for c in prof.nominal),
                   room=polygon(prof.room), look=look,
                   keep_out=tuple(polygon(p) for p in prof.keep_out))
    return replace(scene, profile=prof, true=tuple(camera(c) for c in scene.true),
                   nominal=tuple(camera(c) for c in scene.nominal))
