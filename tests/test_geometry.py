import math

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlpcal.geometry import Camera, distort, paper_camera, rodrigues, rotation_vector, undistort


def tilted_camera(rvec_tilt=(0.03, -0.02, 0.4), dist=(-0.25, 0.08, 0.001, -0.0015, -0.01)):
    R = rodrigues(rvec_tilt) @ rodrigues((math.pi, 0, 0))
    return Camera("T", 160, 120, 150.0, 152.0, 81.0, 58.5, dist, (1.0, 0.8, 2.4),
                  rotation_vector(R))


@given(st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3))
def test_rodrigues_matches_opencv_and_inverts(r):
    R = rodrigues(r)
    assert np.allclose(R, cv2.Rodrigues(np.array(r, float))[0], atol=1e-12)
    assert np.allclose(rodrigues(rotation_vector(R)), R, atol=1e-9)


def test_project_matches_cv2_projectPoints(rng):
    cam = tilted_camera()
    X = np.c_[rng.uniform(0, 2, 200), rng.uniform(0, 1.6, 200), rng.uniform(0, 0.7, 200)]
    uv, front, _ = cam.project(X)
    ref, _ = cv2.projectPoints(X, np.array(cam.rotation), cam.tvec, cam.K, np.array(cam.dist))
    assert front.all()
    assert np.allclose(uv, ref.reshape(-1, 2), atol=1e-9)


def test_nadir_convention():
    """DESIGN.md: rotation [π, 0, 0] looks down with image-right along world +x."""
    cam = paper_camera(position=(1.0, 1.0, 2.3))
    uv, front, inside = cam.project([[1.0, 1.0, 0.0], [1.2, 1.0, 0.0], [1.0, 1.2, 0.0]])
    assert front.all() and inside.all()
    assert np.allclose(uv[0], [79.5, 59.5])
    assert uv[1, 0] > 79.5 and np.isclose(uv[1, 1], 59.5)  # +x world → right
    assert uv[2, 1] < 59.5  # +y world → up in the image
    assert np.allclose(cam.axis, [0, 0, -1])


def test_masks_behind_and_outside():
    cam = paper_camera(position=(0, 0, 2.3))
    uv, front, inside = cam.project([[0, 0, 3.0], [5.0, 0, 0], [0.5, 0.3, 0]])
    assert list(front) == [False, True, True]
    assert list(inside) == [False, False, True]
    assert np.isnan(uv[0]).all()


def test_margin_shrinks_the_image():
    cam = paper_camera(position=(0, 0, 2.3))
    X = np.array([[(158.9 - cam.cx) / cam.fx * 2.3, 0.0, 0.0]])  # projects at u = 158.9
    assert cam.project(X)[2][0]
    assert not cam.project(X, margin=2.0)[2][0]


def test_undistort_inverts_distort_to_machine_precision(rng):
    dist = (-0.3, 0.1, 0.002, -0.001, -0.02)
    xy = rng.uniform(-0.55, 0.55, (500, 2))
    assert np.abs(undistort(distort(xy, dist), dist) - xy).max() < 1e-13


def test_rays_point_at_the_projected_points(rng):
    cam = tilted_camera()
    X = np.c_[rng.uniform(0.2, 1.8, 100), rng.uniform(0.2, 1.4, 100), rng.uniform(0, 0.7, 100)]
    uv, _, _ = cam.project(X)
    d = cam.rays(uv)
    to = X - cam.center
    to /= np.linalg.norm(to, axis=1, keepdims=True)
    assert np.abs(d - to).max() < 1e-12


def test_jacobian_matches_finite_differences(rng):
    cam = tilted_camera()
    X = np.c_[rng.uniform(0.4, 1.6, 50), rng.uniform(0.3, 1.3, 50), rng.uniform(0, 0.7, 50)]
    J = cam.jacobian(X)
    h = 1e-6
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        num = (cam.project(X + e)[0] - cam.project(X - e)[0]) / (2 * h)
        assert np.allclose(J[:, :, k], num, rtol=1e-6, atol=1e-4)


def test_dict_round_trip_and_equality():
    cam = tilted_camera()
    d = cam.to_dict()
    assert set(d) == {"id", "width", "height", "fx", "fy", "cx", "cy", "dist", "position",
                      "rotation"}
    back = Camera.from_dict(d)
    assert back == cam
    assert np.array_equal(back.R, cam.R)


def test_paper_preset():
    cam = paper_camera()
    assert (cam.width, cam.height) == (160, 120)
    assert cam.fx == cam.fy == pytest.approx(153.3)
    # one camera sees about 240 × 180 cm of floor from 2.3 m (section 3.1)
    width_m = cam.width / cam.fx * 2.3
    assert width_m == pytest.approx(2.4, abs=0.01)


def test_wrong_shapes_are_refused():
    with pytest.raises(ValueError, match="dist needs 5"):
        Camera("X", 160, 120, 150, 150, 80, 60, dist=(0, 0, 0))


@given(st.floats(0.0, 1e-3), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_rotation_vector_is_accurate_near_pi(eps, axis):
    """A near-nadir camera's rotation is close to π: the inverse must stay accurate there."""
    a = np.array(axis)
    if np.linalg.norm(a) < 1e-3:
        a = np.array([1.0, 0.0, 0.0])
    r = a / np.linalg.norm(a) * (math.pi - eps)
    back = rotation_vector(rodrigues(r))
    assert np.allclose(rodrigues(back), rodrigues(r), atol=1e-12)
    if eps > 1e-9:
        assert np.abs(back - r).max() < 1e-9


def test_strong_distortion_has_no_false_roots():
    """Past the fold of the distortion polynomial there is no inverse and no visibility."""
    cam = Camera("K", 160, 120, 153.3, 153.3, 79.5, 59.5, (-0.5, 0, 0, 0, 0), (0, 0, 2.3))
    assert cam.max_radius2 == pytest.approx(2 / 3)
    assert np.isnan(cam.normalise([[0.0, 0.0]])).all()  # the corner pixel is past the fold
    cam = Camera("K", 160, 120, 153.3, 153.3, 79.5, 59.5, (-0.3, 0, 0, 0, 0), (0, 0, 2.3))
    uv, front, inside = cam.project([[2.392, 1.794, 0.0]])  # 52° off axis folds into the image
    assert front[0] and 0 <= uv[0, 0] < 160 and 0 <= uv[0, 1] < 120
    assert not inside[0]


def test_jacobian_is_nan_behind_the_camera():
    cam = paper_camera(position=(0, 0, 2.3))
    assert np.isnan(cam.jacobian([[0.0, 0.0, 3.0]])).all()
