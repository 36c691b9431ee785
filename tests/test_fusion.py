import numpy as np
import pytest

from vlpcal.fusion import FUSIONS, RegionMap, fuse, pair_estimates
from vlpcal.geometry import paper_camera


@pytest.fixture
def triangle():
    """Three cameras in a triangle: most points near the middle are seen by all three."""
    return [paper_camera("C1", (1.0, 0.6, 2.3)), paper_camera("C2", (2.0, 0.6, 2.3)),
            paper_camera("C3", (1.5, 1.3, 2.3))]


def views(cams, X, noise=0.0, rng=None):
    uv = []
    for c in cams:
        p, _, inside = c.project(X)
        p[~inside] = np.nan
        uv.append(p)
    uv = np.stack(uv)
    return uv if not noise else uv + rng.normal(0, noise, uv.shape)


@pytest.mark.parametrize("method", FUSIONS)
@pytest.mark.parametrize("pair_method", ["paper", "lsq"])
def test_every_fusion_is_exact_without_noise(triangle, method, pair_method, rng):
    X = np.c_[rng.uniform(1.1, 1.9, 200), rng.uniform(0.7, 1.0, 200), rng.uniform(0, 0.5, 200)]
    res = fuse(triangle, views(triangle, X), method, pair_method=pair_method)
    assert (res.status == "ok").all()
    assert np.abs(res.X - X).max() < 1e-8
    assert (res.used.sum(axis=0) >= 2).all()


def test_statuses_for_missing_views(triangle):
    X = np.array([[1.5, 0.8, 0.0]] * 3)
    uv = views(triangle, X)
    uv[:, 0] = np.nan
    uv[1:, 1] = np.nan
    res = fuse(triangle, uv, "mean")
    assert list(res.status) == ["no_spot", "one_camera", "ok"]
    assert np.isnan(res.X[:2]).all()


def test_nearest_pair_uses_the_closest_cameras(rig, rng):
    X = np.array([[1.3, 0.5, 0.0], [2.0, 1.2, 0.0]])
    res = fuse(rig, views(rig, X), "nearest")
    assert res.used[:, 0].tolist() == [True, True, False]
    assert res.used[:, 1].tolist() == [False, True, True]


def test_region_map_picks_the_named_pair_and_falls_back(triangle, rng):
    X = np.c_[rng.uniform(1.1, 1.9, 300), rng.uniform(0.7, 1.0, 300), np.zeros(300)]
    uv = views(triangle, X, 0.3, rng)
    left = [[0, 0], [1.5, 0], [1.5, 2], [0, 2]]
    rmap = RegionMap.from_dict([{"polygon": left, "cameras": ["C1", "C3"]}])
    res = fuse(triangle, uv, "region", rmap)
    nearest = fuse(triangle, uv, "nearest")
    inside = rmap.lookup(fuse(triangle, uv, "mean").X[:, :2]) == 0
    pairs, Xp = pair_estimates(triangle, uv)
    c13 = np.isfinite(Xp[pairs.index((0, 2))]).all(axis=1)  # C1–C3 has a solution there
    assert (inside & c13).any() and (inside & ~c13).any() and (~inside).any()
    assert (res.used[:, inside & c13] == np.array([[True], [False], [True]])).all()
    # outside the map, or where C1–C3 is degenerate (near its top-view line): approach (b)
    assert np.array_equal(res.X[~inside | ~c13], nearest.X[~inside | ~c13], equal_nan=True)


def test_region_map_with_a_subset_of_three_uses_least_squares(triangle, rng):
    X = np.c_[rng.uniform(1.3, 1.7, 50), rng.uniform(0.8, 0.9, 50), np.zeros(50)]
    uv = views(triangle, X)
    rmap = RegionMap.from_dict([{"polygon": [[0, 0], [4, 0], [4, 4], [0, 4]],
                                 "cameras": ["C1", "C2", "C3"]}])
    res = fuse(triangle, uv, "region", rmap)
    assert res.used.all()
    assert np.abs(res.X - X).max() < 1e-9


def test_region_map_round_trip():
    items = [{"polygon": [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], "cameras": ["C1", "C2"]}]
    assert RegionMap.from_dict(items).to_dict() == items


def test_mean_of_pairs_averages_every_pair(triangle, rng):
    X = np.array([[1.5, 0.8, 0.0]])
    uv = views(triangle, X, 0.3, rng)
    pairs, Xp = pair_estimates(triangle, uv)
    assert len(pairs) == 3
    assert np.allclose(fuse(triangle, uv, "mean").X[0], Xp[:, 0].mean(axis=0))


def test_all_cameras_beat_single_pairs_on_average(triangle, rng):
    X = np.c_[rng.uniform(1.3, 1.7, 2000), rng.uniform(0.75, 0.95, 2000), np.zeros(2000)]
    uv = views(triangle, X, 0.3, rng)
    err = {m: np.nanmean(np.linalg.norm(fuse(triangle, uv, m).X - X, axis=1))
           for m in ("mean", "nearest", "all")}
    assert err["all"] < err["nearest"] and err["all"] < err["mean"]


def test_region_map_naming_unknown_cameras_is_refused(rig):
    rmap = RegionMap.from_dict([{"polygon": [[0, 0], [4, 0], [4, 4]], "cameras": ["C1", "C9"]}])
    with pytest.raises(ValueError, match="C9"):
        fuse(rig, np.full((3, 2, 2), np.nan), "region", rmap)


def test_one_or_no_camera_does_not_crash(rig):
    uv = views(rig[:1], np.array([[0.6, 0.9, 0.0]]))
    for method in FUSIONS:
        assert list(fuse(rig[:1], uv, method).status) == ["one_camera"]
        assert list(fuse([], np.zeros((0, 1, 2)), method).status) == ["no_spot"]


def test_unknown_fusion_is_a_clear_error(rig):
    with pytest.raises(ValueError, match="unknown fusion"):
        fuse(rig, np.zeros((3, 1, 2)), "median")
