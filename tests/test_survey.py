import numpy as np

from vlpcal.fusion import fuse
from vlpcal.geometry import paper_camera
from vlpcal.survey import learn_region_map, plan_survey


def test_region_map_names_the_pair_that_was_best_there(rng):
    """Camera C3 is 3 px off in one half of the room: the map must avoid its pairs there."""
    cams = [paper_camera("C1", (1.2, 0.9, 2.3)), paper_camera("C2", (1.8, 0.9, 2.3)),
            paper_camera("C3", (1.5, 1.4, 2.3))]
    X = np.c_[rng.uniform(1.2, 1.8, 600), rng.uniform(0.2, 1.6, 600), np.zeros(600)]
    X = X[np.abs(X[:, 1] - 0.9) > 0.1]
    uv = np.stack([c.project(X)[0] for c in cams]) + rng.normal(0, 0.1, (3, len(X), 2))
    uv[2, X[:, 0] < 1.5] += [3.0, 0.0]
    room = [[0, 0], [3.0, 0], [3.0, 1.8], [0, 1.8]]
    rmap = learn_region_map(cams, uv, X, room, cell=0.3)
    left = [ids for poly, ids in rmap.regions if poly.centroid.x < 1.5]
    assert left and all(ids == ("C1", "C2") for ids in left)
    # used for approach (c), it beats the plain mean of pairs on the same points
    e_c = np.nanmean(np.linalg.norm(fuse(cams, uv, "region", rmap).X - X, axis=1))
    e_a = np.nanmean(np.linalg.norm(fuse(cams, uv, "mean").X - X, axis=1))
    assert e_c < e_a


def test_survey_plan_walks_a_serpentine_without_crossing_the_room():
    """Each row is entered from the end nearer to where the last row ended: no walk back
    across the room between consecutive points at one height."""
    from pathlib import Path

    from vlpcal.deployment import load

    dep = load(Path(__file__).resolve().parents[1] / "layouts/paper-linear.planned.yaml")
    plan = plan_survey(dep, 0.3, (0.0, 0.35, 0.7))
    same = np.diff(plan.xyz[:, 2]) == 0
    steps = np.linalg.norm(np.diff(plan.xyz[:, :2], axis=0), axis=1)[same]
    width = np.ptp(np.array(dep.room)[:, 0])
    assert steps.max() < width / 2
    assert len(set(map(tuple, plan.xyz.round(6)))) == len(plan.ids)
