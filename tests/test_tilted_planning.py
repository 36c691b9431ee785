"""Tilted cameras and obstacles: the site's mounting and obstacle keys, obstacles' shadows in
the reference model, and the CasADi optimiser on `vlpcal plan`'s default path."""

import copy
import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.planning import SiteError, evaluate, grid_cameras, load_site, site_from_dict
from vlpcal.planning.poses import ANGLE_STEP, pose_of, posed_cameras, snapped, tilts
from vlpcal.planning.reference import unobstructed
from vlpcal.planning.site import Obstacle

C160 = {"width": 160, "height": 120, "fx": 153.3, "fy": 153.3, "cx": 79.5, "cy": 59.5,
        "dist": [0, 0, 0, 0, 0]}
#: a bay: 6 × 3.6 m at 2.8 m, LED 0–0.5 m, two cameras over 95 %, p95 ≤ 2 cm
BAY = {"format": "vlpcal-site", "version": 1,
       "site": {"name": "bay", "ceiling_height": 2.8,
                "room": [[0, 0], [6, 0], [6, 3.6], [0, 3.6]]},
       "camera": C160,
       "requirements": {"heights": [0.0, 0.5], "min_cameras": 2, "coverage": 0.95,
                        "max_error_p95": 0.02, "pixel_noise": 0.3},
       "mounting": {"max_tilt": 30}}


@pytest.mark.parametrize("path,value,fragment", [
    (["mounting", "max_tilt"], 80, "mounting.max_tilt: expected 0 to 75° (from straight down)"),
    (["mounting", "max_tilt"], "30", "mounting.max_tilt: expected a number"),
    (["mounting", "tilt"], 30, "mounting.tilt: unknown key (expected max_tilt, "
                               "wall_clearance)"),
    (["mounting", "wall_clearance"], 2.0, "leaves no ceiling to hang a camera from"),
    (["site", "keep_out"], [{"polygon": [[1, 1], [2, 1], [2, 2], [1, 2]], "height": -1}],
     "site.keep_out[0].height: expected 0 to 2.8 m"),
    (["site", "keep_out"], [{"height": 1.0}], "site.keep_out[0].polygon: missing"),
    (["camera"], {"width": 160, "height": 120, "fx": 153.3},
     "camera.fy: missing (and cx, cy, dist; a camera needs width, height, fx, fy, cx, cy, "
     "dist)"),
    (["site", "keep_out"], [{"polygon": [[1, 1], [2, 1], [2, 2], [1, 2]], "hight": 1}],
     "site.keep_out[0].hight: unknown key (expected polygon, height)"),
])
def test_malformed_mounting_and_obstacles_name_the_key(path, value, fragment):
    doc = copy.deepcopy(BAY)
    node = doc
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value
    with pytest.raises(SiteError) as err:
        site_from_dict(doc, "s.yaml")
    assert str(err.value).startswith("s.yaml: ") and fragment in str(err.value)


def test_obstacles_are_keep_out_areas_that_also_hide():
    doc = copy.deepcopy(BAY)
    pillar = [[2.8, 1.6], [3.2, 1.6], [3.2, 2.0], [2.8, 2.0]]
    doc["site"]["keep_out"] = [{"polygon": pillar, "height": 2.0}, [[0, 0], [0.5, 0], [0.5, 0.5]]]
    site = site_from_dict(doc)
    assert site.keep_out == [pillar, [[0, 0], [0.5, 0], [0.5, 0.5]]]
    assert site.obstacles == [Obstacle(pillar, 2.0)]
    assert site.mounting.max_tilt == pytest.approx(math.radians(30))


def test_a_segment_through_an_obstacle_is_hidden_and_one_over_it_is_not():
    box = [Obstacle([[1, 1], [2, 1], [2, 2], [1, 2]], 1.0)]
    camera = (3.5, 1.5, 3.0)
    points = np.array([[0.5, 1.5, 0.0],   # behind the box: the ray crosses it below 1 m
                       [3.0, 1.5, 0.0],   # in the open
                       [0.5, 1.5, 1.5],   # above the box's top
                       [0.5, 1.5, 0.9],   # rises past 1 m before it reaches the box
                       [1.5, 3.0, 0.0]])  # beside it
    assert unobstructed(camera, points, box).tolist() == [False, True, True, True, True]


def test_the_reference_model_counts_obstacles_shadows():
    """A tall shelf under a 6 × 2 grid: the same floor is served, but the shelf's shadows
    take views away and the layout is judged worse for it."""
    doc = copy.deepcopy(BAY)
    del doc["mounting"]
    open_floor = site_from_dict(doc)
    cams = grid_cameras(open_floor, "square", 6, 2, (1.2, 1.7), (0.3, 0.95))
    shelf = [[2.0, 1.7], [4.0, 1.7], [4.0, 1.9], [2.0, 1.9]]
    doc["site"]["keep_out"] = [shelf]
    flat = evaluate(site_from_dict(doc), cams)
    doc["site"]["keep_out"] = [{"polygon": shelf, "height": 1.8}]
    tall = evaluate(site_from_dict(doc), cams)
    assert np.array_equal(flat.points, tall.points)  # the same floor is served
    assert (tall.views <= flat.views).all() and (tall.views < flat.views).sum() > 50
    assert (tall.coverage, -tall.p95) < (flat.coverage, -flat.p95)


@settings(max_examples=40, deadline=None)
@given(st.floats(-10, 10), st.floats(-10, 10), st.floats(-math.pi, math.pi),
       st.floats(0, math.radians(75)), st.floats(-math.pi, math.pi))
def test_a_pose_survives_the_round_trip_through_a_camera(x, y, yaw, tilt, direction):
    site = site_from_dict(BAY)
    pose = np.array([x, y, yaw, tilt * math.cos(direction), tilt * math.sin(direction)])
    cam = posed_cameras(site, [pose])[0]
    again = posed_cameras(site, [pose_of(cam)])[0]
    assert np.allclose(again.R, cam.R, atol=1e-9)
    leaning = math.atan2(math.hypot(cam.axis[0], cam.axis[1]), -cam.axis[2])
    assert leaning == pytest.approx(tilt, abs=1e-9)


def test_snapped_poses_are_what_a_bracket_sets():
    p = snapped([[1.234, 0.07, 0.31, 0.3, -0.4]], 0.1, math.radians(30))
    assert p[0, :2] == pytest.approx([1.2, 0.1])
    for angle in (p[0, 2], tilts(p)[0], math.atan2(p[0, 4], p[0, 3])):
        assert angle / ANGLE_STEP == pytest.approx(round(angle / ANGLE_STEP), abs=1e-9)
    assert tilts(p)[0] <= math.radians(30) + 1e-12


def test_tilting_plans_the_bay_with_at_most_nine_cameras(tmp_path):
    """The bay: 12 level cameras; tilted up to 30° the optimiser's plan needs ≤ 9,
    on the mounting grid, within the tilt, and `vlpcal check` accepts what it exports."""
    (tmp_path / "bay.yaml").write_text(yaml.safe_dump(BAY))
    out = tmp_path / "plan.yaml"
    res = CliRunner().invoke(main, ["plan", "--site", str(tmp_path / "bay.yaml"), "--out",
                                    str(out)])
    assert res.exit_code == 0, res.output
    assert "CasADi optimiser:" in res.output and " solves, " in res.output
    dep = deployment.load(out)
    assert len(dep.cameras) <= 9
    assert dep.extra["provenance"]["plan"]["family"] == "tilted"
    assert dep.extra["provenance"]["plan"]["started_from"] in ("square", "triangular",
                                                               "linear", "free")
    site = load_site(tmp_path / "bay.yaml")
    assert evaluate(site, dep.cameras).meets
    poses = np.array([pose_of(c) for c in dep.cameras])
    assert (tilts(poses) <= math.radians(30) + 1e-9).all() and tilts(poses).max() > 0
    assert np.allclose(poses[:, :2] / 0.1, np.rint(poses[:, :2] / 0.1), atol=1e-6)
    assert ((poses[:, :2] >= 0) & (poses[:, :2] <= (6, 3.6))).all()
    # how to hang each camera: the lines an installer follows give each camera's lean
    hang = [x for x in res.output.splitlines() if " m: turn " in x]
    assert len(hang) == len(dep.cameras)
    for line, cam in zip(hang, dep.cameras):
        assert line.split()[0] == cam.id
        if "toward" not in line:  # a level camera
            assert cam.axis[2] < -math.cos(math.radians(0.5))
            continue
        toward = float(line.rsplit("toward", 1)[1].strip(" °"))
        lean = math.degrees(math.atan2(cam.axis[1], cam.axis[0]))
        assert abs((toward - lean + 180) % 360 - 180) < 0.5 + 1e-6
    res = CliRunner().invoke(main, ["check", "--site", str(tmp_path / "bay.yaml"), "-d",
                                    str(out)])
    assert res.exit_code == 0 and "meets the site" in res.output


def test_a_level_site_is_told_what_tilting_would_save(tmp_path):
    doc = copy.deepcopy(BAY)
    del doc["mounting"]
    doc["site"]["room"] = [[0, 0], [4, 0], [4, 3], [0, 3]]
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(main, ["plan", "-q", "--site", str(tmp_path / "s.yaml"),
                                    "--out", str(tmp_path / "p.yaml")])
    assert res.exit_code == 0, res.output
    dep = deployment.load(tmp_path / "p.yaml")
    level = len(dep.cameras)
    assert all(math.isclose(-c.axis[2], 1.0) for c in dep.cameras)  # the plan stays level
    line = next(x for x in res.output.splitlines() if x.startswith("with tilt up to 30°"))
    fewer = int(line.split(": ")[1].split()[0])
    assert fewer < level and f"instead of {level}" in line and "tilting brackets" in line


def test_wall_clearance_keeps_tilted_cameras_off_the_walls(tmp_path):
    doc = copy.deepcopy(BAY)
    doc["site"]["room"] = [[0, 0], [4, 0], [4, 3], [0, 3]]
    doc["mounting"] = {"max_tilt": 30, "wall_clearance": 0.3}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(main, ["plan", "-q", "--site", str(tmp_path / "s.yaml"),
                                    "--out", str(tmp_path / "p.yaml")])
    assert res.exit_code == 0, res.output
    xy = np.array([c.position[:2] for c in deployment.load(tmp_path / "p.yaml").cameras])
    assert (xy >= 0.3 - 1e-9).all() and (xy <= np.array([3.7, 2.7]) + 1e-9).all()
    assert evaluate(load_site(tmp_path / "s.yaml"),
                    deployment.load(tmp_path / "p.yaml").cameras).meets


def test_a_room_with_a_pillar_and_a_shelf_plans_a_layout_that_meets_in_their_shadows(tmp_path):
    """No lattice meets once a pillar and a tall shelf hide the floor behind them (the
    lattice search does not see shadows): the optimiser mends the best lattice into a layout
    that meets with the shadows counted, and `vlpcal check` agrees."""
    doc = copy.deepcopy(BAY)
    doc["site"] = {"name": "pillar and shelf", "ceiling_height": 3.0,
                   "room": [[0, 0], [7, 0], [7, 4.5], [0, 4.5]],
                   "keep_out": [{"polygon": [[3.25, 2.0], [3.75, 2.0], [3.75, 2.5],
                                             [3.25, 2.5]], "height": 3.0},
                                {"polygon": [[0.5, 4.1], [2.5, 4.1], [2.5, 4.5], [0.5, 4.5]],
                                 "height": 1.8}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(main, ["plan", "-q", "--site", str(tmp_path / "s.yaml"),
                                    "--out", str(tmp_path / "p.yaml")])
    assert res.exit_code == 0, res.output
    assert "fails the reference model" in res.output and "the optimiser mended" in res.output
    site = load_site(tmp_path / "s.yaml")
    cams = deployment.load(tmp_path / "p.yaml").cameras
    shaded = evaluate(site, cams)
    assert shaded.meets
    res = CliRunner().invoke(main, ["check", "--site", str(tmp_path / "s.yaml"), "-d",
                                    str(tmp_path / "p.yaml")])
    assert res.exit_code == 0 and "meets the site" in res.output


def test_a_tilted_plan_is_hung_surveyed_by_tape_and_tracks_within_what_it_predicted(tmp_path):
    """End to end: a tilted plan → `simulate -d` (hung with a careful install's
    errors) → the tape survey → `locate` of test frames and `track` of a robot, both within
    the plan's predicted mean error (at its 0.3 px spot noise) and within 3 × the true
    cameras on the same frames."""
    import csv

    doc = copy.deepcopy(BAY)
    doc["site"]["room"] = [[0, 0], [4, 0], [4, 2.4], [0, 2.4]]
    doc["requirements"]["coverage"] = 0.9
    doc["requirements"]["max_error_p95"] = 0.03
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))

    def cli(*args):
        res = CliRunner().invoke(main, [str(a) for a in args])
        assert res.exit_code == 0, res.output
        return res.output

    cli("plan", "-q", "--site", tmp_path / "s.yaml", "--out", tmp_path / "p.yaml")
    plan = deployment.load(tmp_path / "p.yaml")
    assert tilts(np.array([pose_of(c) for c in plan.cameras])).max() > 0
    predicted = plan.extra["provenance"]["predicted"]["mean_error_m"]
    sim = tmp_path / "sim"
    cli("simulate", "-d", tmp_path / "p.yaml", "--survey-step", "0.4", "--test-points", 30,
        "--robot-speed", "1", "--seconds", "2", "--out", sim)
    cli("survey", "calibrate", "-d", sim / "nominal.yaml", "--survey", sim / "survey",
        "--out", sim / "cal.yaml", "-q")
    truth = {r["frame_id"]: r for r in csv.DictReader((sim / "frames.truth.csv").open())}

    def located(dep):
        cli("locate", "-d", dep, "--frames", sim / "frames", "--out", sim / f"{dep.stem}.csv",
            "-q")
        rows = [r for r in csv.DictReader((sim / f"{dep.stem}.csv").open())
                if r["status"] == "ok"]
        return np.mean([np.linalg.norm([float(r[a]) - float(truth[r["frame_id"]][a])
                                        for a in "xyz"]) for r in rows]), len(rows)

    calibrated, n_cal = located(sim / "cal.yaml")
    exact, n_true = located(sim / "truth.yaml")
    assert n_cal >= n_true >= 20
    assert calibrated <= predicted and calibrated <= 3 * exact, (calibrated, exact, predicted)
    cli("track", "-d", sim / "cal.yaml", "--frames", sim / "streams", "--out",
        sim / "tracks.csv")
    rows = np.genfromtxt(sim / "tracks.csv", delimiter=",", names=True, dtype=None,
                         encoding="utf-8")
    moving = np.genfromtxt(sim / "streams.truth.csv", delimiter=",", names=True, dtype=None,
                           encoding="utf-8")
    ok = rows["status"] == "ok"
    assert ok.mean() > 0.8
    order = np.argsort(moving["t"])
    true_at = np.stack([np.interp(rows["t"][ok], moving["t"][order], moving[c][order])
                        for c in "xyz"], -1)
    err = np.linalg.norm(np.stack([rows[c][ok] for c in "xyz"], -1) - true_at, axis=1)
    assert np.median(err) <= predicted, (np.median(err), predicted)


def test_an_interrupt_inside_the_optimiser_is_raised_not_counted_as_a_failed_solve():
    """From a hostile probe: Ctrl-C (or SIGTERM, which the CLI turns into the same) while
    IPOPT ran ended that solve as one that "does not meet", and the plan went on to
    overwrite its output with exit 0. The signal reaches Python in the iteration callback."""
    from vlpcal.planning.optimiser import PoseProblem, optimiser_points

    site = site_from_dict(BAY)
    pts = optimiser_points(site)
    start = np.array([[1.5, 1.0, 0, 0, 0], [4.5, 1.0, 0, 0, 0], [3.0, 2.6, 0, 0, 0]])

    def judge(poses):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        PoseProblem(site, 3, pts).solve(start, (0, 0, 6, 3.6), math.radians(30), judge)


def test_a_narrow_ceiling_where_no_level_lattice_meets_is_planned_tilted(tmp_path):
    """From a hostile probe: 0.7 m of wall clearance in a 3.6 × 1.8 m room leaves a strip
    where no level lattice meets; tilted cameras do, and the plan finds them (and a
    --max-cameras under the level count is no reason to give up)."""
    doc = copy.deepcopy(BAY)
    doc["site"] = {"name": "strip", "ceiling_height": 2.3,
                   "room": [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]}
    doc["requirements"]["heights"] = [0.0, 0.7]
    doc["mounting"] = {"max_tilt": 30, "wall_clearance": 0.7}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(main, ["plan", "-q", "--site", str(tmp_path / "s.yaml"),
                                    "--out", str(tmp_path / "p.yaml")])
    assert res.exit_code == 0, res.output
    cams = deployment.load(tmp_path / "p.yaml").cameras
    assert evaluate(load_site(tmp_path / "s.yaml"), cams).meets
    xy = np.array([c.position[:2] for c in cams])
    assert (xy >= 0.7 - 1e-9).all() and (xy <= np.array([2.9, 1.1]) + 1e-9).all()


def test_check_names_what_the_sites_mounting_does_not_allow(tmp_path):
    doc = copy.deepcopy(BAY)
    doc["mounting"] = {"max_tilt": 10, "wall_clearance": 0.5}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    site = load_site(tmp_path / "s.yaml")
    cams = posed_cameras(site, [[0.3, 1.8, 0, 0.0, -math.radians(25)],
                                [3.0, 1.8, 0, 0, 0], [3.0, 1.8, 0, 0.1, 0]])
    dep = deployment.Deployment("bay", 2.8, BAY["site"]["room"], cams)
    (tmp_path / "d.yaml").write_text(deployment.dumps(dep))
    res = CliRunner().invoke(main, ["check", "--site", str(tmp_path / "s.yaml"), "-d",
                                    str(tmp_path / "d.yaml")])
    assert res.exit_code == 1, res.output
    assert "C1 (25.0°) tilt past the site's max_tilt (10°)" in res.output
    assert "C1 (0.30 m) hang closer to a wall than the site's wall_clearance (0.5 m)" \
        in res.output
    assert "outside the room" not in res.output
    # C2 and C3 hang at one place: what only they see cannot be triangulated
    assert "p95 unbounded" in res.output and "nan" not in res.output
