"""Camera model: OpenCV pinhole with Brown–Conrady distortion, posed in the world frame.

Conventions (docs/conventions.md, fixed): metres and radians; world z up, floor at z = 0; pixels are
OpenCV's (u, v) = (column, row) with the centre of the top-left pixel at (0, 0);
``x_cam = R · (X_world − position)`` with ``R = Rodrigues(rotation)``, so OpenCV's
``rvec = rotation`` and ``tvec = −R · position``; ``dist = [k1, k2, p1, p2, k3]``.

Everything here is vectorised over points: arrays are ``N×3`` world points and ``N×2`` pixels.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

#: The paper's camera (Table 2, section 3.1): OV2640 at 160 × 120 px seeing ~240 × 180 cm of
#: floor from 2.3 m, hence f ≈ 160 · 2.3 / 2.4 ≈ 153.3 px (the 4.8 mm lens of the
#: datasheet would give ~218 px; the stated coverage is what we follow).
PAPER_WIDTH, PAPER_HEIGHT, PAPER_F = 160, 120, 153.3
#: Rodrigues vector of a camera looking straight down with image-right along world +x.
NADIR = (math.pi, 0.0, 0.0)


def rodrigues(rvec) -> np.ndarray:
    """Rotation matrix of a Rodrigues vector (same result as ``cv2.Rodrigues``)."""
    r = np.asarray(rvec, dtype=float).reshape(3)
    theta = float(np.linalg.norm(r))
    if theta < 1e-15:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * (kx @ kx)


def rotation_vector(R) -> np.ndarray:
    """Rodrigues vector of a rotation matrix (inverse of :func:`rodrigues`), accurate at any
    angle: θ from atan2 (not acos), and near θ = π (a camera looking almost straight down has
    its rotation there) the axis from the symmetric part of R."""
    R = np.asarray(R, dtype=float)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # 2 sin θ · k
    sin2 = float(np.linalg.norm(w))
    cos = (np.trace(R) - 1.0) / 2.0
    theta = math.atan2(sin2 / 2.0, cos)
    if theta < 1e-12:
        return w / 2.0
    if cos > -0.5:
        return w / sin2 * theta
    # θ > 120°: (R + Rᵀ)/2 = cos θ I + (1 − cos θ) k kᵀ gives k up to sign; w gives the sign
    S = (R + R.T) / 2.0 - cos * np.eye(3)
    i = int(np.argmax(np.diag(S)))
    k = S[:, i] / math.sqrt(max(S[i, i], 1e-300))
    k /= np.linalg.norm(k)
    if k @ w < 0:
        k = -k
    return k * theta


def distort(xy: np.ndarray, dist) -> np.ndarray:
    """Apply OpenCV's distortion to undistorted normalised coordinates ``N×2``."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def distortion_jacobian(xy: np.ndarray, dist) -> np.ndarray:
    """``N×2×2`` derivative of :func:`distort` with respect to its input."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
    J = np.empty(xy.shape[:-1] + (2, 2))
    J[..., 0, 0] = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
    J[..., 0, 1] = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    J[..., 1, 0] = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    J[..., 1, 1] = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
    return J


def max_radius2(dist) -> float:
    """Largest squared undistorted radius r² over which the radial distortion is monotonic.

    Past it, r · (1 + k1 r² + k2 r⁴ + k3 r⁶) folds back: a point there would project inside the
    image although the lens never images it there, and a pixel has two "undistorted" roots.
    The first positive root of d/dr, 1 + 3 k1 s + 5 k2 s² + 7 k3 s³ = 0 with s = r²; inf if none.
    """
    k1, k2, _, _, k3 = dist
    return _fold_radius2(float(k1), float(k2), float(k3))


@functools.lru_cache(maxsize=4096)
def _fold_radius2(k1: float, k2: float, k3: float) -> float:
    # cached: a calibration rebuilds its cameras thousands of times with the same lens
    roots = np.roots([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]) if any((k1, k2, k3)) else []
    s = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and r.real > 0]
    return min(s) if s else math.inf


def undistort(xy_d: np.ndarray, dist, iterations: int = 20, tol: float = 1e-15,
              max_r2: float | None = None) -> np.ndarray:
    """Invert :func:`distort` by Newton's method, to machine precision.

    ``cv2.undistortPoints`` runs a fixed few fixed-point steps and leaves ~1e-4 of error with
    strong distortion; triangulation round trips need ~1e-12, hence Newton here. A point with
    no inverse inside the lens's monotonic range (:func:`max_radius2`) comes back NaN.
    """
    xy_d = np.asarray(xy_d, dtype=float)
    if not np.any(dist):
        return xy_d.copy()
    if xy_d.shape == (1, 2):  # one point (a live frame's spot): the same steps on floats
        return np.array([_undistort_one(float(xy_d[0, 0]), float(xy_d[0, 1]), dist,
                                        iterations, tol, max_r2)])
    xy = xy_d.copy()
    k1, k2, p1, p2, k3 = dist
    for _ in range(iterations):
        # distort() and distortion_jacobian() in one pass (they share r² and the radial term)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        rx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xy_d[..., 0]
        ry = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - xy_d[..., 1]
        cross = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = jxx * jyy - cross * cross
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (jyy * rx - cross * ry) / det
            dy = (jxx * ry - cross * rx) / det
        xy[..., 0] -= dx
        xy[..., 1] -= dy
        step = np.fmax.reduce(np.abs(dx), axis=None, initial=0.0)  # NaN-blind
        step = np.fmax(step, np.fmax.reduce(np.abs(dy), axis=None, initial=0.0))
        if not step > tol:
            break
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(distort(xy, dist) - xy_d).max(axis=-1) < 1e-9) \
            | ~((xy * xy).sum(axis=-1) < (max_radius2(dist) if max_r2 is None else max_r2))
    xy[bad] = np.nan
    return xy


def _undistort_one(xd: float, yd: float, dist, iterations: int, tol: float,
                   max_r2: float | None) -> tuple[float, float]:
    """:func:`undistort` of one point in plain floats (a tenth of the array version's cost)."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    x, y = xd, yd
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        rx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
        ry = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
        cross = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = jxx * jyy - cross * cross
        if det == 0 or not math.isfinite(det):
            return math.nan, math.nan
        dx = (jyy * rx - cross * ry) / det
        dy = (jxx * ry - cross * rx) / det
        x, y = x - dx, y - dy
        if not max(abs(dx), abs(dy)) > tol:
            break
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    ex = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
    ey = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
    limit = max_radius2(dist) if max_r2 is None else max_r2
    if not (max(abs(ex), abs(ey)) < 1e-9 and r2 < limit):
        return math.nan, math.nan
    return x, y


@dataclass(frozen=True)
class Camera:
    """One installed camera: intrinsics, OpenCV distortion and pose (docs/conventions.md#pose).

    Immutable; refinements return new cameras (``dataclasses.replace``).
    """

    id: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = NADIR
    R: np.ndarray = field(init=False, repr=False, compare=False)
    #: squared undistorted radius beyond which the lens model folds back (:func:`max_radius2`)
    max_radius2: float = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name, n in (("dist", 5), ("position", 3), ("rotation", 3)):
            value = tuple(float(v) for v in np.asarray(getattr(self, name), dtype=float).ravel())
            if len(value) != n:
                raise ValueError(f"camera {self.id}: {name} needs {n} numbers, got {len(value)}")
            object.__setattr__(self, name, value)
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        R = rodrigues(self.rotation)
        R.setflags(write=False)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "max_radius2", max_radius2(self.dist))

    # -- the contract's dict form -------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        """Build from the deployment file's camera mapping (docs/formats.md)."""
        return cls(
            id=str(d["id"]), width=d["width"], height=d["height"], fx=d["fx"], fy=d["fy"],
            cx=d["cx"], cy=d["cy"], dist=d.get("dist", (0, 0, 0, 0, 0)),
            position=d["position"], rotation=d["rotation"],
        )

    def to_dict(self) -> dict:
        """The deployment file's camera mapping: plain floats and lists, metres and radians."""
        return {
            "id": self.id, "width": self.width, "height": self.height,
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "dist": list(self.dist), "position": list(self.position),
            "rotation": list(self.rotation),
        }

    # -- derived quantities -------------------------------------------------------------------
    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def center(self) -> np.ndarray:
        """Optical centre in the world, metres."""
        return np.array(self.position)

    @property
    def tvec(self) -> np.ndarray:
        """OpenCV's translation vector, ``−R · position``."""
        return -self.R @ self.center

    @property
    def yaw(self) -> float:
        """rad: the image's x axis (its width) from the world's x axis, about the vertical — how
        a ceiling camera is turned (for a tilted camera, of the axis' floor projection)."""
        return math.atan2(self.R[0][1], self.R[0][0])

    @property
    def axis(self) -> np.ndarray:
        """Unit optical axis in the world frame."""
        return self.R[2].copy()

    @property
    def tilt(self) -> float:
        """rad: the optical axis from straight down (atan2, not acos: exact near 0)."""
        a = self.R[2]
        return math.atan2(math.hypot(a[0], a[1]), -a[2])

    # -- projection -----------------------------------------------------------------------------
    def to_camera(self, X) -> np.ndarray:
        """World points ``N×3`` → camera-frame points ``N×3``."""
        X = np.asarray(X, dtype=float)
        return (X - self.center) @ self.R.T

    def project(self, X, margin: float = 0.0):
        """Project world points ``N×3`` to pixels.

        Returns ``(uv N×2, in_front N, in_image N)``: ``in_front`` is a positive depth,
        ``in_image`` also needs the pixel inside the sensor shrunk by ``margin`` px (pixel centres
        run from 0 to width − 1) and the point inside the lens model's monotonic range (past
        it the distortion polynomial folds back into the image). Points behind the camera get
        NaN pixels.
        """
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        in_front = z > 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = Xc[..., :2] / np.where(in_front, z, np.nan)[..., None]
        uv = self.normalised_to_pixels(distort(xy, self.dist) if any(self.dist) else xy)
        lo = margin - 0.5
        with np.errstate(invalid="ignore"):
            in_lens = (xy * xy).sum(axis=-1) < self.max_radius2
        in_image = (
            in_front & in_lens
            & (uv[..., 0] >= lo) & (uv[..., 0] <= self.width - 0.5 - margin)
            & (uv[..., 1] >= lo) & (uv[..., 1] <= self.height - 0.5 - margin)
        )
        return uv, in_front, in_image

    def normalised_to_pixels(self, xy_d) -> np.ndarray:
        """Distorted normalised coordinates → pixels (applies fx, fy, cx, cy only)."""
        xy_d = np.asarray(xy_d, dtype=float)
        return np.stack([xy_d[..., 0] * self.fx + self.cx, xy_d[..., 1] * self.fy + self.cy], -1)

    def normalise(self, uv) -> np.ndarray:
        """Pixels ``N×2`` → undistorted normalised coordinates ``N×2`` (x/z, y/z in the camera)."""
        uv = np.asarray(uv, dtype=float)
        xy_d = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], -1)
        return undistort(xy_d, self.dist, max_r2=self.max_radius2)

    def rays(self, uv) -> np.ndarray:
        """Pixels ``N×2`` → unit world directions ``N×3`` from :attr:`center` (NaN stays NaN)."""
        xy = self.normalise(uv)
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ self.R
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def ground(self, uv, height: float = 0.0) -> np.ndarray:
        """Where the rays of pixels ``uv`` (N×2) meet the level plane z = ``height``: N×2
        floor positions, NaN where a ray does not reach it (it points away)."""
        d = self.rays(uv)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (height - self.position[2]) / d[..., 2]
        xy = self.center[:2] + t[..., None] * d[..., :2]
        xy[~(np.isfinite(t) & (t > 0))] = np.nan
        return xy

    def footprint(self, height: float = 0.0) -> np.ndarray:
        """Where the image falls on the level plane z = ``height``: its four corners' rays,
        closed (5×2); NaN where a corner's ray does not reach the plane."""
        w, h = self.width - 0.5, self.height - 0.5
        return self.ground(np.array([[-0.5, -0.5], [w, -0.5], [w, h], [-0.5, h],
                                     [-0.5, -0.5]]), height)

    def jacobian(self, X) -> np.ndarray:
        """``N×2×3`` derivative of pixels with respect to world position (distortion included).

        ``J = diag(fx, fy) · D · (1/z) [[1, 0, −x], [0, 1, −y]] · R`` with D the distortion
        Jacobian; the planner's accuracy model builds the information ``Σ JᵀJ / σ²`` from it.
        """
        Xc = self.to_camera(X)
        z = np.where(Xc[..., 2] > 1e-9, Xc[..., 2], np.nan)  # behind the camera: NaN
        iz = 1.0 / z
        x, y = Xc[..., 0] * iz, Xc[..., 1] * iz
        # d(x, y)/d(camera point) = (1/z) [[1, 0, −x], [0, 1, −y]], then the distortion's
        # 2×2 Jacobian D and the focal lengths, then R: written out, no batched matmuls
        if any(self.dist):
            D = distortion_jacobian(np.stack([x, y], -1), self.dist)
            a, b, c, d = D[..., 0, 0], D[..., 0, 1], D[..., 1, 0], D[..., 1, 1]
        else:
            a, b, c, d = 1.0, 0.0, 0.0, 1.0
        R = self.R
        # rows of (1/z)[[1,0,−x],[0,1,−y]] · R, as N×3
        g0 = iz[..., None] * (R[0] - x[..., None] * R[2])
        g1 = iz[..., None] * (R[1] - y[..., None] * R[2])
        J = np.empty(Xc.shape[:-1] + (2, 3))
        J[..., 0, :] = self.fx * (np.asarray(a)[..., None] * g0 + np.asarray(b)[..., None] * g1)
        J[..., 1, :] = self.fy * (np.asarray(c)[..., None] * g0 + np.asarray(d)[..., None] * g1)
        return J


def paper_camera(id: str = "C1", position=(1.2, 0.9, 2.3), rotation=NADIR) -> Camera:
    """The paper's camera (160 × 120 px, fx = fy = 153.3 px, centred principal point, nadir)."""
    return Camera(
        id=id, width=PAPER_WIDTH, height=PAPER_HEIGHT, fx=PAPER_F, fy=PAPER_F,
        cx=(PAPER_WIDTH - 1) / 2, cy=(PAPER_HEIGHT - 1) / 2, position=position, rotation=rotation,
    )


def paper_rig() -> list[Camera]:
    """The paper's three cameras in a line at 2.3 m over its 3.6 × 1.8 m area.

    Read from section 3: C1 and C3 form the first pair and C2 is "placed in the middle"; one
    camera sees 240 cm and a pair shares 120 × 180 cm (Table 2's experimental area), and Table
    4 has a C1C3 pair. So C1 and C3 are 1.2 m apart (x = 1.2 and 2.4 m) with C2 at 1.8 m, all
    three see the experimental area x ∈ [1.2, 2.4] m on the floor.
    """
    return [paper_camera(f"C{i + 1}", (x, 0.9, 2.3)) for i, x in enumerate((1.2, 1.8, 2.4))]
