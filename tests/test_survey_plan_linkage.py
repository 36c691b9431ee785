"""Survey plans that link every camera, checked before anyone measures — the free
LED's route through every thin overlap, references and frame marks spread over the room, the
cameras that cannot be linked named with what would link them, tape positions to what a tape
marks and the survey's time said. Deployments are written directly (planning them is slow)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from shapely.geometry import MultiPoint, Polygon

from vlpcal.cli import main
from vlpcal.deployment import Deployment, save
from vlpcal.geometry import NADIR, paper_camera, rodrigues, rotation_vector
from vlpcal.survey import SurveyError, free_route, plan_references
from vlpcal.survey.frame_error import marks_frame_error
from vlpcal.survey.free_checks import MIN_SHARED, check_linked
from vlpcal.survey.free_plan import MARK_MARGIN, plan_marks
from vlpcal.survey.linkage import (
    PLACING_SHARE,
    SWEEP_SETS,
    Reach,
    _hidden,
    _remedy,
    footprint,
    link_cameras,
)

PILLAR = [[2.8, 1.8], [3.2, 1.8], [3.2, 2.2], [2.8, 2.2]]


def cam(cid, x, y, z, yaw_deg=0.0):
    """The paper's camera, level, turned by ``yaw_deg`` about the vertical."""
    rvec = rotation_vector(rodrigues(NADIR) @ rodrigues((0.0, 0.0, math.radians(yaw_deg))).T)
    return paper_camera(cid, (x, y, z), rvec)


def issue_office():
    """The issue's office: 6 × 4 m with a pillar, 12 level cameras in 3 columns × 4 rows at
    2.8 m, turned 90°: the columns' views overlap in a strip ~18 cm wide at the floor."""
    cams = [cam(f"C{3 * r + c + 1}", 1.0 + 2.0 * c, 0.5 + 1.0 * r, 2.8, 90)
            for r in range(4) for c in range(3)]
    return Deployment("office", 2.8, [[0, 0], [6, 0], [6, 4], [0, 4]], cams, [PILLAR])


def planned(name, ceiling, room, keep_out, layout):
    """A layout as `vlpcal plan` placed it (positions and yaws copied from its output)."""
    return Deployment(name, ceiling, room, [cam(f"C{k + 1}", x, y, ceiling, yaw)
                                            for k, (x, y, yaw) in enumerate(layout)], keep_out)


ROOMS = {
    "office 6x4, pillar (planned)": lambda: planned(
        "office", 2.8, [[0, 0], [6, 0], [6, 4], [0, 4]], [PILLAR],
        [(x, y, 0) for y in (1.0, 2.9) for x in (0.0, 1.2, 2.4, 3.6, 4.8, 6.0)]),
    "L-shaped room (planned)": lambda: planned(
        "l-room", 2.8, [[0, 0], [6, 0], [6, 2.5], [2.5, 2.5], [2.5, 6], [0, 6]], [],
        [(1.2, 0.6, 0), (4.6, 0.2, 0), (0.7, 1.1, 90), (2.5, 1.3, 90), (4.9, 1.2, 90),
         (1.2, 2.4, 0), (3.4, 1.2, 90), (4.7, 2.0, 0), (1.2, 3.2, 0), (1.2, 4.0, 0),
         (1.2, 4.8, 0), (1.2, 5.6, 0)]),
    "corridor 12x2 (planned)": lambda: planned(
        "corridor", 2.6, [[0, 0], [12, 0], [12, 2], [0, 2]], [],
        [(0.3 + 0.8 * k, 0.9, 90) for k in range(15)]),
    "office of the issue": issue_office,
}


def apart():
    """Two groups of two cameras with 4 m of floor between their views."""
    cams = [cam(f"C{k + 1}", x, 1.5, 2.8) for k, x in enumerate((1.2, 2.4, 7.6, 8.8))]
    return Deployment("apart", 2.8, [[0, 0], [10, 0], [10, 3], [0, 3]], cams)


def walk(dep, route, rng, tops=None):
    """The LED as a person carries it along ``route``: at each stop, put down by eye within
    the placing share of a footprint, swept from the foot to the stop's top and back in
    :data:`SWEEP_SETS` moments. Returns the cameras' sightings ``C×N`` (2 px margin)."""
    r = PLACING_SHARE * footprint(dep.cameras, route.low)
    tops = route.tops if tops is None else tops
    pts = []
    for (x, y), top in zip(route.stops, tops):
        h = np.r_[np.linspace(route.low, top, SWEEP_SETS // 2),
                  np.linspace(top, route.low, SWEEP_SETS // 2)]
        xy = np.c_[x, y] + rng.uniform(-r, r, (len(h), 2))
        pts.append(np.c_[xy, h])
    pts = np.concatenate(pts)
    return np.stack([c.project(pts, margin=2.0)[2] for c in dep.cameras])


def hull_share(xyz, dep):
    return MultiPoint(np.asarray(xyz)[:, :2]).convex_hull.area / Polygon(dep.room).area


def test_the_issue_office_is_linked_through_its_thin_column_overlaps():
    """The issue's 12 cameras: the old route swept only same-column pairs and the calibration
    refused the columns as unlinked. The route now stops in the thin overlaps between columns
    with a low sweep; walked as a person would, the calibration's own linkage rule passes —
    and the same stops swept full height (crossing the strip in a moment) fail it."""
    dep = issue_office()
    route = free_route(dep)
    ids = [c.id for c in dep.cameras]
    assert route.groups == [ids]
    assert ("C1", "C2") in route.linkage.thin and ("C2", "C3") in route.linkage.thin
    low = route.tops < route.high - 1e-9
    assert low.any() and (route.tops[low] < 0.3 * route.high).all()
    across = {p for stop in route.pairs for p in stop}
    assert {("C1", "C2"), ("C2", "C3"), ("C10", "C11"), ("C11", "C12")} <= across
    assert (route.sets[np.triu(route.linkage.linked, 1)] >= MIN_SHARED).all()
    rng = np.random.default_rng(3)
    check_linked(ids, walk(dep, route, rng))  # the calibration's rule: no refusal
    with pytest.raises(SurveyError, match="not linked"):
        check_linked(ids, walk(dep, route, rng, tops=np.full(len(route.stops), route.high)))


@pytest.mark.parametrize("room", sorted(ROOMS))
def test_survey_plan_free_links_every_room_and_spreads_its_references(room, tmp_path):
    """`survey plan --free` on each room: every camera linked (one line), references seen by
    two cameras or more over most of the room (the old plan put them in a third of the
    office), each to the millimetre, and the time said."""
    dep = ROOMS[room]()
    save(dep, tmp_path / "d.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--free",
                                    "--out", str(tmp_path / "refs.csv")])
    assert res.exit_code == 0, res.output
    assert f"linked: a free LED swept from 0 to {0.4 * dep.ceiling_height:.2f} m links all " \
           f"{len(dep.cameras)} cameras" in res.output
    assert "warning" not in res.output
    assert "(about " in res.output and "stops (one sweep each: about " in res.output  # time
    rows = [r.split(",") for r in (tmp_path / "refs.csv").read_text().splitlines()[1:]]
    xyz = np.array([[float(v) for v in r[1:]] for r in rows])
    assert np.allclose(xyz * 1000, np.round(xyz * 1000), atol=1e-6)  # what a tape marks
    seen = np.stack([c.project(xyz, margin=5.0)[2] for c in dep.cameras])
    assert (seen.sum(axis=0) >= 2).all()
    assert hull_share(xyz, dep) > 0.6, hull_share(xyz, dep)
    floor = xyz[xyz[:, 2] == 0, :2]  # not along one line (the old plan: 7 of 9 on one)
    x0, y0, x1, y1 = Polygon(dep.room).bounds
    assert np.sqrt(np.linalg.eigvalsh(np.cov(floor.T))[0]) > 0.25 * min(x1 - x0, y1 - y0)


def test_references_spread_where_twelve_cameras_have_many_pairs():
    """plan_references on the issue's office: the old pair-by-pair choice spent all twelve
    references on the first pairs (hull 26 % of the room, none above y = 1.75 m)."""
    dep = issue_office()
    refs = plan_references(dep)
    assert len(refs.ids) == 12 and hull_share(refs.xyz, dep) > 0.6
    assert refs.xyz[:, 1].max() > 3.0 and refs.xyz[:, 1].min() < 1.0
    assert len(set(refs.xyz[:, 2])) == 3  # three heights still


def test_cameras_that_cannot_be_linked_are_named_before_measuring(tmp_path):
    """Two groups of cameras far apart: the plan is written (a tape survey, or one more camera,
    can still work) and warns, naming the group and where one more camera would link it —
    and a camera there does."""
    dep = apart()
    save(dep, tmp_path / "d.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--free",
                                    "--out", str(tmp_path / "refs.csv")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "refs.csv").is_file() and (tmp_path / "refs.png").is_file()
    warn = [line for line in res.output.splitlines() if line.startswith("warning:")]
    assert len(warn) == 2 and "2 groups (C1, C2; C3, C4)" in warn[0]
    assert warn[1].startswith("warning: C3, C4: no other camera shares their view")
    linkage = link_cameras(dep)
    assert linkage.unlinked == ["C3", "C4"]
    (remedy,) = linkage.remedies
    assert remedy.camera_at is not None and math.isnan(remedy.sweep_top)
    assert f"add a camera near ({remedy.camera_at[0]:.2f}, {remedy.camera_at[1]:.2f}) m" in warn[1]
    assert 3.9 < remedy.camera_at[0] < 6.1
    more = Deployment("apart+1", 2.8, dep.room,
                      dep.cameras + [cam("C5", *remedy.camera_at, 2.8)])
    assert link_cameras(more).all_linked
    # no overlap at all: nothing a free LED can do, refused in one line
    far = Deployment("far", 2.8, [[0, 0], [20, 0], [20, 3], [0, 3]],
                     [cam("A", 2, 1.5, 2.8), cam("B", 15, 1.5, 2.8)])
    save(far, tmp_path / "far.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "far.yaml"),
                                    "--free", "--out", str(tmp_path / "f.csv")])
    assert res.exit_code == 2 and "two cameras" in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_an_obstacle_hides_what_is_behind_it():
    """A counter 1 m tall between two cameras hides the LED near it from the far camera: the
    pair linked over an open floor is not linked behind it, and a camera above it would."""
    counter = [[2.1, 0], [2.9, 0], [2.9, 3], [2.1, 3]]
    dep = Deployment("counter", 2.8, [[0, 0], [5, 0], [5, 3], [0, 3]],
                     [cam("C1", 2.0, 1.5, 2.8), cam("C2", 3.0, 1.5, 2.8)], [counter])
    assert link_cameras(dep, obstacles=[]).all_linked
    hidden = link_cameras(dep, obstacles=[(counter, 1.0)])
    assert hidden.unlinked == ["C2"] and hidden.sets[0, 1] < MIN_SHARED
    assert hidden.remedies[0].camera_at is not None
    pts = np.array([[1.9, 1.5, 0.0], [1.9, 1.5, 2.5], [4.0, 1.5, 0.0]])
    assert _hidden(np.array([3.0, 1.5, 2.8]), pts, [(counter, 1.0)]).tolist() == \
        [True, False, False]


def test_a_taller_sweep_is_named_where_the_shared_view_is_higher():
    """Where a pair shares the view only above the sweep (an obstacle below, a camera's
    lean), the remedy names the lowest sweep from the floor that would link it."""
    L, Y, X = 12, 9, 9
    seen = np.zeros((2, L, Y, X), bool)
    seen[0] = True
    seen[1, 6:] = True  # camera 1 sees the LED only from level 6 up
    reach = Reach([cam("A", 0.5, 0.5, 3), cam("B", 0.6, 0.5, 3)], np.arange(X) * 0.1,
                  np.arange(Y) * 0.1, np.ones((Y, X), bool), np.linspace(0, 2.2, L), 4, seen,
                  1, 0.1, Polygon([[0, 0], [1, 0], [1, 1], [0, 1]]))
    remedy = _remedy(reach, [1], [0])
    need = MIN_SHARED / SWEEP_SETS  # levels 6..m of 0..m shared: (m - 5) / (m + 1) ≥ need
    m = next(m for m in range(L) if (m - 5) / (m + 1) >= need)
    assert remedy.sweep_top == pytest.approx(reach.levels[m])
    assert f"sweep up to {reach.levels[m]:.2f} m" in remedy.words()


def test_a_wand_survey_plans_frame_marks_with_empty_cells(tmp_path):
    """`survey plan --wand`: O, X and three floor marks, each in two cameras' view wherever
    it lands by eye, O where the most cameras see it and X far ahead of it along x, the marks
    spread; the file's unmeasured cells
    empty; the wand waved to 40 % of the ceiling plus half its length."""
    from vlpcal.datasets import read_points

    dep = issue_office()
    marks = plan_marks(dep)
    assert marks.ids == ["O", "X", "F1", "F2", "F3"] and marks.axis == "x"
    r = PLACING_SHARE * footprint(dep.cameras, 0.0)
    for dx, dy in ((0, 0), (r, 0), (-r, 0), (0, r), (0, -r)):
        p = marks.xyz + [dx, dy, 0]
        assert (np.stack([c.project(p, margin=5.0)[2] for c in dep.cameras]).sum(axis=0)
                >= 2).all(), (dx, dy)
    o, x = marks.xyz[:2]
    assert o[1] == x[1] and x[0] - o[0] > 0.4 * 6  # half the marks' zone ahead of O
    views = marks.seen.sum(axis=0)
    assert views[0] == views.max() >= 3  # the origin where the cameras agree best
    # the floor marks where the frame they set moves the fixes least: better than 95 % of
    # other floor marks two cameras see (O and X as planned)
    rng = np.random.default_rng(0)
    zone = np.c_[rng.uniform(0, 6, 500), rng.uniform(0, 4, 500), rng.choice([0, 0.7], 500)]
    margin = MARK_MARGIN * 120

    def error(xyz):
        seen = np.stack([c.project(xyz, margin=margin)[2] for c in dep.cameras])
        return marks_frame_error(dep.cameras, xyz, seen, zone)

    cand = np.c_[rng.uniform(0, 6, 4000), rng.uniform(0, 4, 4000), np.zeros(4000)]
    two = np.stack([c.project(cand, margin=margin)[2] for c in dep.cameras]).sum(axis=0) >= 2
    cand = cand[two]
    others = [error(np.vstack([marks.xyz[:2], cand[rng.choice(len(cand), 3, replace=False)]]))
              for _ in range(300)]
    assert error(marks.xyz) < np.percentile(others, 5), (error(marks.xyz), np.min(others))
    # and the floor's tilt is fixed across the room both ways, not along one line
    assert (np.ptp(marks.xyz[:, :2], axis=0) > 0.5 * np.array([6, 4])).all()
    save(dep, tmp_path / "d.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--wand",
                                    "0.5", "--out", str(tmp_path / "marks.csv")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "marks.csv").read_text().splitlines() == [
        "point_id,x,y,z", "O,0,0,0", "X,,0,0", "F1,,,0", "F2,,,0", "F3,,,0"]
    ids, xyz = read_points(tmp_path / "marks.csv", unmeasured=True)
    assert ids[:2] == ["O", "X"] and np.isnan(xyz[1, 0]) and np.isnan(xyz[2, :2]).all()
    assert "from 0 to 1.37 m" in res.output and "linked: " in res.output
    assert "along the plan's +x from O: the calibrated frame's +x" in res.output


def test_tape_positions_are_to_the_millimetre_and_the_time_is_said(tmp_path):
    """A tape plan's positions are what a tape marks (1 mm at ±3 mm, 1 cm at ±3 cm); the time
    is said, and when it is hours a wand survey is proposed."""
    from vlpcal.survey import plan_survey

    dep = Deployment("line", 2.3, [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]],
                     [paper_camera(f"C{k + 1}", (x, 0.9, 2.3)) for k, x in
                      enumerate((0.6, 1.8, 3.0))])
    for tape, mark in ((0.003, 0.001), (0.03, 0.01)):
        plan = plan_survey(dep, step=0.1234, tape=tape)
        assert np.allclose(plan.xyz / mark, np.round(plan.xyz / mark), atol=1e-6)
        assert not np.allclose(plan.xyz / mark / 10, np.round(plan.xyz / mark / 10), atol=1e-6)
    save(dep, tmp_path / "d.yaml")
    for step, hours in (("0.5", False), ("0.1", True)):
        out = tmp_path / f"s{step}.csv"
        res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"),
                                        "--step", step, "--out", str(out)])
        assert res.exit_code == 0, res.output
        minutes = len(out.read_text().splitlines()) - 1
        said = next(line for line in res.output.splitlines() if line.startswith("time:"))
        assert (f"{minutes / 60:.1f} h" if minutes >= 90 else f"{minutes} min") in said
        assert ("a wand survey needs no tape" in said) == hours


def test_vlpcal_plan_says_whether_a_free_survey_links_its_layout(tmp_path):
    from pathlib import Path

    site = Path(__file__).parent.parent / "layouts" / "paper-linear.site.yaml"
    res = CliRunner().invoke(main, ["plan", "--site", str(site), "--out",
                                    str(tmp_path / "p.yaml"), "-q"])
    assert res.exit_code == 0, res.output
    line = res.output.strip().splitlines()[-1]
    assert line.startswith("free survey (vlpcal survey plan --free): a free LED swept from 0 "
                           "to 0.92 m links all ")


def test_the_map_labels_do_not_collide(tmp_path):
    """The plan's map: references, stops, cameras, unlinked cameras and where another camera
    would go, every label clear of the others."""
    from vlpcal.reports import survey_plan_figure

    for dep in (issue_office(), apart()):
        plan, route = plan_references(dep), free_route(dep)
        boxes = survey_plan_figure(tmp_path / f"{dep.name}.png", dep, plan, route)
        assert len(boxes) >= len(plan.ids) + len(route.stops) + len(dep.cameras)
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                assert not a.overlaps(b), (a, b)


def test_a_plan_never_replaces_a_surveys_measured_points(tmp_path):
    """From a hostile probe: `survey plan -o bundle/points.csv` wrote the plan over the
    measurements of a survey bundle."""
    dep = issue_office()
    save(dep, tmp_path / "d.yaml")
    bundle = tmp_path / "survey"
    (bundle / "frames" / "P1").mkdir(parents=True)
    record = "point_id,x,y,z\nP1,1.002,2.001,0\n"
    (bundle / "points.csv").write_text(record)
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--wand",
                                    "0.5", "--out", str(bundle / "points.csv")])
    assert res.exit_code == 2 and "is a survey's record (it has frames beside it)" in res.output
    assert (bundle / "points.csv").read_text() == record
    (tmp_path / "link.csv").symlink_to(bundle / "points.csv")  # through a link, too
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--wand",
                                    "0.5", "--out", str(tmp_path / "link.csv")])
    assert res.exit_code == 2 and "is a survey's record" in res.output, res.output
    assert (bundle / "points.csv").read_text() == record


def test_a_wand_longer_than_the_room_is_refused_before_planning(tmp_path):
    """From a hostile probe: `survey plan --wand 50` planned a survey that `survey calibrate`
    then refuses (a length in the wrong unit)."""
    save(issue_office(), tmp_path / "d.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--wand",
                                    "50", "--out", str(tmp_path / "marks.csv")])
    assert res.exit_code == 2 and "--wand 50: longer than the room" in res.output, res.output
    assert not (tmp_path / "marks.csv").exists()


def test_frame_marks_are_the_same_along_y_far_from_the_origin_and_in_a_hall():
    """From a hostile probe: a room long along y was refused ("the floor places … lie on one
    line": X was scored by its y, which is its distance along y there), and so was the same
    room 1000 m from the plan's origin (the error model in absolute coordinates). The marks
    now follow the room: turned with it, moved with it."""
    ys = (1.2, 1.8, 2.4, 3.0, 3.6)

    def room(w, h, dx=0.0):
        return [[dx, 0], [dx + w, 0], [dx + w, h], [dx, h]]

    along_x = Deployment("x", 2.3, room(4.8, 1.8),
                         [cam(f"C{k + 1}", y, 0.9, 2.3) for k, y in enumerate(ys)])
    along_y = Deployment("y", 2.3, [[y, x] for x, y in room(4.8, 1.8)],
                         [cam(f"C{k + 1}", 0.9, y, 2.3, 90.0) for k, y in enumerate(ys)])
    far = Deployment("far", 2.3, room(4.8, 1.8, 1000.0),
                     [cam(f"C{k + 1}", 1000.0 + y, 0.9, 2.3) for k, y in enumerate(ys)])
    mx, my, mf = plan_marks(along_x), plan_marks(along_y), plan_marks(far)
    assert mx.axis == "x" and my.axis == "y"
    assert np.allclose(my.xyz[:, [1, 0]], mx.xyz[:, :2], atol=0.05), (mx.xyz, my.xyz)
    assert np.allclose(mf.xyz[:, 0] - 1000.0, mx.xyz[:, 0], atol=0.05), (mx.xyz, mf.xyz)
    # the same cameras in a 100 × 50 m hall: they were lost between the points of a grid
    # over the whole hall ("too few places … seen by two cameras")
    hall = Deployment("hall", 2.3, room(100.0, 50.0), along_x.cameras)
    assert np.allclose(plan_marks(hall).xyz, mx.xyz, atol=0.05), (mx.xyz, plan_marks(hall).xyz)
