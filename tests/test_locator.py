import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from vlpcal import deployment, sim
from vlpcal.cli import main
from vlpcal.datasets import write_frames_folder
from vlpcal.locator import Locator
from vlpcal.sim.profiles import get_profile
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import deployment_of, grid_points


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A simulated paper-2024 install: its true deployment file and 40 rendered frame sets."""
    root = tmp_path_factory.mktemp("site")
    scene = make_scene(get_profile("paper-2024"), seed=2)
    path = root / "truth.yaml"
    deployment.save(deployment_of(scene, "true"), path)
    pts = grid_points(scene, 0.2, [0.0, 0.35], min_cameras=2)[:40]
    frames, _ = render_scene(scene, pts, seed=3)
    return scene, path, pts, frames


def test_locate_batch_and_single_agree_and_hit_the_truth(site):
    scene, path, pts, frames = site
    loc = Locator.from_file(path)
    sets = [{c: frames[c][i] for c in frames} for i in range(len(pts))]
    batch = loc.locate_batch(sets, list(range(len(sets))))
    assert (batch.status == "ok").all()
    err = np.linalg.norm(batch.X - pts, axis=1)
    assert err.max() < 0.01  # true cameras: millimetres
    one = loc.locate(sets[5], "f5")
    assert one.ok and one.frame_id == "f5"
    assert np.allclose([one.x, one.y, one.z], batch.X[5], atol=1e-12)
    assert set(one.cameras) <= {"C1", "C2", "C3"} and len(one.cameras) >= 2
    assert all(r < 0.5 for r in one.residual.values())
    assert 0 < one.sigma < 0.02


def test_a_batch_rows_are_its_fixes_rows(site):
    """FixBatch.rows (the folder writer's fast path) equals each Fix.row, for fixes of every
    kind: ok, one camera, none, and cameras that sent nothing."""
    scene, path, pts, frames = site
    loc = Locator.from_file(path)
    sets = [{c: frames[c][i] for c in frames} for i in range(len(pts))]
    sets += [{"C1": frames["C1"][0]}, {}, {c: b"" for c in frames},
             {c: frames[c][1] for c in ("C1", "C3")}]
    batch = loc.locate_batch(sets, [f"s{i}" for i in range(len(sets))])
    assert len(set(batch.status)) >= 3
    assert batch.rows() == [fix.row() for fix in batch]


def test_a_batch_rows_name_every_camera_of_a_large_site(rng):
    """Rows of a site of 70 cameras (more than the bits of a machine word) name the cameras
    each fix used as each Fix.row does."""
    from vlpcal.locator import FixBatch

    n, ids = 40, [f"C{k}" for k in range(70)]
    used = rng.random((70, n)) < 0.05
    used[69, ::2] = True
    batch = FixBatch(ids, [f"s{i}" for i in range(n)], rng.normal(size=(n, 3)),
                     np.array(["ok"] * n, dtype=object), used, rng.random((70, n)),
                     rng.random(n), np.where(used, "ok", "no_spot").astype(object))
    assert batch.rows() == [fix.row() for fix in batch]
    assert all(r["cameras"].endswith("C69") for r in batch.rows()[::2])


def test_bad_camera_data_is_a_status_never_an_exception(site):
    scene, path, pts, frames = site
    loc = Locator.from_file(path)
    good = {c: frames[c][0] for c in frames}
    dark = sim.encode_jpeg(np.full((120, 160), 20, np.uint8))
    cases = {
        "corrupt": {c: b"\xff\xd8garbage\xff\xd9" for c in frames},
        "truncated": {c: f[: len(f) // 2] for c, f in good.items()},
        "empty": {c: b"" for c in frames},
        "wrong size": {c: sim.encode_jpeg(np.zeros((60, 80), np.uint8)) for c in frames},
        "dark": {c: dark for c in frames},
        "nothing": {},
        "stranger only": {"X9": good["C1"]},
        "array": {c: np.zeros((120, 160), np.uint8) for c in frames},
    }
    batch = loc.locate_batch(list(cases.values()), list(cases))
    got = dict(zip(cases, batch.status))
    assert got == {"corrupt": "corrupt_frame", "truncated": "corrupt_frame",
                   "empty": "corrupt_frame", "wrong size": "wrong_size", "dark": "no_spot",
                   "nothing": "no_frames", "stranger only": "no_frames", "array": "no_spot"}
    assert np.isnan(batch.X).all()
    assert loc.unknown_cameras(cases.values()) == {"X9": 1}
    # a set alone is measured frame by frame (the live path): the same statuses
    for i, (name, fs) in enumerate(cases.items()):
        one = loc.locate(fs, name)
        assert (one.status, one.camera_status) == (got[name], batch[i].camera_status), name


def test_a_set_alone_is_the_batchs_fix(site):
    """Located alone (each frame measured on its own: detect_frame), every set gives the fix,
    the cameras, the residuals and the camera statuses it gets in a batch (stacks)."""
    import vlpcal.locator as locator

    scene, path, pts, frames = site
    loc = Locator.from_file(path)
    sets = [{c: frames[c][i] for c in frames} for i in range(len(pts))]
    sets[3] = {c: f for c, f in sets[3].items() if c != "C2"}  # a camera missing
    sets[4]["C1"] = sets[4]["C1"][:200]  # a truncated frame
    batch = loc.locate_batch(sets)
    assert len(sets) > locator._FRAME_BY_FRAME  # the batch went through the stacks
    for i, fs in enumerate(sets):
        one, b = loc.locate(fs), batch[i]
        assert (one.status, one.cameras, one.camera_status) == (b.status, b.cameras,
                                                                 b.camera_status), i
        np.testing.assert_allclose([one.x, one.y, one.z], [b.x, b.y, b.z], atol=1e-12)
    assert {"missing", "corrupt_frame"} <= {s for f in batch for s in f.camera_status.values()}


def test_frames_folder_with_every_kind_of_bad_file(site, tmp_path):
    scene, path, pts, frames = site
    n = 12
    ids = [f"{i:03d}" for i in range(n)]
    data = {c: list(frames[c][:n]) for c in frames}
    data["C1"][1] = b""  # empty
    data["C2"][2] = data["C2"][2][:300]  # truncated
    data["C3"][3] = b"not a jpeg at all"  # corrupt
    data["C1"][4] = sim.encode_jpeg(np.zeros((240, 320), np.uint8))  # wrong size
    data["C2"][5] = None  # missing file
    dark = sim.encode_jpeg(np.full((120, 160), 20, np.uint8))
    for c in data:
        data[c][6] = dark  # all-dark frame set
    data["C7"] = [frames["C1"][0]] * n  # a camera the deployment does not have
    write_frames_folder(tmp_path / "frames", ids, data)
    out = tmp_path / "fixes.csv"
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--frames",
                                    str(tmp_path / "frames"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "C7" in res.output and "12 frame sets" in res.output
    rows = list(csv.DictReader(out.open()))
    assert [r["frame_id"] for r in rows] == ids
    assert list(rows[0])[:5] == ["frame_id", "x", "y", "z", "status"]
    by_id = {r["frame_id"]: r for r in rows}
    assert by_id["006"]["status"] == "no_spot" and by_id["006"]["x"] == ""
    assert "C1:corrupt_frame" in by_id["001"]["camera_status"]
    assert "C2:corrupt_frame" in by_id["002"]["camera_status"]
    assert "C3:corrupt_frame" in by_id["003"]["camera_status"]
    assert "C1:wrong_size" in by_id["004"]["camera_status"]
    assert "C2:missing" in by_id["005"]["camera_status"]
    for fid in ("000", "007", "008", "009", "010", "011"):  # untouched sets are fixed
        r = by_id[fid]
        assert r["status"] == "ok"
        i = int(fid)
        assert np.linalg.norm([float(r["x"]) - pts[i, 0], float(r["y"]) - pts[i, 1],
                               float(r["z"]) - pts[i, 2]]) < 0.01
    # a set that lost one camera out of three still gets a fix where two remain
    assert by_id["001"]["status"] in ("ok", "one_camera")


def test_observations_csv_and_jsonl_to_stdout(site, tmp_path):
    scene, path, pts, _ = site
    obs = tmp_path / "obs.csv"
    with obs.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame_id", "camera_id", "u", "v"])
        for i, p in enumerate(pts[:10]):
            for cam in scene.true:
                uv, _, inside = cam.project(p[None])
                if inside[0]:
                    w.writerow([f"t{i}", cam.id, *uv[0]])
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--observations", str(obs),
                                    "--format", "jsonl", "-q"])
    assert res.exit_code == 0, res.output
    lines = [json.loads(line) for line in res.output.splitlines()]
    assert [r["frame_id"] for r in lines] == [f"t{i}" for i in range(10)]
    got = np.array([[r["x"], r["y"], r["z"]] for r in lines])
    assert np.abs(got - pts[:10]).max() < 1e-6  # exact pixels, exact cameras


def test_bad_observations_and_missing_inputs_are_one_line_errors(site, tmp_path):
    _, path, _, _ = site
    obs = tmp_path / "obs.csv"
    obs.write_text("frame_id,camera_id,u,v\n1,C1,nan,3\n")
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--observations", str(obs)])
    assert res.exit_code == 2 and "line 2 u: expected a finite number" in res.output
    res = CliRunner().invoke(main, ["locate", "-d", str(path)])
    assert res.exit_code == 2 and "exactly one input" in res.output
    out = tmp_path / "fixes.csv"
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--frames", str(tmp_path / "no"),
                                    "--out", str(out)])
    assert res.exit_code == 2 and "not a folder" in res.output
    assert not out.exists() and not list(tmp_path.glob(".fixes*"))  # no partial output


def test_a_wild_spot_is_dropped_and_max_residual_is_the_deployments(site):
    scene, path, pts, _ = site
    dep = deployment.load(path)
    X = pts
    uv = np.stack([c.project(X)[0] for c in dep.cameras])
    seen = np.stack([c.project(X, margin=3.0)[2] for c in dep.cameras]).sum(axis=0)
    i = int(np.flatnonzero(seen == 3)[0])
    wild = uv.copy()
    wild[0, i] = [10000.0, 60.0]  # far outside the image: no spot can be there
    fix = Locator(dep).locate_pixels(wild)[i]
    assert fix.ok and "C1" not in fix.cameras
    assert np.linalg.norm([fix.x - X[i, 0], fix.y - X[i, 1], fix.z - X[i, 2]]) < 0.01
    off = uv.copy()
    off[2, i] += [9.0, 0.0]  # C3 nine pixels off
    strict = Locator(dep).locate_pixels(off)[i]
    loose = Locator(deployment.Deployment(dep.name, dep.ceiling_height, dep.room, dep.cameras,
                                          extra={"fusion": {"max_residual": 100.0}}))
    lenient = loose.locate_pixels(off)[i]
    # (the lenient fix, 9 px off in C3, may then be refused as outside the room: kept or not,
    # C3 is not dropped)
    assert strict.camera_status["C3"] == "dropped" and lenient.camera_status["C3"] != "dropped"


def test_out_to_a_folder_is_a_one_line_error_leaving_nothing(site, tmp_path):
    _, path, _, frames = site
    write_frames_folder(tmp_path / "frames", ["a"], {c: [frames[c][0]] for c in frames})
    (tmp_path / "fixes").mkdir()
    res = CliRunner().invoke(main, ["locate", "-d", str(path), "--frames",
                                    str(tmp_path / "frames"), "--out", str(tmp_path / "fixes")])
    assert res.exit_code == 2 and "cannot write the fixes there" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fixes", "frames"]


def test_a_fix_whose_rays_miss_each_other_says_so_in_its_sigma():
    """A camera moved 3 cm since the deployment was written: its rays miss the others' by far
    more than the spot noise, and 452 of 546 ok fixes lay beyond 3 sigma at millimetre sigmas
    (a hostile probe). Each fix's sigma now holds what its own residuals, and the run's
    three-camera fixes', say; the deployment as it hangs keeps its sigmas."""
    from dataclasses import replace

    from vlpcal.deployment import Deployment
    from vlpcal.geometry import paper_camera

    cams = [paper_camera(f"C{k + 1}", (1.0 + 0.8 * k, 0.9, 2.3)) for k in range(3)]
    room = [[0, 0], [3.6, 0], [3.6, 1.8], [0, 1.8]]
    rng = np.random.default_rng(5)
    X = np.c_[rng.uniform(1.0, 2.6, 400), rng.uniform(0.5, 1.3, 400), rng.uniform(0, 0.5, 400)]
    uv = np.stack([c.project(X)[0] for c in cams]) + rng.normal(0, 0.04, (3, 400, 2))
    as_hung = Locator(Deployment("line", 2.3, room, cams, [], {})).locate_pixels(uv)
    moved = [cams[0], replace(cams[1], position=(cams[1].position[0] + 0.03,
                                                 *cams[1].position[1:])), cams[2]]
    stale = Locator(Deployment("line", 2.3, room, moved, [], {})).locate_pixels(uv)
    for fixes, far in ((as_hung, 0.01), (stale, 0.2)):
        ok = fixes.status == "ok"
        err = np.linalg.norm(fixes.X[ok] - X[ok], axis=1)
        assert ok.mean() > 0.8 and np.median(err) < far
        assert (err <= 3 * fixes.sigma[ok]).mean() > 0.99, (err / fixes.sigma[ok]).max()
    assert np.nanmedian(stale.sigma) > 5 * np.nanmedian(as_hung.sigma)
    from vlpcal.locator import residual_scale

    assert np.median(residual_scale(as_hung.residual, as_hung.used, 0.05)) < 1.5
