"""Tracking a moving LED with cameras that are not synchronised (issue 16).

Cheap cameras each send frames on their own clock: two views of a moving LED are never of the
same moment, and triangulating them as if they were costs the LED's motion between them (7.5 cm
at 1.5 m/s and 50 ms). Here no two views need to be simultaneous. Each camera frame's spot is a
ray at that frame's own capture time; the LED's path over a short window of time is a
quadratic — position, velocity, acceleration at the window's middle — fitted by least squares
to every ray in the window, in pixels (the linear form of N-view triangulation, each ray's rows
weighted by its pixels per metre). A frame's row is the fit of the window centred on its
capture time, so it is written half a window after the frame arrives (:data:`WINDOW` frame
periods in all).

- a spot farther from the track's extrapolated position than :data:`GATE_SIGMAS` of its
  expected scatter is not the LED — a reflection, a lamp — and is not used;
- a track starts from two cameras whose spots arrive within :data:`START_WINDOW` frame periods
  and whose rays meet within the motion possible between them;
- a window where one camera alone saw the LED leans on the track's own motion (its last fit,
  carried forward, within the acceleration it allows): a track survives it, and ends after
  :data:`LOST_PERIODS` frame periods without a spot.

``Tracker.update(camera_id, t, frame)`` is the interface; frames arrive in time order, and
``finish()`` writes the rows still waiting for the end of their window.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .deployment import Deployment
from .detection import detect_spots

#: the fit's window, in frame periods of the slowest camera (centred on each row's time)
WINDOW = 4.0
#: a spot farther than this many sigmas from the track's extrapolated position is not the LED
GATE_SIGMAS = 5.0
#: two cameras' first spots start a track when they are this many frame periods apart or less
START_WINDOW = 2.0
#: a track that accepts no spot for this many frame periods is lost …
LOST_PERIODS = 15.0
#: … and so is one that only one camera has seen for this many (its depth is then a guess)
COAST_PERIODS = 8.0
#: m/s²: the LED's acceleration, 1 sigma (a robot turning, a cart; a hand waves harder)
ACCELERATION = 5.0
#: m/s: the fastest the LED is expected to go (how far it may move between two first spots)
TOP_SPEED = 4.0
#: px: a moving LED's spot noise (blur, the detector), 1 sigma
PIXEL_SIGMA = 0.15

#: a row whose predicted error passes this share of the room's size is ``degenerate``
DEGENERATE_SHARE = 0.1

TRACK_COLUMNS = ("t", "led", "x", "y", "z", "vx", "vy", "vz", "sigma_m", "cameras", "status")


@dataclass
class TrackUpdate:
    """One row of one track: the fitted state at time ``t`` (s, a frame's capture time)."""

    t: float
    led: str
    position: np.ndarray  #: m
    velocity: np.ndarray  #: m/s
    sigma_m: float  #: predicted RMS position error of the fit (at the spot noise)
    cameras: str  #: the cameras whose rays the window held, e.g. "C1+C2+C4"
    status: str  #: ok; one_camera (one camera's rays: the motion carried it); degenerate

    def row(self) -> list:
        return [f"{self.t:.6f}", self.led, *(f"{v:.6f}" for v in self.position),
                *(f"{v:.6f}" for v in self.velocity), f"{self.sigma_m:.6f}", self.cameras,
                self.status]


@dataclass
class _Ray:
    t: float
    camera: int
    xy: np.ndarray  #: undistorted normalised image coordinates


@dataclass
class _Track:
    led: str
    rays: list  #: accepted rays, in time order (older than a window: dropped)
    fit_t: float  #: the time of the last fit
    fit: np.ndarray  #: 9: position, velocity, acceleration at ``fit_t``
    due: list = field(default_factory=list)  #: capture times whose rows are not yet written
    last_ray: float = 0.0
    s_pos: float = 0.0  #: m, 1 sigma per axis, of the fit's position
    s_vel: float = 0.0  #: m/s, of its velocity
    last_two: float = 0.0  #: the last time two cameras' rays placed it


class Tracker:
    """Tracks of an LED from camera frames that arrive one at a time, each at its own time.

    ``period``: the cameras' frame period, s (the slowest camera's); it sets the window, the
    start window and when a track is lost. The deployment's detector and pixel corrections
    apply as in :class:`~vlpcal.locator.Locator`."""

    def __init__(self, deployment: Deployment, period: float = 1 / 30,
                 acceleration: float = ACCELERATION, pixel_sigma: float = PIXEL_SIGMA):
        self.deployment = deployment
        self.period, self.acceleration, self.pixel_sigma = period, acceleration, pixel_sigma
        self.cameras = list(deployment.cameras)
        self._index = {c.id: k for k, c in enumerate(self.cameras)}
        offsets = deployment.pixel_offsets
        self._offset = np.array([offsets.get(c.id, (0.0, 0.0)) for c in self.cameras], float)
        self._size = deployment.size  #: m: a row as uncertain as this is no position
        self._R = np.stack([c.R for c in self.cameras])
        self._C = np.stack([c.center for c in self.cameras])
        self._f = np.array([0.5 * (c.fx + c.fy) for c in self.cameras])
        self.tracks: list[_Track] = []
        self._pending: list[_Ray] = []
        self._next = 1

    # -- the interface ---------------------------------------------------------------------
    def update(self, camera_id: str, t: float, frame) -> list[TrackUpdate]:
        """A camera's frame (JPEG bytes or an image array) captured at ``t`` s: its spot is
        found and the tracks updated; returns the rows now complete."""
        cam = self.cameras[self._index[camera_id]]
        spot = detect_spots([frame], self.deployment.detector, self.deployment.detector_settings,
                            shape=(cam.height, cam.width))
        uv = np.array([spot.u[0], spot.v[0]], float)
        return self.update_spot(camera_id, t, uv if np.isfinite(uv).all() else None)

    def update_spot(self, camera_id: str, t: float, uv) -> list[TrackUpdate]:
        """As :meth:`update`, from a spot already found (px; None: the camera saw no LED)."""
        k = self._index[camera_id]
        out = self._due(t)
        self._drop_lost(t, out)
        if uv is None:
            return out
        uv = np.asarray(uv, float) - self._offset[k]
        ray = _Ray(t, k, self.cameras[k].normalise(uv[None])[0])
        track = self._claim(ray, uv)
        if track is not None:
            track.rays.append(ray)
            track.due.append(t)
            track.last_ray = t
            self._refresh(track, t)
        else:
            self._start(ray)
        return out

    def finish(self) -> list[TrackUpdate]:
        """The rows still waiting for the rest of their window (the stream ended)."""
        out = []
        for tr in self.tracks:
            out += [self._row(tr, t) for t in tr.due]
            tr.due = []
        return sorted(out, key=lambda u: u.t)

    # -- inside ----------------------------------------------------------------------------
    @property
    def half(self) -> float:
        return 0.5 * WINDOW * self.period

    def _due(self, now: float) -> list[TrackUpdate]:
        """Rows whose window has passed by ``now``."""
        out = []
        for tr in self.tracks:
            ready = [t for t in tr.due if t <= now - self.half]
            tr.due = [t for t in tr.due if t > now - self.half]
            out += [self._row(tr, t) for t in ready]
            tr.rays = [r for r in tr.rays if r.t >= now - 4 * self.half]
        return sorted(out, key=lambda u: u.t)

    def _drop_lost(self, now: float, out: list) -> None:
        keep = []
        for tr in self.tracks:
            if now - tr.last_ray > LOST_PERIODS * self.period or \
                    now - tr.last_two > COAST_PERIODS * self.period:
                out += [self._row(tr, t) for t in tr.due]
            else:
                keep.append(tr)
        self.tracks = keep

    def _extrapolated(self, tr: _Track, t: float):
        """The track's latest fit carried to ``t`` at its velocity, with the sigmas of position
        and velocity that the motion it cannot foresee (:data:`ACCELERATION`) leaves there."""
        dt = t - tr.fit_t  # at constant velocity: a short window's acceleration is noisy
        pos = tr.fit[:3] + tr.fit[3:6] * dt
        vel = tr.fit[3:6].copy()
        s_pos = np.sqrt(tr.s_pos ** 2 + (tr.s_vel * dt) ** 2
                        + (0.5 * self.acceleration * dt * dt) ** 2)
        s_vel = np.sqrt(tr.s_vel ** 2 + (self.acceleration * abs(dt)) ** 2)
        return pos, vel, s_pos, s_vel

    def _refresh(self, tr: _Track, t: float) -> None:
        """The track's state now, from its rays of the last window and its state before:
        what the next spot is judged against."""
        rays = [r for r in tr.rays if r.t >= t - WINDOW * self.period]
        if len({r.camera for r in rays}) < 2:
            return  # one camera cannot place it: the state from two carries on (coasting)
        # the state before anchors a window whose rays barely cross (loosened threefold: it
        # holds these rays already, and counted twice they would make the track overconfident)
        pos, vel, s_pos, s_vel = self._extrapolated(tr, t)
        fit, _, cov = self._solve(rays, t, (pos, vel, 3 * s_pos, 3 * s_vel))
        if fit is not None:
            tr.last_two = t
            tr.fit, tr.fit_t = fit, t
            tr.s_pos = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0) / 3))
            tr.s_vel = float(np.sqrt(max(np.trace(cov[3:6, 3:6]), 0.0) / 3))

    def _claim(self, ray: _Ray, uv) -> _Track | None:
        """The track whose extrapolated position this spot fits (None: none does)."""
        best, best_d = None, np.inf
        cam = self.cameras[ray.camera]
        for tr in self.tracks:
            X, _, s_pos, _ = self._extrapolated(tr, ray.t)
            pred, front, _ = cam.project(X[None])
            if not front[0]:
                continue
            depth = float(cam.to_camera(X[None])[0, 2])
            # what the spot may scatter: its noise, and where the track may be by now
            slack = np.hypot(self.pixel_sigma, s_pos * self._f[ray.camera] / depth)
            d = float(np.linalg.norm(uv - pred[0])) / slack
            if d < GATE_SIGMAS and d < best_d:
                best, best_d = tr, d
        return best

    def _start(self, ray: _Ray) -> None:
        """A spot no track claims: start a track with a recent spot of another camera whose
        ray meets this one's, else keep it for the next camera."""
        window = START_WINDOW * self.period
        self._pending = [p for p in self._pending
                         if ray.t - p.t <= window and p.camera != ray.camera]
        for p in reversed(self._pending):
            fit, resid, _ = self._solve([p, ray], ray.t, order=0)
            if fit is None:
                continue
            X = fit[:3]
            depth = [float(self.cameras[r.camera].to_camera(X[None])[0, 2]) for r in (p, ray)]
            if min(depth) <= 0:
                continue
            allowed = 3 * self.pixel_sigma + TOP_SPEED * (ray.t - p.t) * max(
                self._f[r.camera] / d for r, d in zip((p, ray), depth))
            if resid > allowed:
                continue
            self._pending.remove(p)
            s_pos = TOP_SPEED * (ray.t - p.t) + self._metres_per_px(X, [ray.camera])
            tr = _Track(f"T{self._next}", [p, ray], ray.t, np.r_[X, np.zeros(6)],
                        [p.t, ray.t], ray.t, last_two=ray.t, s_pos=s_pos, s_vel=TOP_SPEED)
            self._next += 1
            self.tracks.append(tr)
            return
        self._pending.append(ray)

    def _row(self, tr: _Track, t: float) -> TrackUpdate:
        rays = [r for r in tr.rays if abs(r.t - t) <= self.half]
        cams = sorted({r.camera for r in rays})
        fit, _, cov = self._solve(rays, t) if len(cams) >= 2 else (None, None, None)
        if fit is None:  # one camera: the track's motion places the LED along that ray
            pos, vel, s_pos, _ = self._extrapolated(tr, t)
            if rays:
                near = min(rays, key=lambda r: abs(r.t - t))
                cam = self.cameras[near.camera]
                d = np.r_[near.xy, 1.0] @ cam.R  # the ray's direction in the world
                d = d / np.linalg.norm(d)
                pos = cam.center + d * float((pos - cam.center) @ d)
            fit, cov = np.r_[pos, vel, np.zeros(3)], np.eye(9) * s_pos ** 2
        sigma = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)))
        status = "ok" if len(cams) >= 2 else "one_camera"
        if not sigma < DEGENERATE_SHARE * self._size:  # no position worth the name
            status = "degenerate"
        return TrackUpdate(t, tr.led, fit[:3].copy(), fit[3:6].copy(), sigma,
                           "+".join(self.cameras[k].id for k in cams), status)

    def _metres_per_px(self, X, cams) -> float:
        if not cams:
            return 1.0
        k = cams[0]
        return float(self.cameras[k].to_camera(X[None])[0, 2]) / self._f[k] * self.pixel_sigma

    def _solve(self, rays, t0: float, prior=None, order: int = 2):
        """Least squares over rays: the LED at ``t0 + τ`` is ``a + b τ + c τ² / 2`` (``order``
        2; 0: a still point). Each ray gives two linear equations, ``(R₀ − x R₂)·(X − C) = 0``
        and ``(R₁ − y R₂)·(X − C) = 0``, weighted by pixels per metre at the point (``f /
        depth``, from a first solve) over the spot noise; the acceleration is held to
        :data:`ACCELERATION` and ``prior`` (position, velocity, their sigmas per axis) joins
        as equations. Returns (the 9 (or 3) numbers, RMS residual px, their covariance);
        (None, inf, None) when the rays do not determine them."""
        if not rays:
            return None, np.inf, None
        k = np.array([r.camera for r in rays])
        xy = np.array([r.xy for r in rays])
        tau = np.array([r.t for r in rays]) - t0
        R = self._R[k]
        rows = np.concatenate([R[:, 0] - xy[:, :1] * R[:, 2], R[:, 1] - xy[:, 1:] * R[:, 2]])
        C = np.concatenate([self._C[k], self._C[k]])
        ff = np.concatenate([self._f[k], self._f[k]])
        tt = np.concatenate([tau, tau])
        basis = [np.ones_like(tt), tt, 0.5 * tt * tt][:order + 1]
        A = np.concatenate([rows * b[:, None] for b in basis], axis=1)
        y = np.einsum("ij,ij->i", rows, C)
        w = np.ones(len(A))
        fit = None
        for _ in range(2):
            Aw, yw = A * w[:, None], y * w
            if order == 2:
                P = np.zeros((3, 9))
                P[:, 6:] = np.eye(3) / self.acceleration
                Aw, yw = np.vstack([Aw, P]), np.r_[yw, np.zeros(3)]
            if prior is not None and order == 2:
                pos, vel, s_pos, s_vel = prior
                P = np.zeros((6, 9))
                P[:3, :3] = np.eye(3) / s_pos
                P[3:, 3:6] = np.eye(3) / s_vel
                Aw = np.vstack([Aw, P])
                yw = np.r_[yw, pos / s_pos, vel / s_vel]
            N = Aw.T @ Aw
            if not _well_posed(N):
                return None, np.inf, None
            fit = np.linalg.solve(N, Aw.T @ yw)
            X = fit[:3] + (fit[3:6] * tt[:, None] + 0.5 * fit[6:9] * (tt * tt)[:, None]
                           if order == 2 else 0.0)
            depth = np.einsum("ij,ij->i", np.concatenate([R[:, 2], R[:, 2]]), X - C)
            if (depth <= 0).any():
                return None, np.inf, None
            w = ff / depth / self.pixel_sigma  # rows in units of the spot noise
        resid = (A @ fit - y) * w * self.pixel_sigma
        return fit, float(np.sqrt(np.mean(resid ** 2))), np.linalg.inv(N)


def _well_posed(N) -> bool:
    """Whether the normal matrix ``N`` determines every unknown: its Cholesky factor, with the
    unknowns scaled to unit information, has no pivot below 1e-6 of the largest (a relative
    test: metres, seconds and pixels alike)."""
    d = np.sqrt(np.diag(N))
    if not (d > 0).all():
        return False
    try:
        L = np.linalg.cholesky(N / d[:, None] / d[None, :])
    except np.linalg.LinAlgError:
        return False
    piv = np.abs(np.diag(L))
    return bool(piv.min() > 1e-6 * piv.max())
