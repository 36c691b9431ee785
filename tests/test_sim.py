import numpy as np
import pytest
from click.testing import CliRunner

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.datasets import POINTS_COLUMNS, read_frames_folder, read_survey_bundle
from vlpcal.detection import detect_spots
from vlpcal.sim.profiles import PROFILES, get_profile
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import (
    grid_points,
    simulate_frames,
    simulate_survey,
    trajectory,
    write_deployments,
)


@pytest.mark.parametrize("name", PROFILES)
def test_same_seed_same_bytes_other_seed_other_bytes(name):
    scene = make_scene(get_profile(name), seed=4)
    pts = grid_points(scene, 0.5, [0.0, 0.35])[:12]
    a, seen_a = render_scene(scene, pts, seed=1)
    b, seen_b = render_scene(make_scene(get_profile(name), seed=4), pts, seed=1)
    assert a == b and np.array_equal(seen_a, seen_b)
    c, _ = render_scene(scene, pts, seed=2)
    assert c != a
    assert make_scene(get_profile(name), seed=5).true != scene.true


def test_true_cameras_stray_from_nominal_as_the_profile_says():
    profile = get_profile("cheap-wide")
    scene = make_scene(profile, seed=0)
    assert scene.nominal == profile.nominal
    for nom, true in zip(scene.nominal, scene.true):
        assert np.linalg.norm(np.subtract(true.position, nom.position)) < 0.15
        tilt = np.degrees(np.arccos(np.clip(true.axis @ nom.axis, -1, 1)))
        assert 0.0 < tilt < 6.0
        assert true.dist[0] < -0.1  # strong barrel distortion
        assert true.fy / true.fx == pytest.approx(1.0135, abs=1e-9)


@pytest.mark.parametrize("name", PROFILES)
def test_detected_centre_matches_the_true_projection(name):
    """Without distractors, away from the image edge: the default detector finds the LED (all
    but the dimmest far-corner spots of a wide lens) and its error on the simulator's frames is
    what benchmarks/detectors.py states (RMS ~0.05 px, no outliers)."""
    scene = make_scene(get_profile(name), seed=0)
    pts = grid_points(scene, 0.25, [0.0, 0.35])
    frames, seen = render_scene(scene, pts, seed=0, distractors=False)
    errs, bright = [], []
    for k, cam in enumerate(scene.true):
        uv = cam.project(pts)[0]
        inner = seen[k] & (uv[:, 0] > 6) & (uv[:, 0] < cam.width - 7) & (uv[:, 1] > 6) \
            & (uv[:, 1] < cam.height - 7)
        res = detect_spots([f for f, i in zip(frames[cam.id], inner) if i])
        assert res.ok.mean() >= 0.9
        errs.append(np.hypot(*(res.uv - uv[inner]).T)[res.ok])
        bright.append(res.peak[res.ok] >= 80)
    err, bright = np.concatenate(errs), np.concatenate(bright)
    assert len(err) > 100 and bright.mean() > 0.5
    assert np.sqrt(np.mean(err ** 2)) < 0.1
    # no outliers among clearly visible spots; a dim far-corner spot (peak ~10–20 DN over the
    # background, JPEG q 60) can be off by up to ~0.5 px
    assert err[bright].max() < 0.3


def test_led_outside_the_view_gives_no_spot():
    scene = make_scene(get_profile("paper-2024"), seed=0)
    frames, seen = render_scene(scene, [[3.5, 0.1, 0.7]], distractors=False)
    assert not seen[0, 0]
    assert detect_spots(frames["C1"]).reasons == ["no_spot"]


def test_survey_bundle_follows_design_md(tmp_path):
    scene = make_scene(get_profile("paper-2024"), seed=0)
    pts = grid_points(scene, 0.4, [0.0, 0.35])
    measured = simulate_survey(scene, tmp_path / "survey", pts)
    header = (tmp_path / "survey" / "points.csv").read_text().splitlines()[0]
    assert header == ",".join(POINTS_COLUMNS)
    bundle = read_survey_bundle(tmp_path / "survey")
    assert len(bundle.point_ids) == len(pts)
    assert np.allclose(bundle.xyz, measured, atol=1e-9)
    err = np.abs(measured - pts)
    assert 0 < err.max() < 6 * scene.profile.tape  # tape-measure noise, not exact positions
    assert set(bundle.camera_ids()) == {c.id for c in scene.true}
    for (pid, cid), path in bundle.frames.items():
        assert path == tmp_path / "survey" / "frames" / pid / f"{cid}.jpg"
        assert path.read_bytes()[:2] == b"\xff\xd8"
    # a frame is written only where the camera saw the LED ("missing = not seen")
    _, seen = render_scene(scene, pts)
    assert len(bundle.frames) == seen.sum()


def test_frames_folder_and_deployments_follow_design_md(tmp_path):
    scene = make_scene(get_profile("cheap-wide"), seed=1)
    path = trajectory(scene, 30)
    ids = simulate_frames(scene, tmp_path / "frames", path)
    folder = read_frames_folder(tmp_path / "frames")
    assert folder.frame_ids == ids
    assert folder.camera_ids == [c.id for c in scene.true]
    assert len(folder.files) == 30 * len(scene.true)  # every camera sends every frame
    truth = np.loadtxt(tmp_path / "frames.truth.csv", delimiter=",", skiprows=1,
                       usecols=(1, 2, 3))
    assert np.allclose(truth, path, atol=1e-9)
    nominal, true = write_deployments(scene, tmp_path)
    assert deployment.load(nominal).cameras == list(scene.nominal)
    loaded = deployment.load(true)
    for a, b in zip(loaded.cameras, scene.true):
        assert np.allclose(a.to_dict()["rotation"], b.rotation, atol=1e-12)
        assert np.allclose(a.dist, b.dist, atol=1e-12)
    assert loaded.extra["provenance"]["profile"] == "cheap-wide"


def test_simulate_command_writes_every_file(tmp_path):
    out = tmp_path / "sim"
    res = CliRunner().invoke(main, ["simulate", "--profile", "qvga", "--out", str(out),
                                    "--survey-step", "0.6", "--test-points", "5"])
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == {"nominal.yaml", "truth.yaml", "survey", "frames",
                                               "frames.truth.csv"}
    assert len(read_frames_folder(out / "frames").frame_ids) == 5
    again = CliRunner().invoke(main, ["simulate", "--out", str(out)])
    assert again.exit_code == 2 and "--overwrite" in again.output
    bad = CliRunner().invoke(main, ["simulate", "--profile", "nope", "--out", str(out)])
    assert bad.exit_code == 2 and "paper-2024" in bad.output


def test_describe_names_the_sources():
    res = CliRunner().invoke(main, ["simulate", "--profile", "paper-2024", "--describe"])
    assert res.exit_code == 0 and "paper 3.1/3.3" in res.output and "measured:" in res.output


def test_a_robots_body_hides_the_floors_mirror_image_of_its_led():
    """cheap-wide's polished floor mirrors the LED; under a robot's LED the floor is its body."""
    from dataclasses import replace

    scene = make_scene(get_profile("cheap-wide"), seed=0)
    pts = [[1.5, 1.2, 0.15], [3.0, 2.5, 0.15]]
    bare, _ = render_scene(scene, pts, seed=3)
    robot, _ = render_scene(scene, pts, seed=3, carrier_radius=[0.2, 0.0])
    flat = replace(scene, profile=replace(scene.profile, look=replace(scene.profile.look,
                                                                      reflection=0.0)))
    no_mirror, _ = render_scene(flat, pts, seed=3)
    for cid in bare:
        assert robot[cid][0] == no_mirror[cid][0]  # hidden by the body
        assert robot[cid][1] == bare[cid][1]  # no body: the mirror image shows
    assert any(bare[c][0] != no_mirror[c][0] for c in bare)
