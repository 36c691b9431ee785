"""`vlpcal survey capture` against simulated MJPEG cameras on 127.0.0.1: non-interactive with a
kill and a resume, interactive through a pseudo-terminal, and a camera that dies mid-session."""

import os
import pty
import select
import signal
import subprocess
import sys
import threading
import time
import zlib
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from vlpcal import deployment
from vlpcal.cli import main
from vlpcal.datasets import SurveyAppender, read_points, read_survey_bundle, write_truth_csv
from vlpcal.sim.mjpeg import mjpeg_head, mjpeg_part
from vlpcal.sim.profiles import get_profile
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import deployment_of
from vlpcal.survey import plan_survey

VARIANTS = 2  # frames a camera cycles through while the LED stays put (noise differs)


class Rig:
    """One MJPEG stream per simulated camera at /<camera_id>. The LED is where the file
    ``current`` says ("x y z", written by capture's --on-point); no file: the LED is off."""

    def __init__(self, scene, root: Path, fps: float = 40.0, die: dict | None = None,
                 comes_back: bool = False):
        """``die``: camera id → frames it sends before it drops off the network; it stays
        off (connections refused) unless ``comes_back``."""
        self.scene, self.current, self.fps = scene, root / "current", fps
        self.cache: dict = {}
        self.lock = threading.Lock()
        die = die or {}
        dead: set = set()
        rig = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                cid = self.path.strip("/")
                if cid in dead:
                    self.send_error(503)
                    return
                mjpeg_head(self)
                try:
                    for i in range(10**9):
                        if cid in die and i >= die[cid]:
                            if not comes_back:
                                dead.add(cid)
                            die.pop(cid)  # (one drop-out)
                            self.connection.shutdown(2)  # the camera drops off
                            return
                        jpg = rig.frame(cid, i % VARIANTS)
                        self.wfile.write(mjpeg_part(jpg))
                        self.wfile.flush()
                        time.sleep(1.0 / rig.fps)
                except (BrokenPipeError, ConnectionResetError, OSError):
                    pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def frame(self, cid: str, variant: int) -> bytes:
        try:
            key = self.current.read_text().strip()
        except OSError:
            key = ""
        with self.lock:
            if key not in self.cache:
                p = [float(t) for t in key.split()] if key else [-50.0, -50.0, 0.0]
                seed = zlib.crc32(key.encode())
                frames, _ = render_scene(self.scene, np.repeat([p], VARIANTS, axis=0),
                                         seed=seed)
                self.cache[key] = frames
            return self.cache[key][cid][variant]

    def args(self):
        port = self.server.server_address[1]
        return [a for c in self.scene.true
                for a in ("--camera", f"{c.id}=http://127.0.0.1:{port}/{c.id}")]

    def hook(self):
        # braces that are not placeholders pass through untouched (awk, shell functions)
        return (f"awk 'BEGIN{{exit 0}}' && test -n \"$VLPCAL_POINT_ID\" && "
                f"printf '%s %s %s' {{x}} {{y}} {{z}} > {self.current}")

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A simulated paper-2024 install (its true cameras as the deployment) and a survey plan."""
    root = tmp_path_factory.mktemp("capture")
    scene = make_scene(get_profile("paper-2024"), seed=5)
    dep = deployment_of(scene, "true")
    deployment.save(dep, root / "dep.yaml")
    plan = plan_survey(dep, 0.5, (0.0, 0.35), min_per_camera=8)
    write_truth_csv(root / "points.csv", plan.ids, plan.xyz, id_column="point_id")
    return scene, root


def capture_cmd(root, rig, survey, *extra):
    return [sys.executable, "-m", "vlpcal", "survey", "capture", "-d", str(root / "dep.yaml"),
            "--points", str(root / "points.csv"), "--survey", str(survey), *rig.args(),
            "--on-point", rig.hook(), *extra]


def bundle_contents(path: Path) -> dict:
    files = {p.relative_to(path).as_posix(): p.read_bytes()
             for p in sorted(path.rglob("*")) if p.is_file() and ".capture" not in p.parts}
    return files


def test_capture_killed_and_resumed_equals_an_uninterrupted_run(site, tmp_path):
    scene, root = site
    rig = Rig(scene, tmp_path)
    try:
        whole = tmp_path / "whole"
        res = subprocess.run(capture_cmd(root, rig, whole, "--yes", "--delay", "0.1"),
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
        n_planned = len(read_points(root / "points.csv")[0])
        assert len(read_points(whole / "points.csv")[0]) == n_planned
        assert "cameras good enough to calibrate" in res.stdout

        # the same session, killed without warning midway, then run again
        (tmp_path / "current").unlink()
        cut = tmp_path / "cut"
        proc = subprocess.Popen(capture_cmd(root, rig, cut, "--yes", "--delay", "0.1"),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            path = cut / "points.csv"
            if path.exists() and path.read_text().count("\n") >= 1 + n_planned // 2:
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kept = read_points(cut / "points.csv")[0]
        assert 0 < len(kept) < n_planned
        res = subprocess.run(capture_cmd(root, rig, cut, "--yes", "--delay", "0.1"),
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
        assert f"resuming: {len(kept)} points already in" in res.stdout
    finally:
        rig.close()
    assert bundle_contents(cut) == bundle_contents(whole)
    bundle = read_survey_bundle(cut)
    assert len(bundle.point_ids) == n_planned and bundle.camera_ids() == ["C1", "C2", "C3"]
    out = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(root / "dep.yaml"),
                                    "--survey", str(cut), "--out", str(tmp_path / "cal.yaml"),
                                    "--folds", "3", "-q"])
    assert out.exit_code == 0, out.output
    cal = deployment.load(tmp_path / "cal.yaml")
    for c, t in zip(cal.cameras, scene.true):  # the capture's frames calibrate the cameras
        assert np.linalg.norm(np.subtract(c.position, t.position)) < 0.02


class Terminal:
    """A process on a pseudo-terminal: wait for text, type a line."""

    def __init__(self, cmd):
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen(cmd, stdin=slave, stdout=slave, stderr=slave,
                                     close_fds=True)
        os.close(slave)
        self.out = ""

    def expect(self, text, timeout=60.0):
        deadline = time.monotonic() + timeout
        while text not in self.out:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"waited for {text!r}; got:\n{self.out[-3000:]}")
            ready, _, _ = select.select([self.master], [], [], min(left, 0.5))
            if ready:
                try:
                    self.out += os.read(self.master, 65536).decode(errors="replace")
                except OSError:
                    break
        i = self.out.index(text) + len(text)
        seen, self.out = self.out[:i], self.out[i:]
        return seen

    def type(self, line):
        os.write(self.master, (line + "\n").encode())

    def close(self):
        try:
            self.proc.wait(timeout=30)
        finally:
            os.close(self.master)


def test_interactive_capture_through_a_terminal(site, tmp_path):
    scene, root = site
    ids, xyz = read_points(root / "points.csv")
    write_truth_csv(tmp_path / "four.csv", ids[:4], xyz[:4], id_column="point_id")
    rig = Rig(scene, tmp_path)
    survey = tmp_path / "survey"
    cmd = capture_cmd(root, rig, survey)
    cmd[cmd.index("--points") + 1] = str(tmp_path / "four.csv")
    term = Terminal(cmd)
    try:
        a, b, c, d = ids[:4]
        term.expect(f"[1/4] place the LED at {a}")
        term.type("")
        first = term.expect("accept?")
        assert "C1 " in first and "px" in first
        term.type("r")  # redo: another burst
        term.expect("accept?")
        term.type("")
        term.expect(f"{a} saved")
        term.expect(f"[2/4] place the LED at {b}")
        term.type("s")
        term.expect(f"{b} skipped")
        term.expect(f"[3/4] place the LED at {c}")
        term.type("")
        term.expect("accept?")
        term.type("")
        term.expect(f"{c} saved")
        term.expect(f"[4/4] place the LED at {d}")
        term.type("b")  # back: C's capture is removed and redone
        term.expect(f"back to {c}")
        term.expect(f"[3/4] place the LED at {c}")
        term.type("")
        term.expect("accept?")
        term.type("")
        term.expect(f"[4/4] place the LED at {d}")
        term.type("e")  # an extra point, measured by the person
        term.expect("x y z in metres")
        term.type("1.70 0.80 0.10")
        term.expect("extra point X001")
        term.expect("accept?")
        term.type("")
        term.expect("X001 saved")
        term.expect(f"[4/4] place the LED at {d}")
        term.type("")
        term.expect("accept?")
        term.type("")
        term.expect("points captured now")
    finally:
        term.close()
        rig.close()
    assert term.proc.returncode == 0
    got, pos = read_points(survey / "points.csv")
    assert got == [a, c, "X001", d]
    np.testing.assert_allclose(pos[2], [1.70, 0.80, 0.10])
    assert sorted(p.name for p in (survey / "frames").iterdir()) == sorted(got)
    assert SurveyAppender(survey).skipped() == {b}


def capture_six(site, tmp_path, **rig_options):
    """An unattended capture of the plan's first six points; the run and the point ids."""
    scene, root = site
    ids, xyz = read_points(root / "points.csv")
    write_truth_csv(tmp_path / "six.csv", ids[:6], xyz[:6], id_column="point_id")
    rig = Rig(scene, tmp_path, **rig_options)
    cmd = capture_cmd(root, rig, tmp_path / "survey", "--yes", "--delay", "0.3")
    cmd[cmd.index("--points") + 1] = str(tmp_path / "six.csv")
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    finally:
        rig.close()
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    return res, ids


def test_a_camera_that_dies_is_reported_and_the_others_are_captured(site, tmp_path):
    res, ids = capture_six(site, tmp_path, die={"C2": 60})  # C2 stops after 1.5 s of frames
    assert "camera C2:" in res.stdout and "going on without it" in res.stdout
    assert "C2     no frames (stopped" in res.stdout
    bundle = read_survey_bundle(tmp_path / "survey")
    assert bundle.point_ids == ids[:6]
    last = bundle.point_ids[-1]
    assert (last, "C2") not in bundle.frames
    assert (last, "C1") in bundle.frames and (last, "C3") in bundle.frames


def test_appender_recovers_from_a_crash_at_any_step(tmp_path):
    """A line cut mid-write is dropped, frames without their line are removed, a stage left
    behind is cleared: what remains is exactly the committed points."""
    app = SurveyAppender(tmp_path / "b")
    app.accept("S0001", (1.0, 0.5, 0.0), {"C1": b"\xff\xd8one\xff\xd9", "C2": None})
    app.accept("S0002", (1.5, 0.5, 0.0), {"C1": b"\xff\xd8two\xff\xd9"})
    root = tmp_path / "b"
    with open(root / "points.csv", "a") as f:
        f.write("S0003,2.0,0.")  # the crash: a partial line
    (root / "frames" / "S0004").mkdir()  # renamed, but its line never written
    with open(root / ".capture" / "journal.csv", "a") as f:
        f.write("commit,S0004\n")
    (root / "frames" / "S9999").mkdir()  # not ours to remove: kept (the reader will object)
    (root / ".capture" / "stage-S0005").mkdir()
    again = SurveyAppender(root)
    ids, xyz = again.accepted()
    assert ids == ["S0001", "S0002"] and xyz[1].tolist() == [1.5, 0.5, 0.0]
    assert sorted(p.name for p in (root / "frames").iterdir()) == ["S0001", "S0002", "S9999"]
    assert not list((root / ".capture").glob("stage-*"))
    (root / "frames" / "S9999").rmdir()
    assert read_survey_bundle(root).point_ids == ids
    with pytest.raises(Exception, match="already in the survey"):
        again.accept("S0001", (0, 0, 0), {})
    again.skip("S0003")
    again.remove("S0001")
    assert again.accepted()[0] == ["S0002"] and again.skipped() == {"S0003"}
    assert not (root / "frames" / "S0001").exists()


def test_live_check_names_what_a_camera_still_needs(site):
    from vlpcal.capture import live_check

    scene, root = site
    dep = deployment.load(root / "dep.yaml")
    cam = dep.cameras[0]
    g = np.mgrid[0.6:1.8:0.1, 0.4:1.4:0.1, 0:0.4:0.35].reshape(3, -1).T
    uv = np.stack([np.where(c.project(g)[2][:, None], c.project(g)[0], np.nan)
                   for c in dep.cameras])
    ids = [f"P{i}" for i in range(len(g))]
    checks = {c.camera: c for c in live_check(dep, g, uv, ids)}
    assert checks[cam.id].verdict == "good" and checks[cam.id].rms_px < 0.01
    # only points under the camera's middle: its corners are missing
    middle = np.linalg.norm(g[:, :2] - np.array(cam.position[:2]), axis=1) < 0.3
    few = live_check(dep, g[middle], uv[:, middle], [i for i, m in zip(ids, middle) if m])
    assert "corners" in few[0].verdict or "more points" in few[0].verdict
    assert set(few[0].missing) == {"top-left", "top-right", "bottom-left", "bottom-right"}


def test_capture_never_takes_over_a_folder_it_did_not_start(tmp_path):
    """A simulate output, a plan's folder: refused, and nothing in it is touched."""
    sim = tmp_path / "sim"
    (sim / "frames" / "000001").mkdir(parents=True)
    (sim / "frames" / "000001" / "C1.jpg").write_bytes(b"jpeg")
    with pytest.raises(Exception, match="survey capture did not start"):
        SurveyAppender(sim)
    assert (sim / "frames" / "000001" / "C1.jpg").read_bytes() == b"jpeg"
    assert not (sim / "points.csv").exists() and not (sim / ".capture").exists()


def test_a_camera_back_on_the_network_is_used_again(site, tmp_path):
    res, _ = capture_six(site, tmp_path, die={"C2": 30}, comes_back=True)
    assert "camera C2:" in res.stdout and "camera C2: trying it again" in res.stdout
    bundle = read_survey_bundle(tmp_path / "survey")
    assert (bundle.point_ids[-1], "C2") in bundle.frames


def test_capture_checks_every_camera_before_the_first_point(site, tmp_path):
    """No camera answers: one line naming each and why, exit 1 (as a live locate whose
    cameras never answer), before the walk starts (the first point is never announced) and
    nothing written."""
    scene, root = site
    cmd = [sys.executable, "-m", "vlpcal", "survey", "capture", "-d", str(root / "dep.yaml"),
           "--points", str(root / "points.csv"), "--survey", str(tmp_path / "s"), "--yes",
           "--delay", "0", "--camera", "C1=http://127.0.0.1:9/none",
           "--camera", "C2=http://127.0.0.1:9/other"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode == 1, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 2 and lines[0].startswith("note: no --camera for C3"), lines
    assert "no camera answered (C1: connection refused; C2: connection refused)" in lines[1]
    assert "S0001" not in res.stdout and "Traceback" not in res.stderr
    assert not (tmp_path / "s").exists()  # nothing captured: nothing left behind


def test_capture_says_which_cameras_answered(site, tmp_path):
    """One camera of three answers with frames of the wrong size, one is off: each is named
    before the walk, and the walk goes on with the one that answered properly."""
    scene, root = site
    rig = Rig(scene, tmp_path)
    try:
        port = rig.server.server_address[1]
        cmd = [sys.executable, "-m", "vlpcal", "survey", "capture", "-d", str(root / "dep.yaml"),
               "--points", str(root / "points.csv"), "--survey", str(tmp_path / "s"), "--yes",
               "--delay", "0", "--camera", f"C1=http://127.0.0.1:{port}/C1",
               "--camera", "C2=http://127.0.0.1:9/off", "--on-point", "exit 3"]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    finally:
        rig.close()
    assert "camera C1: answered (160×120)" in res.stderr, res.stderr
    assert "camera C2: connection refused; going on without it" in res.stderr, res.stderr
    assert "--on-point 'exit 3' failed" in res.stderr  # the walk had started


def test_device_frames_are_stored_as_jpeg(site):
    """V4L2 sources give arrays: they are encoded once and handled like MJPEG frames."""
    import cv2

    from vlpcal.capture import as_jpeg, summarise

    scene, root = site
    dep = deployment.load(root / "dep.yaml")
    frames, _ = render_scene(scene, [[1.3, 0.8, 0.0]], seed=2)
    img = cv2.imdecode(np.frombuffer(frames["C1"][0], np.uint8), cv2.IMREAD_COLOR)
    jpegs = [as_jpeg(img), as_jpeg(img.copy())]
    assert jpegs[0][:2] == b"\xff\xd8" and jpegs[0] == jpegs[1]
    view = summarise(dep.cameras[0], jpegs, dep)
    assert view.verdict == "ok" and view.frames == 1 and view.frame == jpegs[0]


class MovingRig(Rig):
    """A rig whose LED, until capture's --on-point places it, moves along a free path: it
    holds each place for ``hold`` s (the cameras are not synchronised; a set spanning a jump
    is what a real free survey also sees, and the calibration rejects it)."""

    def __init__(self, scene, root: Path, path: np.ndarray, hold: float = 0.2, **kw):
        super().__init__(scene, root, **kw)
        self.path, self.hold, self.t0 = path, hold, time.monotonic()
        frames, _ = render_scene(scene, path, seed=11)
        self.moving = frames

    def frame(self, cid: str, variant: int) -> bytes:
        if self.current.exists():
            return super().frame(cid, variant)
        i = int((time.monotonic() - self.t0) / self.hold) % len(self.path)
        return self.moving[cid][i]


def _capture_free(root, rig, survey, points, *extra):
    """`survey capture --yes` of a free survey (25 s at 8 sets/s) and then ``points``, against
    ``rig``, which is closed after."""
    try:
        cmd = capture_cmd(root, rig, survey, "--yes", *extra, "--duration", "25", "--rate", "8")
        cmd[cmd.index("--points") + 1] = str(points)
        return subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    finally:
        rig.close()


def test_free_capture_then_references_calibrates_end_to_end(site, tmp_path):
    """`survey capture --free` against simulated MJPEG cameras: the free part records sets
    while the LED moves and reports each camera's coverage and the pairs; then the reference
    points; `survey calibrate` on the bundle succeeds and finds the cameras."""
    from vlpcal.sim.writers import free_path
    from vlpcal.survey import plan_references

    scene, root = site
    dep = deployment.load(root / "dep.yaml")
    refs = plan_references(dep)
    write_truth_csv(tmp_path / "refs.csv", refs.ids, refs.xyz, id_column="point_id")
    rig = MovingRig(scene, tmp_path, free_path(scene, 400), fps=30.0)
    survey = tmp_path / "survey"
    res = _capture_free(root, rig, survey, tmp_path / "refs.csv", "--delay", "0.1", "--free")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "free survey:" in res.stdout and "sightings" in res.stdout
    assert "pairs:" in res.stdout and "linked" in res.stdout
    bundle = read_survey_bundle(survey)
    assert len(bundle.free_ids) >= 100 and len(bundle.point_ids) == len(refs.ids)
    out = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(root / "dep.yaml"),
                                    "--survey", str(survey), "--out", str(tmp_path / "cal.yaml"),
                                    "-q"])
    assert out.exit_code == 0, out.output
    assert "where the free LED went" in out.output
    cal = deployment.load(tmp_path / "cal.yaml")
    for c, t in zip(cal.cameras, scene.true):
        assert np.linalg.norm(np.subtract(c.position, t.position)) < 0.02
    # run again: the free survey is resumed, not recorded twice over
    rig = MovingRig(scene, tmp_path, free_path(scene, 400), fps=30.0)
    try:
        cmd = capture_cmd(root, rig, survey, "--yes", "--free", "--free-sets",
                          str(len(bundle.free_ids)))
        cmd[cmd.index("--points") + 1] = str(tmp_path / "refs.csv")
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    finally:
        rig.close()
    assert res.returncode == 0, res.stderr[-2000:]
    assert f"{len(bundle.free_ids)} sets already in" in res.stdout
    assert len(read_survey_bundle(survey).free_ids) == len(bundle.free_ids)


class WandRig(MovingRig):
    """A wand (two LEDs on a bar) waved along ``path`` (M×2×3) until a frame mark is asked
    for; then one LED rests on the mark: the on-point hook writes the mark's id, and the
    rig knows where each mark really lies (``marks``: id → x y z)."""

    def __init__(self, scene, root: Path, path: np.ndarray, marks: dict, **kw):
        super().__init__(scene, root, path[:, 0], **kw)
        frames, _ = render_scene(scene, path, seed=11)
        self.moving, self.marks = frames, marks

    def frame(self, cid: str, variant: int) -> bytes:
        if self.current.exists():
            key = self.current.read_text().strip()
            with self.lock:
                if key not in self.cache:
                    p = np.repeat([self.marks[key]], VARIANTS, axis=0)
                    self.cache[key] = render_scene(self.scene, p, seed=zlib.crc32(
                        key.encode()))[0]
                return self.cache[key][cid][variant]
        return super().frame(cid, variant)

    def hook(self):
        return f"printf '%s' {{id}} > {self.current}"


def test_a_wand_survey_captured_live_calibrates_with_no_tape(site, tmp_path):
    """`survey capture --wand`: the wand waved past simulated MJPEG cameras (both spots kept
    per camera), then the LED resting on each frame mark of `survey plan --wand`'s file (a
    burst each, the cells nobody measured left empty); `survey calibrate --wand` on the
    bundle puts the cameras where they are, in the marks' frame."""
    from vlpcal.sim.writers import wand_path
    from vlpcal.survey.free_plan import plan_marks

    scene, root = site
    dep = deployment.load(root / "dep.yaml")
    marks = plan_marks(dep)
    (tmp_path / "marks.csv").write_text("point_id,x,y,z\nO,0,0,0\nX,,0,0\nF1,,,0\nF2,,,0\n"
                                        "F3,,,0\n")
    rig = WandRig(scene, tmp_path, wand_path(scene, 400, 0.5, 3),
                  dict(zip(marks.ids, marks.xyz.tolist())), fps=30.0)
    survey = tmp_path / "survey"
    res = _capture_free(root, rig, survey, tmp_path / "marks.csv", "--delay", "0.2", "--wand",
                        "0.5")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "wave the wand (0.5 m)" in res.stdout and "place the LED on mark X" in res.stdout
    assert "--wand 0.5 --out calibrated.yaml" in res.stdout
    assert (survey / "points.csv").read_text().splitlines()[1:3] == ["O,0.0,0.0,0.0",
                                                                     "X,,0.0,0.0"]
    bursts = [d for d in (survey / "frames" / "O").iterdir()]  # every distinct frame kept
    assert len(bursts) >= 2 and all(len(list(d.glob("*.jpg"))) == VARIANTS for d in bursts)
    doubles = [r for r in (survey / "free" / "observations.csv").read_text().splitlines()[1:]]
    assert len(doubles) > len({tuple(r.split(",")[:2]) for r in doubles})  # two spots per view
    out = CliRunner().invoke(main, ["survey", "calibrate", "-d", str(root / "dep.yaml"),
                                    "--survey", str(survey), "--wand", "0.5",
                                    "--out", str(tmp_path / "cal.yaml"), "-q"])
    assert out.exit_code == 0, out.output
    cal = deployment.load(tmp_path / "cal.yaml")
    o = marks.xyz[0]
    for c, t in zip(cal.cameras, scene.true):  # the marks' frame: O the origin, x along x
        assert np.linalg.norm(np.subtract(c.position, np.subtract(t.position, o))) < 0.02


def test_a_free_capture_shows_its_coverage_pairs_and_next_point_live(site, tmp_path):
    """`survey capture --free --view`: the page's stream carries each camera's frames with
    their spots, what the LED covered in each image and the camera pairs it linked, then the
    reference point to capture next."""
    import json
    import re
    import urllib.request

    from vlpcal.sim.writers import free_path
    from vlpcal.survey import plan_references

    scene, root = site
    dep = deployment.load(root / "dep.yaml")
    refs = plan_references(dep)
    write_truth_csv(tmp_path / "refs.csv", refs.ids, refs.xyz, id_column="point_id")
    rig = MovingRig(scene, tmp_path, free_path(scene, 400), fps=30.0)
    cmd = capture_cmd(root, rig, tmp_path / "survey", "--yes", "--free", "--duration", "12",
                      "--rate", "8", "--delay", "0.1", "--view", "127.0.0.1:0")
    cmd[cmd.index("--points") + 1] = str(tmp_path / "refs.csv")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    updates = []
    try:
        url = None
        for _ in range(20):
            m = re.search(r"view: (http://\S+)", proc.stderr.readline())
            if m:
                url = m.group(1)
                break
        assert url, "no view address"
        end = time.monotonic() + 60
        with urllib.request.urlopen(url + "events", timeout=30) as stream:
            for line in stream:
                if line.startswith(b"data: ") and b'"cameras"' in line:
                    updates.append(json.loads(line[6:]))
                if any(u.get("survey", {}).get("stop") for u in updates) \
                        or time.monotonic() > end:
                    break
        proc.wait(120)
    finally:
        if proc.poll() is None:
            proc.kill()
        rig.close()
    assert proc.returncode == 0, proc.stderr.read()[-2000:]
    framed = {cid for u in updates for cid, c in u["cameras"].items()
              if c.get("jpeg") and c.get("jpeg_uv")}
    assert framed == {c.id for c in dep.cameras}  # each camera's frames, its spot on them
    covered = [u["survey"]["coverage"] for u in updates if "coverage" in u.get("survey", {})]
    assert covered and covered[-1]["pairs"]  # the pairs linked so far
    last = covered[-1]["cameras"]
    assert all(sum(last[c.id]["counts"]) == last[c.id]["sightings"] > 0 for c in dep.cameras)
    stop = next(u["survey"]["stop"] for u in updates if u.get("survey", {}).get("stop"))
    assert stop["id"] == refs.ids[0] and stop["number"] == 1 and stop["total"] == len(refs.ids)
