"""vlpcal simulate -d: any deployment simulated (issue 26), and a wand's free survey."""

import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner
from shapely import contains_xy
from shapely.geometry import Polygon

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.datasets import read_frames_folder, read_survey_bundle
from vlpcal.demo import DEMO_ERRORS
from vlpcal.detection import detect_several
from vlpcal.geometry import NADIR, Camera
from vlpcal.sim.profiles import get_profile, profile_of_deployment
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import (
    grid_points,
    longest_wand,
    simulate_free_survey,
    wand_fits,
    wand_path,
)

ROOM = [[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]]
KEEP_OUT = [[2.6, 1.6], [3.4, 1.6], [3.4, 2.4], [2.6, 2.4]]  # a pillar in the middle


def level_grid(nx=3, ny=2, width=160, room=ROOM, keep_out=(KEEP_OUT,), height=2.5,
               name="six"):
    """A level grid of cameras over ``room``'s bounding box, as a user's deployment."""
    xs, ys = np.array(room).T
    f = 153.3 * width / 160
    cams = [Camera(f"C{j * nx + i + 1}", width, width * 3 // 4, f, f, (width - 1) / 2,
                   (width * 3 // 4 - 1) / 2, (0,) * 5,
                   (xs.min() + (i + 0.5) * np.ptp(xs) / nx,
                    ys.min() + (j + 0.5) * np.ptp(ys) / ny, height), NADIR)
            for j in range(ny) for i in range(nx)]
    return deployment.Deployment(name, height, [list(p) for p in room], cams,
                                 [list(map(list, k)) for k in keep_out])


@pytest.fixture
def six(tmp_path):
    path = tmp_path / "six.yaml"
    deployment.save(level_grid(), path)
    return path


def run(*args):
    return CliRunner().invoke(main, ["simulate", *map(str, args)])


def test_a_deployment_becomes_a_profile_hung_with_a_careful_install():
    dep = level_grid()
    p = profile_of_deployment(dep, DEMO_ERRORS)
    assert p.nominal == tuple(dep.cameras) and p.ceiling_height == 2.5
    assert p.keep_out == (tuple(map(tuple, KEEP_OUT)),)
    assert p.errors.position == DEMO_ERRORS.position and p.errors.tilt == DEMO_ERRORS.tilt
    # the paper's look for its 160 px cameras, its LED as bright under cameras 2.5 m up
    assert p.look.psf_sigma == get_profile("paper-2024").look.psf_sigma
    assert p.look.reference_distance == pytest.approx(2.5)
    assert "paper-2024's" in p.sources["look"]
    wide = profile_of_deployment(level_grid(width=640), DEMO_ERRORS)
    assert wide.look.psf_sigma == get_profile("qvga").look.psf_sigma
    assert "qvga's" in wide.sources["look"]
    assert wide.errors.principal == pytest.approx(4 * DEMO_ERRORS.principal)  # 640 px wide


def test_simulate_d_writes_every_folder_around_the_keep_out(six, tmp_path):
    out = tmp_path / "sim"
    res = run("-d", six, "--out", out, "--survey-step", "0.5", "--test-points", "6",
              "--free-sets", "40", "--robot-speed", "1", "--seconds", "0.3", "--seed", "3")
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == {
        "nominal.yaml", "truth.yaml", "survey", "frames", "frames.truth.csv", "free-survey",
        "free-survey.truth.csv", "streams", "streams.truth.csv"}
    assert "6 cameras hung with a careful install by hand" in res.output
    assert "paper-2024's" in res.output
    nominal, truth = deployment.load(out / "nominal.yaml"), deployment.load(out / "truth.yaml")
    mine = deployment.load(six)
    assert nominal.cameras == mine.cameras and nominal.keep_out == mine.keep_out
    assert truth.room == mine.room and truth.keep_out == mine.keep_out
    # the cameras as hung: off by a careful install's amounts (1 sigma 5 mm, 0.2°), not more
    moved = [np.linalg.norm(np.subtract(t.position, n.position))
             for t, n in zip(truth.cameras, nominal.cameras)]
    tilt = [math.degrees(math.acos(min(1.0, t.axis @ n.axis)))
            for t, n in zip(truth.cameras, nominal.cameras)]
    assert 0 < min(moved) and max(moved) < 0.04
    assert 0 < min(tilt) and max(tilt) < 1.5
    assert all(-0.07 < t.dist[0] < 0.03 and t.dist[0] != 0 for t in truth.cameras)
    assert all(abs(t.fx / n.fx - 1) < 0.05 for t, n in zip(truth.cameras, nominal.cameras))
    # no survey point, test point or free position in the pillar
    pillar = Polygon(KEEP_OUT)
    bundle = read_survey_bundle(out / "survey")
    assert len(bundle.point_ids) > 100 and len(bundle.frames) > 100
    assert not contains_xy(pillar, *bundle.xyz[:, :2].T).any()
    test = np.loadtxt(out / "frames.truth.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
    assert len(test) == 6 and not contains_xy(pillar, *test[:, :2].T).any()
    assert len(read_frames_folder(out / "frames").files) == 6 * 6
    free = np.loadtxt(out / "free-survey.truth.csv", delimiter=",", skiprows=1,
                      usecols=(2, 3, 4))
    assert len(free) == 40 and not contains_xy(pillar.buffer(0.05), *free[:, :2].T).any()
    assert (out / "free-survey" / "free" / "frames").is_dir()
    assert (out / "streams" / "times.csv").is_file()
    # --describe says where each value comes from
    said = run("-d", six, "--describe")
    assert said.exit_code == 0 and "install errors: a careful install" in said.output
    # --overwrite replaces every file simulate wrote, the free survey's truth included
    again = run("-d", six, "--out", out, "--overwrite", "--survey-step", "1", "--test-points", 1)
    assert again.exit_code == 0, again.output
    assert not (out / "free-survey.truth.csv").exists()


def test_survey_frames_follow_the_sightings_not_cameras_times_points():
    """24 cameras: a frame is rendered only where a camera sees the LED — bytes identical to a
    full render, and the work proportional to the sightings."""
    big = level_grid(6, 4, room=[[0, 0], [12, 0], [12, 8], [0, 8]],
                     keep_out=([[5, 3], [7, 3], [7, 5], [5, 5]],))
    scene = make_scene(profile_of_deployment(big, DEMO_ERRORS), 1)
    pts = grid_points(scene, 0.6, [0.0, 0.7])
    some, seen = render_scene(scene, pts, seed=2, only_seen=True)
    rendered = sum(f is not None for jpegs in some.values() for f in jpegs)
    assert rendered == seen.sum() < len(pts) * 24 / 8
    few = pts[:25]
    full, _ = render_scene(scene, few, seed=2)
    part, _ = render_scene(scene, few, seed=2, only_seen=True)
    for k, cid in enumerate(full):
        assert [b is not None for b in part[cid]] == list(seen[k, :25])
        assert all(b is None or a == b for a, b in zip(full[cid], part[cid]))
    assert 0 < seen[:, :25].sum() < 25 * 24 / 4


def test_a_wand_shows_both_leds_a_fixed_length_apart(tmp_path):
    scene = make_scene(profile_of_deployment(level_grid(), DEMO_ERRORS), 2)
    refs = [[1.0, 1.0, 0.0], [5.0, 3.0, 0.5], [3.0, 1.0, 0.9]]
    measured, path = simulate_free_survey(scene, tmp_path / "fs", refs, 60, seed=1,
                                          wand=0.6, truth=tmp_path / "fs.truth.csv")
    assert measured.shape == (3, 3) and path.shape == (60, 2, 3)
    assert np.allclose(np.linalg.norm(path[:, 0] - path[:, 1], axis=1), 0.6, atol=1e-9)
    rows = list(csv.reader(open(tmp_path / "fs.truth.csv")))
    assert rows[0] == ["set_id", "led", "x", "y", "z"] and len(rows) == 1 + 120
    assert rows[1][:2] == ["F00001", "A"] and rows[2][:2] == ["F00001", "B"]
    assert np.allclose([float(v) for v in rows[2][2:]], path[0, 1], atol=1e-8)
    bundle = read_survey_bundle(tmp_path / "fs")
    assert bundle.free_frames
    both = one = 0
    for (sid, cid), f in sorted(bundle.free_frames.items()):
        X = path[int(sid[1:]) - 1]
        uv, _, inside = scene.true[[c.id for c in scene.true].index(cid)].project(X)
        away = (uv[:, 0] > 5) & (uv[:, 0] < 154) & (uv[:, 1] > 5) & (uv[:, 1] < 114)
        if not (inside == away).all() or np.hypot(*(uv[0] - uv[1])) < 8:
            continue  # near the edge, or the two spots touch: not this test's business
        got = detect_several([f.read_bytes()], 2)[0]
        found = np.isfinite(got[:, 0]).sum()
        assert found == inside.sum(), (sid, cid)
        for p in uv[inside]:
            assert np.nanmin(np.hypot(*(got - p).T)) < 0.5
        both += inside.all()
        one += inside.sum() == 1
    assert both >= 5 and one >= 3


def test_a_wand_is_waved_smoothly_over_the_sphere_inside_the_room():
    p = profile_of_deployment(level_grid(), DEMO_ERRORS)
    scene = make_scene(p, 0)
    X = wand_path(scene, 1800, 0.8, seed=4)
    top = 0.4 * p.ceiling_height
    assert X[..., 2].min() >= -1e-9 and X[..., 2].max() <= top + 1e-9
    ends = X.reshape(-1, 3)[:, :2]
    room = Polygon(ROOM).buffer(-0.099)
    assert contains_xy(room, *ends.T).all()
    assert not contains_xy(Polygon(KEEP_OUT), *ends.T).any()
    d = (X[:, 1] - X[:, 0]) / 0.8
    # every way up and round: up and down, all four quarters of the compass
    assert (d[:, 2] > 0.5).any() and (d[:, 2] < -0.5).any()
    quarters = np.floor((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (np.pi / 2)).astype(int)
    assert set(quarters) >= {0, 1, 2, 3}
    # smoothly: a tenth of a second apart (1800 sets in three minutes), a few degrees
    turn = np.degrees(np.arccos(np.clip((d[1:] * d[:-1]).sum(axis=1), -1, 1)))
    assert np.median(turn) < 8 and turn.max() < 30
    # a wand too long for the room (its centre 0.1 m + half its length from the walls and
    # half its length from the pillar): refused, saying the longest that fits
    assert wand_fits(p, 2.4) and not wand_fits(p, 2.7)
    assert 2.4 <= longest_wand(p) < 2.7
    with pytest.raises(ValueError, match="at most 2.5"):
        wand_path(scene, 10, 2.7)


def test_marks_leave_unmeasured_cells_empty_and_zeros_exact(tmp_path):
    """Frame marks (DESIGN.md): O,0,0,0, X,,0,0 and F1,,,0 as a person writes them; a taped
    reference with tape noise. Needs datasets.write_survey_bundle to write NaN as an empty
    cell (issue 26's frame marks)."""
    scene = make_scene(profile_of_deployment(level_grid(), DEMO_ERRORS), 0)
    refs = [[0.0, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.5]]
    measured = np.array([[1, 1, 1], [0, 1, 1], [0, 0, 1], [1, 1, 1]], bool)
    record, _ = simulate_free_survey(scene, tmp_path / "fs", refs, 20,
                                     marks=(["O", "X", "F1", "R1"], measured))
    lines = (tmp_path / "fs" / "points.csv").read_text().splitlines()
    assert lines[1:4] == ["O,0.0,0.0,0.0", "X,,0.0,0.0", "F1,,,0.0"]
    r1 = [float(v) for v in lines[4].split(",")[1:]]
    assert 0 < np.abs(np.subtract(r1, refs[3])).max() < 5 * scene.profile.tape
    assert np.isnan(record[1, 0]) and np.isnan(record[2, :2]).all()
    assert np.array_equal(record[:3][measured[:3]], np.zeros(6))
    with pytest.raises(ValueError, match="marks"):
        simulate_free_survey(scene, tmp_path / "bad", refs, 5,
                             marks=(["O", "X"], measured))
    none = measured.copy()
    none[3] = False
    with pytest.raises(ValueError, match="R1 has no measured coordinate"):
        simulate_free_survey(scene, tmp_path / "bad", refs, 5, marks=(["O", "X", "F1", "R1"],
                                                                      none))


@pytest.mark.parametrize("args, words", [
    (["--profile", "qvga", "-d", "{six}"], ["--profile", "-d", "not both"]),
    (["-d", "{tmp}/nope.yaml"], ["nope.yaml"]),
    (["-d", "{tmp}/bad.yaml"], ["bad.yaml", "cameras"]),
    (["-d", "{six}", "--wand", "0.5"], ["--wand", "--free-sets"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "0"], ["--wand", "above 0"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "-1"], ["--wand", "above 0"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "50"], ["--wand", "diagonal (7.21 m)"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "nan"], ["--wand", "finite"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "3.9"], ["--wand", "at most 2.5"]),
    (["-d", "{six}", "--free-sets", "5", "--wand", "0.5", "--free-height", "0.2"],
     ["--wand", "--free-height"]),
    (["-d", "{tmp}/one.yaml", "--free-sets", "5"], ["--free-sets", "seen by two cameras"]),
])
def test_refusals_are_one_line(six, tmp_path, args, words):
    (tmp_path / "bad.yaml").write_text("format: vlpcal-deployment\nversion: 1\n"
                                       "site: {name: x, ceiling_height: 2, room: "
                                       "[[0,0],[1,0],[1,1]]}\n")
    deployment.save(level_grid(1, 1, keep_out=()), tmp_path / "one.yaml")
    res = run(*[a.format(six=six, tmp=tmp_path) for a in args], "--out", tmp_path / "o")
    assert res.exit_code == 2, res.output
    assert res.output.count("\n") == 1 and "Traceback" not in res.output, res.output
    for w in words:
        assert w in res.output, res.output
    assert not (tmp_path / "o").exists()


def test_own_site_free_survey_walks_the_planned_route_and_links_every_camera(tmp_path):
    """From a newcomer's walk: 12 level cameras as vlpcal plan laid them over a 6 × 4 m office
    (two rows whose views meet in a strip ~20 cm wide at the floor). The plan says a free LED
    links them all; the simulated surveyor carries it along that plan's route, so every camera
    is linked by shared sightings, each stop swept between the route's foot and its top."""
    from vlpcal.sim.writers import deployment_of, route_path
    from vlpcal.survey import free_route
    from vlpcal.survey.free import MIN_SHARED
    from vlpcal.survey.linkage import _components

    cams = [Camera(f"C{j * 6 + i + 1}", 160, 120, 153.3, 153.3, 79.5, 59.5, (0,) * 5,
                   (1.2 * i, (1.0, 2.9)[j], 2.8), NADIR) for j in range(2) for i in range(6)]
    pillar = [[2.8, 1.8], [3.2, 1.8], [3.2, 2.2], [2.8, 2.2]]
    dep = deployment.Deployment("office", 2.8, ROOM, cams, [pillar])
    scene = make_scene(profile_of_deployment(dep, DEMO_ERRORS), 0)
    route = free_route(deployment_of(scene, "nominal"))
    assert route.linkage.all_linked
    path = route_path(scene, route, 1800)
    assert path.shape == (1800, 3)
    assert (path[:, 2] >= route.low - 1e-9).all() and (path[:, 2] <= route.tops.max() + 1e-9).all()
    assert np.ptp(path[:, 2]) > 0.8 * (route.high - route.low)  # swept, not carried level
    assert not contains_xy(Polygon(pillar), path[:, 0], path[:, 1]).any()
    seen = np.array([c.project(path, margin=2.0)[2] for c in scene.true])  # C×N, as installed
    shared = (seen[:, None] & seen[None]).sum(axis=2)
    assert len(_components(shared >= MIN_SHARED)) == 1
    # and the CLI says it walked the route
    deployment.save(dep, tmp_path / "office.yaml")
    out = run("-d", tmp_path / "office.yaml", "--free-sets", 600, "--test-points", 5,
              "--out", tmp_path / "o")
    assert out.exit_code == 0, out.output
    assert "along survey plan's route" in out.output
