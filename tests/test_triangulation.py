import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlpcal.geometry import Camera, paper_camera, rodrigues, rotation_vector
from vlpcal.triangulation import (
    triangulate,
    triangulate_cv2,
    triangulate_pair_paper,
    triangulate_robust,
)


def ceiling_camera(i, x, y, tilt, yaw, dist, f=150.0):
    R = rodrigues((tilt[0], tilt[1], yaw)) @ rodrigues((math.pi, 0.0, 0.0))
    return Camera(f"C{i}", 160, 120, f, f * 1.0135, 79.5 + 2 * i % 5, 59.5 - i % 3, dist,
                  (x, y, 2.3 + 0.02 * i), rotation_vector(R))


rigs = st.integers(2, 6).flatmap(lambda n: st.tuples(
    st.just(n),
    st.lists(st.tuples(st.floats(-0.035, 0.035), st.floats(-0.035, 0.035)), min_size=n,
             max_size=n),
    st.lists(st.floats(-math.pi, math.pi), min_size=n, max_size=n),
    st.lists(st.floats(-0.3, 0.0), min_size=n, max_size=n),
    st.tuples(st.floats(0.9, 1.5), st.floats(0.7, 1.1), st.floats(0.0, 0.7)),
))


@settings(max_examples=60, deadline=None)
@given(rigs)
def test_project_triangulate_round_trip_is_exact(rig):
    """2–6 tilted, distorted cameras: noise-free pixels give the point back to < 1e-9 m."""
    n, tilts, yaws, k1s, target = rig
    cams = [ceiling_camera(i, 0.6 + 0.35 * i, 0.6 + 0.25 * (i % 2), tilts[i], yaws[i],
                           (k1s[i], 0.05, 0.0005, -0.0005, 0.0)) for i in range(n)]
    X = np.array(target)[None] + np.array([[0, 0, 0], [0.05, -0.04, 0.02], [-0.03, 0.02, -0.0]])
    uv = np.stack([c.project(X)[0] for c in cams])
    res = triangulate(cams, uv)
    assert np.abs(res.X - X).max() < 1e-9
    assert np.nanmax(res.residual) < 1e-6
    assert (res.views == n).all()


def test_unseen_points_are_nan_and_views_counted(rig):
    X = np.array([[1.2, 0.9, 0.0], [2.4, 0.7, 0.3], [0.2, 0.2, 0.0]])
    uv = np.stack([c.project(X)[0] for c in rig])
    uv[:, 2] = np.nan
    uv[0, 1] = np.nan
    uv[2, 0] = np.nan  # point 0 seen by C1, C2 only
    res = triangulate(rig, uv)
    assert np.allclose(res.X[:2], X[:2], atol=1e-9)
    assert np.isnan(res.X[2]).all()
    assert list(res.views) == [2, 2, 0]


def test_paper_pair_hand_worked_example():
    """Cameras C1 (0.6, 0.9) and C2 (1.8, 0.9) at 2.3 m, nadir, f = 153.3 px; LED at
    (1.0, 0.5, 0.35 m): 1.95 m below the cameras.

    By hand: C1 sees the LED 0.4 m along +x and 0.4 m along −y at depth 1.95, so
    u1 = 79.5 + 153.3 · 0.4 / 1.95 = 110.946…, v1 = 59.5 + 153.3 · 0.4 / 1.95 = 90.946…;
    C2: u2 = 79.5 − 153.3 · 0.8 / 1.95 = 16.607…, v2 = v1. Floor footprints: l1 = (0.6, 0.9) +
    (2.3 / 1.95)(0.4, −0.4) = (1.0718, 0.4282), l2 = (0.8564, 0.4282). Lines C1→l1 and C2→l2
    meet at (1.0, 0.5). Along the baseline tan θ1 = 0.4718/2.3, tan θ2 = 0.9436/2.3, so
    depth = 1.2 / (1.4154/2.3) = 1.95 and z = 2.3 − 1.95 = 0.35.
    """
    c1, c2 = paper_camera("C1", (0.6, 0.9, 2.3)), paper_camera("C2", (1.8, 0.9, 2.3))
    k = 153.3 / 1.95
    uv1 = np.array([[79.5 + 0.4 * k, 59.5 + 0.4 * k]])
    uv2 = np.array([[79.5 - 0.8 * k, 59.5 + 0.4 * k]])
    assert uv1[0, 0] == pytest.approx(110.946, abs=1e-3)
    assert uv2[0, 0] == pytest.approx(16.607, abs=1e-3)
    est = triangulate_pair_paper(c1, c2, uv1, uv2)
    assert not est.degenerate[0]
    assert est.X[0] == pytest.approx([1.0, 0.5, 0.35], abs=1e-12)
    # the same depth through the paper's triangle (Fig. 7): α = 90° − θ1, β = 90° − θ2,
    # E = B sin β / sin(180° − α − β), z_depth = E sin α
    t1, t2 = (1.0718 - 0.6) / 2.3, (1.8 - 0.8564) / 2.3
    a, b = math.pi / 2 - math.atan(t1), math.pi / 2 - math.atan(t2)
    E = 1.2 * math.sin(b) / math.sin(math.pi - a - b)
    assert E * math.sin(a) == pytest.approx(1.95, abs=2e-4)


def test_paper_pair_flags_the_degenerate_top_view_case():
    """LED on the cameras' line in top view: the two top-view lines coincide."""
    c1, c2 = paper_camera("C1", (0.6, 0.9, 2.3)), paper_camera("C2", (1.8, 0.9, 2.3))
    X = np.array([[1.0, 0.9, 0.0], [1.0, 0.5, 0.0]])
    est = triangulate_pair_paper(c1, c2, c1.project(X)[0], c2.project(X)[0])
    assert list(est.degenerate) == [True, False]
    assert np.isnan(est.X[0]).all()
    assert est.X[1] == pytest.approx([1.0, 0.5, 0.0], abs=1e-9)


def test_paper_pair_flags_the_ill_conditioned_band_near_the_line(rig, rng):
    """Near the cameras' line the intersection amplifies noise ~1/sin(angle): flagged, not
    reported as a fix metres off."""
    X = np.c_[rng.uniform(1.4, 1.6, 500), np.full(500, 0.9) + rng.uniform(-0.003, 0.003, 500),
              np.zeros(500)]
    uv1 = rig[0].project(X)[0] + rng.normal(0, 0.1, (500, 2))
    uv2 = rig[1].project(X)[0] + rng.normal(0, 0.1, (500, 2))
    est = triangulate_pair_paper(rig[0], rig[1], uv1, uv2)
    assert est.degenerate.all()
    far = X + [0, 0.2, 0]
    est = triangulate_pair_paper(rig[0], rig[1], rig[0].project(far)[0], rig[1].project(far)[0])
    assert not est.degenerate.any()


def test_a_solution_behind_the_cameras_is_refused(rig):
    """Diverging rays meet above the ceiling: no fix, not an 'ok' point at z = 3.6 m."""
    uv = np.array([[[10.0, 59.5]], [[150.0, 59.5]], [[np.nan, np.nan]]])
    assert np.isnan(triangulate(rig, uv).X).all()


def test_empty_inputs(rig):
    assert triangulate(rig, np.zeros((3, 0, 2))).X.shape == (0, 3)
    assert triangulate_cv2(rig[0], rig[1], np.zeros((0, 2)), np.zeros((0, 2))).shape == (0, 3)


def test_paper_pair_beyond_the_baseline(rig):
    X = np.array([[2.1, 0.5, 0.1]])  # beyond C2 seen from C1 and C2
    est = triangulate_pair_paper(rig[0], rig[1], rig[0].project(X)[0], rig[1].project(X)[0])
    assert est.X[0] == pytest.approx(X[0], abs=1e-9)


def test_cv2_baseline_agrees(rig, rng):
    X = np.c_[rng.uniform(0.7, 1.7, 50), rng.uniform(0.2, 1.6, 50), rng.uniform(0, 0.7, 50)]
    uv1, uv2 = rig[0].project(X)[0], rig[1].project(X)[0]
    assert np.abs(triangulate_cv2(rig[0], rig[1], uv1, uv2) - X).max() < 1e-9


def test_least_squares_beats_or_matches_the_paper_pair_under_noise(rig, rng):
    X = np.c_[rng.uniform(0.7, 1.7, 3000), rng.uniform(0.2, 1.6, 3000), np.zeros(3000)]
    uv = np.stack([c.project(X)[0] for c in rig[:2]]) + rng.normal(0, 0.3, (2, 3000, 2))
    ls = np.linalg.norm(triangulate(rig[:2], uv).X - X, axis=1)
    paper = np.linalg.norm(triangulate_pair_paper(rig[0], rig[1], uv[0], uv[1]).X - X, axis=1)
    assert np.nanmedian(ls) <= np.nanmedian(paper) * 1.01


def test_robust_drops_the_reflection_and_says_which(rng):
    cams = [paper_camera(f"C{i}", (0.9 + 0.5 * (i % 2), 0.6 + 0.5 * (i // 2), 2.3))
            for i in range(4)]
    X = np.c_[rng.uniform(0.9, 1.4, 400), rng.uniform(0.6, 1.1, 400), rng.uniform(0, 0.5, 400)]
    uv = np.stack([c.project(X)[0] for c in cams]) + rng.normal(0, 0.1, (4, 400, 2))
    uv[2, :40] += [7.0, -4.0]  # camera 3 picked up a reflection in 10 % of the frames
    plain = np.linalg.norm(triangulate(cams, uv).X - X, axis=1)
    res = triangulate_robust(cams, uv)
    robust = np.linalg.norm(res.X - X, axis=1)
    assert res.dropped[2, :40].all()
    assert res.dropped.sum() <= 42  # nearly no good observation is thrown away
    # the affected points are solved from the three good cameras, exactly
    without = triangulate([cams[k] for k in (0, 1, 3)], uv[[0, 1, 3], :40]).X
    assert np.abs(res.X[:40] - without).max() < 1e-9
    assert (robust[:40] < plain[:40]).all()
    assert not res.used[2, :40].any()


def test_wrong_shape_is_refused(rig):
    with pytest.raises(ValueError, match="C×N×2"):
        triangulate(rig, np.zeros((2, 5, 2)))
