"""Survey calibration: recovery from rough guesses, refusals, mis-measured points, the CLI."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.datasets import write_survey_bundle
from vlpcal.geometry import Camera, rodrigues, rotation_vector
from vlpcal.survey import SurveyError, calibrate, fit_camera

DEG = math.pi / 180


def look_at(cid, position, target, f=153.3, dist=(0, 0, 0, 0, 0), size=(160, 120)):
    """A camera at ``position`` looking at ``target`` (image-up roughly toward +z or +y)."""
    z = np.subtract(target, position)
    z = z / np.linalg.norm(z)
    up = np.array([0, 0, 1.0]) if abs(z[2]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    w, h = size
    return Camera(cid, w, h, f, f, (w - 1) / 2, (h - 1) / 2, dist, position, rotation_vector(R))


def nudge(cam, rng, move=0.05, turn=3 * DEG):
    """The camera as a rough plan would have it: ~5 cm and ~3° off."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R = cam.R @ rodrigues(axis * turn)
    d = rng.normal(size=3)
    return Camera(cam.id, cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, cam.dist,
                  np.add(cam.position, d / np.linalg.norm(d) * move), rotation_vector(R))


def observe(cams, X, rng, noise=0.05):
    uv = []
    for c in cams:
        p, _, inside = c.project(X)
        p = p + rng.normal(0, noise, p.shape)
        p[~inside] = np.nan
        uv.append(p)
    return np.stack(uv)


def survey_grid(heights=(0.0, 0.35, 0.7), x=(0.3, 3.3), y=(0.2, 1.6), step=0.2):
    gx, gy = np.meshgrid(np.arange(x[0], x[1] + 1e-9, step), np.arange(y[0], y[1] + 1e-9, step))
    return np.concatenate([np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, h)]
                           for h in heights])


def pose_error(a, b):
    dR = a.R @ b.R.T
    angle = math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
    return np.linalg.norm(np.subtract(a.position, b.position)), angle


def test_recovers_ceiling_cameras_from_a_guess_5cm_3deg_off(rng):
    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x + 0.1 * k, 0.85, 0.0),
                    dist=(-0.05, 0.01, 0, 0, 0)) for k, x in enumerate((1.2, 1.8, 2.4))]
    guess = [nudge(c, rng) for c in true]
    X = survey_grid()
    ids = [f"P{i}" for i in range(len(X))]
    measured = X + rng.normal(0, 0.002, X.shape)
    cal = calibrate(guess, measured, observe(true, X, rng), ids, intrinsics=True)
    for got, want in zip(cal.cameras, true):
        moved, turned = pose_error(got, want)
        # with the lens free, a fraction of a degree of tilt trades against the principal
        # point (the same pixels); what matters is where fixes land, checked below
        assert moved < 0.01 and turned < 0.5
        assert got.dist[0] == pytest.approx(-0.05, abs=0.02)
    assert cal.mismeasured == []
    from vlpcal.fusion import fuse

    test = survey_grid(heights=(0.15, 0.5), step=0.23) + [0.05, 0.05, 0.0]
    uv = observe(true, test, rng, noise=0.0)
    err = np.linalg.norm(fuse(cal.cameras, uv, "all").X - test, axis=1)
    assert np.nanmean(err) < 0.003 and np.isfinite(err).mean() > 0.5


def test_cameras_facing_each_other_across_the_volume(rng):
    """Wall cameras looking at each other over the floor, not down: still calibrated."""
    centre = (2.0, 1.5, 0.4)
    true = [look_at("W1", (0.0, 1.5, 2.0), centre, f=120), look_at("W2", (4.0, 1.5, 2.0),
                                                                      centre, f=120),
            look_at("W3", (2.0, -0.5, 2.2), centre, f=120)]
    guess = [nudge(c, rng) for c in true]
    X = survey_grid(x=(1.0, 3.0), y=(0.6, 2.4), step=0.25)
    ids = [f"P{i}" for i in range(len(X))]
    cal = calibrate(guess, X, observe(true, X, rng), ids)
    for got, want in zip(cal.cameras, true):
        moved, turned = pose_error(got, want)
        assert moved < 0.01 and turned < 0.1


def test_mis_measured_point_is_reported_by_id(rng):
    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x, 0.9, 0.0)) for k, x in
            enumerate((1.2, 1.8, 2.4))]
    X = survey_grid()
    ids = [f"P{i:03d}" for i in range(len(X))]
    uv = observe(true, X, rng)
    seen3 = np.flatnonzero(np.isfinite(uv).all(axis=2).sum(axis=0) == 3)
    wrong = int(seen3[len(seen3) // 2])
    measured = X.copy()
    measured[wrong, 0] += 0.06  # a 6 cm misreading of the tape
    cal = calibrate(true, measured, uv, ids)
    assert [pid for pid, _ in cal.mismeasured] == [ids[wrong]]
    assert cal.mismeasured[0][1] == pytest.approx(0.06, abs=0.005)  # how far off the record is
    for got, want in zip(cal.cameras, true):
        assert pose_error(got, want)[0] < 0.01  # the bad point did not drag the cameras


def test_refusals_say_which_camera_and_why(rng):
    cams = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x, 0.9, 0.0)) for k, x in
            enumerate((1.2, 1.8, 2.4))]
    floor = survey_grid(heights=(0.0,))
    ids = [f"P{i}" for i in range(len(floor))]
    with pytest.raises(SurveyError, match="camera C1: cannot fit its lens .*all lie on one plane"):
        calibrate(cams, floor, observe(cams, floor, rng), ids, intrinsics=True)
    few = floor[:5]
    with pytest.raises(SurveyError, match="sees [0-5] survey points, needs at least 6"):
        fit_camera(cams[0], few, cams[0].project(few)[0], ids[:5])
    blind = observe(cams, floor, rng)
    blind[1] = np.nan
    with pytest.raises(SurveyError, match="camera C2: saw none of the"):
        calibrate(cams, floor, blind, ids)
    # a tape's precision written in millimetres (3 for 3 mm) passed as metres gave a
    # calibration worse than the nominal cameras, exit 0 (a hostile input)
    with pytest.raises(SurveyError, match=r"±3.0 m, .* a tenth of it: .*millimetres\?"):
        calibrate(cams, floor, observe(cams, floor, rng), ids, point_sigma=3.0)


def test_cli_calibrates_from_observations_alone_and_refuses_clearly(tmp_path, rng):
    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x + 0.05, 0.9, 0.0),
                    dist=(-0.04, 0, 0, 0, 0)) for k, x in enumerate((1.2, 1.8, 2.4))]
    nominal = [nudge(c, rng) for c in true]
    room = [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]
    dep = deployment.Deployment("lab", 2.3, room, nominal)
    deployment.save(dep, tmp_path / "nominal.yaml")
    X = survey_grid()
    ids = [f"S{i:03d}" for i in range(len(X))]
    uv = observe(true, X, rng)
    write_survey_bundle(tmp_path / "survey", ids, X + rng.normal(0, 0.002, X.shape),
                        observations={c.id: uv[k] for k, c in enumerate(true)})
    out = tmp_path / "calibrated.yaml"
    res = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(tmp_path / "nominal.yaml"),
                                    "--survey", str(tmp_path / "survey"), "--out", str(out),
                                    "--intrinsics", "-q"])
    assert res.exit_code == 0, res.output
    assert "held-out 3D error" in res.output
    cal = deployment.load(out)
    for got, want in zip(cal.cameras, true):
        assert pose_error(got, want)[0] < 0.01
    report = json.loads(out.with_suffix(".report.json").read_text())
    held = report["held_out_m"]
    assert held["calibrated, all-camera LS"]["mean"] < held["nominal, all-camera LS"]["mean"] / 3
    assert cal.fusion in ("mean", "nearest", "region", "robust") and cal.region_map is not None
    assert out.with_suffix(".png").is_file()
    assert cal.extra["provenance"]["command"] == "vlpcal survey calibrate"
    assert report["suspects"] == [] and "warning: point" not in res.output  # no false alarm
    # a floor-only survey cannot fit the lens: a refusal, not a bad calibration, no file
    write_survey_bundle(tmp_path / "floor", ids[:len(X) // 3], X[:len(X) // 3],
                        observations={c.id: uv[k, :len(X) // 3] for k, c in enumerate(true)})
    bad = tmp_path / "bad.yaml"
    res = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(tmp_path / "nominal.yaml"),
                                    "--survey", str(tmp_path / "floor"), "--out", str(bad),
                                    "--intrinsics", "-q"])
    assert res.exit_code == 2 and "cannot fit its lens" in res.output
    assert "survey at more heights" in res.output
    assert "Traceback" not in res.output and not bad.exists()
    # positions in millimetres read as metres: refused, named by point
    write_survey_bundle(tmp_path / "mm", ids, X * 1000,
                        observations={c.id: uv[k] for k, c in enumerate(true)})
    res = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(tmp_path / "nominal.yaml"),
                                    "--survey", str(tmp_path / "mm"), "--out", str(bad), "-q"])
    assert res.exit_code == 2 and "is not in the room" in res.output and "S000" in res.output


def test_calibration_sees_the_spots_the_locator_sees(tmp_path, rng):
    """A nominal deployment with a pixel correction: the calibrated cameras are fitted to the
    corrected spots, so locating with the calibrated file lands on the survey points."""
    from vlpcal.locator import Locator

    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x, 0.9, 0.0)) for k, x in
            enumerate((1.2, 1.8, 2.4))]
    room = [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]
    dep = deployment.Deployment("lab", 2.3, room, true,
                                extra={"corrections": {"C2": {"pixel_offset": [3.0, 0.0]}}})
    deployment.save(dep, tmp_path / "nominal.yaml")
    X = survey_grid()
    ids = [f"S{i:03d}" for i in range(len(X))]
    uv = observe(true, X, rng)
    write_survey_bundle(tmp_path / "survey", ids, X,
                        observations={c.id: uv[k] for k, c in enumerate(true)})
    out = tmp_path / "cal.yaml"
    res = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(tmp_path / "nominal.yaml"),
                                    "--survey", str(tmp_path / "survey"), "--out", str(out),
                                    "-q"])
    assert res.exit_code == 0, res.output
    fixes = Locator(deployment.load(out)).locate_pixels(uv)
    assert np.nanmean(np.linalg.norm(fixes.X - X, axis=1)) < 0.005


def test_survey_plan_covers_every_camera_and_pair_and_prints_a_map(tmp_path):
    from shapely.geometry import Point, Polygon

    from vlpcal.datasets import read_survey_bundle
    from vlpcal.geometry import paper_rig

    keep_out = [[1.6, 0.2], [2.0, 0.2], [2.0, 0.6], [1.6, 0.6]]
    dep = deployment.Deployment("lab", 2.3, [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]],
                                paper_rig(), keep_out=[keep_out])
    deployment.save(dep, tmp_path / "d.yaml")
    res = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--out",
                                    str(tmp_path / "plan" / "points.csv")])
    assert res.exit_code == 0, res.output
    plan = read_survey_bundle(tmp_path / "plan")
    assert plan.point_ids[0] == "S0001" and len(set(plan.point_ids)) == len(plan.point_ids)
    assert len(set(plan.xyz[:, 2])) >= 2
    block = Polygon(keep_out)
    assert not any(block.contains(Point(x, y)) for x, y, _ in plan.xyz)
    for cam in dep.cameras:
        assert cam.project(plan.xyz, margin=5.0)[2].sum() >= 12
    seen = np.stack([c.project(plan.xyz, margin=5.0)[2] for c in dep.cameras])
    for i in range(3):
        for j in range(i + 1, 3):
            assert (seen[i] & seen[j]).sum() >= 6
    assert (tmp_path / "plan" / "points.png").is_file()
    bad = CliRunner().invoke(main, ["survey", "plan", "-d", str(tmp_path / "d.yaml"), "--out",
                                    str(tmp_path / "x.csv"), "--heights", "0"])
    assert bad.exit_code == 2 and "two or more heights" in bad.output


def test_hostile_surveys_and_outputs_are_refused_in_one_line(tmp_path, rng):
    """A survey along one line, a camera of random spots, an output that is an input or not a
    YAML file: one-line refusals, nothing written, the inputs unchanged."""
    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x, 0.9, 0.0)) for k, x in
            enumerate((1.2, 1.8, 2.4))]
    X = survey_grid()
    ids = [f"S{i:03d}" for i in range(len(X))]
    line = np.c_[np.linspace(0.5, 3.1, 40), np.full(40, 0.9), np.full(40, 0.35)]
    with pytest.raises(SurveyError, match="camera C1: its survey points cannot fix its pose"):
        calibrate(true, line, observe(true, line, rng), [f"L{i}" for i in range(40)])
    uv = observe(true, X, rng)
    noisy = uv.copy()
    seen = np.isfinite(noisy[2]).all(axis=1)
    noisy[2, seen] = rng.uniform([0, 0], [160, 120], (seen.sum(), 2))
    with pytest.raises(SurveyError, match="camera C3: its spots fit no pose"):
        calibrate(true, X, noisy, ids)
    room = [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]
    nominal = tmp_path / "nominal.yaml"
    deployment.save(deployment.Deployment("lab", 2.3, room, true), nominal)
    write_survey_bundle(tmp_path / "survey", ids, X,
                        observations={c.id: uv[k] for k, c in enumerate(true)})
    before = {p: p.read_bytes() for p in (nominal, tmp_path / "survey" / "points.csv")}
    for out, why in ((nominal, "own input"), (tmp_path / "survey" / "cal.yaml", "own input"),
                     (tmp_path / "cal.png", "is a YAML file")):
        res = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(nominal), "--survey",
                                        str(tmp_path / "survey"), "--out", str(out), "-q"])
        assert res.exit_code == 2 and why in res.output and len(res.output.splitlines()) == 1
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nominal.yaml", "survey"]


@pytest.mark.parametrize("wand", [False, True])
def test_the_schur_step_is_the_sparse_solve_step(rng, wand):
    """The bundle adjustment's step by eliminating the points (their 3×3 blocks, 6×6 for a
    wand's two ends) equals a general sparse solve of the same damped normal equations."""
    from scipy.sparse import csr_matrix, diags
    from scipy.sparse.linalg import spsolve

    from vlpcal.survey.calibration import _pattern
    from vlpcal.survey.least_squares import SchurSolver as _SchurSolver

    npars, n_pts = [6, 9, 7], 40
    obs = [(np.sort(rng.choice(n_pts, 25, replace=False)), None) for _ in npars]
    pairs = (np.arange(0, 20, 2), np.arange(1, 20, 2)) if wand else None
    rows, cols, shape = _pattern(npars, obs, n_pts, pairs)
    J = csr_matrix((rng.normal(size=len(rows)), (rows, cols)), shape=shape)
    A = (J.T @ J).tocsc()
    g = rng.normal(size=shape[1])
    damping = 1e-3 * np.maximum(A.diagonal(), 1.0)
    want = spsolve((A + diags(damping)).tocsc(), -g)
    got = _SchurSolver(sum(npars), n_pts, pairs)(A, g, damping)
    assert got is not None
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9 * np.abs(want).max())


def test_a_tape_point_30_cm_off_is_named_with_what_leaving_it_out_gives(rng):
    """A tape survey's point read 0.30 m off in x: named with its held-out error
    against the other points' and their held-out mean with it and without it; the survey
    without the misreading names none."""
    from vlpcal.survey import calibrate_survey

    true = [look_at(f"C{k + 1}", (x, 0.9, 2.3), (x, 0.9, 0.0)) for k, x in
            enumerate((1.2, 1.8, 2.4))]
    nominal = [nudge(c, rng, 0.02, 1 * DEG) for c in true]
    dep = deployment.Deployment("lab", 2.3, [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]], nominal)
    X = survey_grid(step=0.3)
    ids = [f"P{i:03d}" for i in range(len(X))]
    uv = observe(true, X, rng)
    measured = X + rng.normal(0, 0.002, X.shape)
    clean = calibrate_survey(dep, measured, uv, ids, lens="pose")
    assert clean.suspects == [] and clean.report()["suspects"] == []
    seen3 = np.flatnonzero(np.isfinite(uv).all(axis=2).sum(axis=0) == 3)
    wrong = int(seen3[len(seen3) // 2])
    measured[wrong, 0] += 0.30
    result = calibrate_survey(dep, measured, uv, ids, lens="pose")
    assert [s.point_id for s in result.suspects] == [ids[wrong]], result.suspects
    s = result.suspects[0]
    assert s.residual == pytest.approx(0.30, abs=0.02) and s.residual > s.limit
    assert s.limit > 5 * s.typical and s.typical < 0.01, s
    assert np.isfinite(s.others_with) and s.others_without <= 1.05 * s.others_with, s
    assert result.report()["suspects"][0]["point_id"] == ids[wrong]
