"""A track's path over a window of rays at their own capture times: the least-squares fit (a
quadratic in time, in pixels), the row it gives and its extrapolation: the tracker's methods."""

from __future__ import annotations

import cv2
import numpy as np

from .constants import BODY_MEASURE, DEGENERATE_SHARE, FIT_SIGMAS, TOP_SPEED
from .records import TrackUpdate, _Ray, _Track


class PathFit:
    """The :class:`~vlpcal.tracking.Tracker`'s fit of a track's path and its rows."""

    def _extrapolated(self, tr: _Track, t: float):
        """The track's latest fit carried to ``t`` at its velocity, with the sigmas of position
        and velocity that the motion it cannot foresee (:data:`ACCELERATION`) leaves there."""
        dt = t - tr.fit_t  # at constant velocity: a short window's acceleration is noisy
        pos = tr.fit[:3] + tr.fit[3:6] * dt
        vel = tr.fit[3:6].copy()
        s_pos = _carried(tr.s_pos, tr.s_vel, dt, self.acceleration)
        s_vel = np.hypot(tr.s_vel, self.acceleration * dt)
        return pos, vel, s_pos, s_vel

    def _plausible(self, fit, cov) -> bool:
        """Whether a window's fit can be the LED: inside the room (the locator's rule,
        :meth:`~vlpcal.deployment.Deployment.outside`) and no faster than three times
        :data:`TOP_SPEED` (rays that barely cross can fit a point far off, flying)."""
        sigma = float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)))
        return bool(np.linalg.norm(fit[3:6]) <= 3 * TOP_SPEED
                    and not self.deployment.outside(fit[:3], sigma)[0])

    def _predicted(self, k: int, t: float):
        """Each track's extrapolated spot in camera ``k`` at ``t`` (T×2 px, NaN: behind it),
        where the blink code expects to see it."""
        if not self.tracks:
            return np.zeros((0, 2))
        X = np.array([self._extrapolated(tr, t)[0] for tr in self.tracks])
        pred, front, _ = self.cameras[k].project(X)
        pred[~front] = np.nan
        return pred

    def _meet(self, p: _Ray, ray: _Ray):
        """How well two rays of two cameras meet as one LED: (their residual over what the
        motion possible between them allows, < 1 when they do; the point), or (inf, None) when
        they do not determine a point in front of both cameras, above the floor (a floor's
        mirror image of an LED meets below it)."""
        fit, resid, cov = self._solve([p, ray], ray.t, order=0)
        if fit is None:
            return np.inf, None
        X = fit[:3]
        depth = [float(self.cameras[r.camera].to_camera(X[None])[0, 2]) for r in (p, ray)]
        if min(depth) <= 0 or X[2] < -3 * np.sqrt(max(cov[2, 2], 0.0)):
            return np.inf, None
        allowed = 3 * self.pixel_sigma + TOP_SPEED * abs(ray.t - p.t) * max(
            self._f[r.camera] / d for r, d in zip((p, ray), depth))
        return (resid / allowed if resid <= allowed else np.inf), X

    def _row(self, tr: _Track, t: float) -> TrackUpdate:
        fit = cov = None
        rays: list = []
        cams: list = []
        guess = self._extrapolated(tr, t)[0]
        for reach in (self.half, 0.5 * self.half):  # a window the path does not fit: halved
            ahead = min(self._lag, reach)  # the window reaches this far past t (its lag)
            rays = [r for r in tr.rays if t - 2 * reach + ahead <= r.t <= t + ahead]
            cams = sorted({r.camera for r in rays})
            if len(cams) < 2:
                break
            fit, resid, cov = self._solve(rays, t, guess=guess)
            if fit is not None and resid <= FIT_SIGMAS * self.pixel_sigma \
                    and self._plausible(fit, cov):
                break
            fit = cov = None
        timing = 0.0
        if fit is not None:  # (a window that shares no ray with the last one that told the
            learn = rays[0].t > tr.timed_until  # latencies tells them too)
            timing = self._timed(rays, t, fit, cov, learn)
            if timing is None:  # its cameras' times disagree: not placed by them
                fit = cov = None
            elif learn:
                tr.timed_until = rays[-1].t
        fit_ok = fit is not None
        if fit is None:  # one camera (or none that fits): the motion places it on a ray
            pos, vel, s_pos, _ = self._extrapolated(tr, t)
            if rays:
                near = min(rays, key=lambda r: abs(r.t - t))
                cam = self.cameras[near.camera]
                d = np.r_[near.xy, 1.0] @ cam.R  # the ray's direction in the world
                d = d / np.linalg.norm(d)
                pos = cam.center + d * float((pos - cam.center) @ d)
            fit, cov = np.r_[pos, vel, np.zeros(3)], np.eye(9) * s_pos ** 2
        variance = np.trace(cov[:3, :3]) + (timing if fit_ok else 0.0)
        sigma = float(np.sqrt(max(variance, 0.0)))
        status = "ok" if fit_ok else "one_camera"
        # the motion that would carry a one-camera row was fitted at times not yet checked
        # (a late camera's first second): no position
        unchecked = not fit_ok and self.spots == 1 and not self.latency.vetted[
            sorted({r.camera for r in tr.rays})].all()
        if unchecked or not sigma < DEGENERATE_SHARE * self._size:
            # no position worth the name: none given (as the locator's degenerate fixes), so
            # no robot steers by it; live, the first second's, before a search has checked
            # the cameras' times, say so
            status = "times_unchecked" if unchecked or (
                fit_ok and timing > variance - timing
                and not self.latency.vetted[cams].all()) else "degenerate"
            fit = np.full(9, np.nan)
        return TrackUpdate(t, tr.led, fit[:3].copy(), fit[3:6].copy(), sigma,
                           "+".join(self.cameras[k].id for k in cams), status)

    def _metres_per_px(self, X, cams) -> float:
        if not cams:
            return 1.0
        k = cams[0]
        return float(self.cameras[k].to_camera(X[None])[0, 2]) / self._f[k] * self.pixel_sigma

    def _solve(self, rays, t0: float, prior=None, order: int = 2, guess=None):
        """Least squares over rays: the LED at ``t0 + τ`` is ``a + b τ + c τ² / 2`` (``order``
        2; 0: a still point). Each ray gives two linear equations, ``(R₀ − x R₂)·(X − C) = 0``
        and ``(R₁ − y R₂)·(X − C) = 0``, weighted by pixels per metre at the point (``f /
        depth``, the depth from ``guess``, a position near ``t0``, or from a first solve) over
        the spot noise; the acceleration is held to :data:`ACCELERATION` and ``prior``
        (position, velocity, their sigmas per axis) joins as equations. Returns (the 9 (or 3)
        numbers, RMS residual px, their covariance); (None, inf, None) when the rays do not
        determine them."""
        if not rays:
            return None, np.inf, None
        m = len(rays)
        eq = np.concatenate([r.eq for r in rays])  # 2m × 10, each ray's two equations
        rows, y, tt = eq[:, :3], eq[:, 3], eq[:, 4] - t0
        axis, along, ff = eq[:, 5:8], eq[:, 8], eq[:, 9]
        if order == 0:
            A, P = rows, None
        else:  # the position at each ray's time is P @ (a, b, c) per axis
            P = tt[:, None] ** _POWERS * _HALF_SQUARE
            A = (P[:, :, None] * rows[:, None, :]).reshape(2 * m, 9)
        D = b = None  # the priors, diagonal: information D, and b = D × their values
        if order == 2:
            ia = 1.0 / self.acceleration ** 2
            if prior is None:
                D = np.array([0.0] * 6 + [ia] * 3)
            else:
                pos, vel, s_pos, s_vel = prior
                ip, iv = float(1.0 / s_pos ** 2), float(1.0 / s_vel ** 2)
                D = np.array([ip] * 3 + [iv] * 3 + [ia] * 3)
                b = np.concatenate((pos * ip, vel * iv, _ZERO3))
        if guess is not None:
            depth = axis @ np.asarray(guess, float) - along
            if not (depth > 0).all():
                return None, np.inf, None
            w = ff / depth
            passes = 1
        else:
            w, passes = np.ones(len(A)), 2
        fit = cov = None
        for _ in range(passes):
            Aw = A * (w * w)[:, None]
            N = Aw.T @ A
            if D is not None:
                N.flat[::len(N) + 1] += D
            rhs = Aw.T @ y
            fit, cov = _solve_posed(N, rhs if b is None else rhs + b)
            if fit is None:
                return None, np.inf, None
            if P is None:
                depth = axis @ fit - along
            else:  # the LED at each ray's time
                depth = np.einsum("ij,ij->i", axis, P @ fit.reshape(3, 3)) - along
            if not (depth > 0).all():
                return None, np.inf, None
            if passes == 2:
                w = ff / depth
        resid = (A @ fit - y) * w
        return fit, float(self.pixel_sigma * np.sqrt(resid @ resid / len(resid))), cov




def _carried(s0, s_rate, dt: float, acceleration: float):
    """The sigma of a state (a position, a heading) carried ``dt`` at its rate: its own, its
    rate's over ``dt``, and the acceleration it cannot foresee (1 sigma) over ``dt``."""
    return np.sqrt(s0 ** 2 + (s_rate * dt) ** 2 + (0.5 * acceleration * dt * dt) ** 2)


def _apart(pa, sa: float, pb, sb: float, want: float) -> tuple[bool, float]:
    """Whether two placed LEDs (positions, sigmas per axis) lie ``want`` apart, as their body
    has them, within their sigmas (3 of them in 3D, and the body's own measure,
    :data:`BODY_MEASURE`); and that slack."""
    slack = 3 * np.sqrt(3 * (sa ** 2 + sb ** 2)) + BODY_MEASURE * want
    return bool(abs(float(np.linalg.norm(pa - pb)) - want) <= slack), float(slack)


def _slope(t, xy) -> np.ndarray:
    """The least-squares line's slope of points ``xy`` (N×2) over times ``t`` (N)."""
    dt = t - t.mean()
    return dt @ (xy - xy.mean(axis=0)) / (dt @ dt)


#: a ray's time τ → the factors (1, τ, τ²/2) of position, velocity and acceleration
_POWERS, _HALF_SQUARE = np.arange(3.0), np.array([1.0, 1.0, 0.5])
_ZERO3 = np.zeros(3)


def _solve_posed(N, rhs):
    """``(N⁻¹ rhs, N⁻¹)`` when the normal matrix ``N`` determines every unknown, else
    ``(None, None)``. With the unknowns scaled to unit information, each must keep at least
    1e-12 of it once the others are free: the inverse's diagonal (the variance inflation) at
    most 1e12 (a relative test: metres, seconds and pixels alike). OpenCV's Cholesky inverse:
    a 9 × 9 in ~2 µs, where numpy's calls cost ~15 µs."""
    d = np.sqrt(N.diagonal())
    if not (d > 0).all():
        return None, None
    dd = np.multiply.outer(d, d)
    ok, inv = cv2.invert(N / dd, flags=cv2.DECOMP_CHOLESKY)
    inflation = inv.diagonal()
    if not (ok and (inflation > 0.5).all() and (inflation < 1e12).all()):
        return None, None
    cov = inv / dd
    return cov @ rhs, cov
