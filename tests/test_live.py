"""Live sources: MJPEG served from 127.0.0.1, located by `vlpcal locate --camera`."""

import csv
import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest

from vlpcal import deployment
from vlpcal.live import LiveGrouper, mjpeg_frames
from vlpcal.sim.mjpeg import mjpeg_head, mjpeg_part
from vlpcal.sim.profiles import get_profile
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import deployment_of

POINTS = np.array([[1.5, 0.5, 0.0], [1.9, 1.2, 0.15], [2.1, 0.6, 0.35]])
REPEAT = 8  # frames per position


class Streams:
    """One MJPEG stream per camera at /<camera_id>, like an ESP32-CAM's :81/stream."""

    def __init__(self, frames: dict, fps: float = 20.0, stop_after: int | None = None):
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                jpegs = frames.get(self.path.strip("/"))
                if jpegs is None:
                    self.send_error(404)
                    return
                mjpeg_head(self)
                try:
                    for i, jpg in enumerate(jpegs):
                        if outer.stop_after is not None and i >= outer.stop_after:
                            self.connection.shutdown(2)  # the camera dies mid-stream
                            return
                        self.wfile.write(mjpeg_part(jpg))
                        self.wfile.flush()
                        time.sleep(1.0 / fps)
                except (BrokenPipeError, ConnectionResetError, OSError):
                    pass

        self.stop_after = stop_after
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def url(self, cid):
        return f"http://127.0.0.1:{self.port}/{cid}"

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    root = tmp_path_factory.mktemp("live")
    scene = make_scene(get_profile("paper-2024"), seed=5)
    path = root / "truth.yaml"
    deployment.save(deployment_of(scene, "true"), path)
    frames, _ = render_scene(scene, np.repeat(POINTS, REPEAT, axis=0), seed=1)
    return path, frames


def run_locate(path, streams, out, *extra):
    args = [sys.executable, "-m", "vlpcal", "locate", "-d", str(path), "--out", str(out),
            "--tolerance", "0.02", *extra]
    for cid in ("C1", "C2", "C3"):
        args += ["--camera", f"{cid}={streams.url(cid)}"]
    return subprocess.run(args, capture_output=True, text=True, timeout=60)


def test_mjpeg_parser_reads_every_frame(rig):
    _, frames = rig
    streams = Streams(frames, fps=200)
    try:
        got = list(mjpeg_frames(streams.url("C2")))
    finally:
        streams.close()
    assert got == frames["C2"]


def test_locate_live_mjpeg_streams(rig, tmp_path):
    path, frames = rig
    streams = Streams(frames)
    try:
        res = run_locate(path, streams, tmp_path / "fixes.csv")
    finally:
        streams.close()
    assert res.returncode == 0, res.stderr
    rows = list(csv.DictReader((tmp_path / "fixes.csv").open()))
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) >= 0.5 * len(POINTS) * REPEAT
    X = np.array([[float(r[k]) for k in "xyz"] for r in ok])
    nearest = np.min(np.linalg.norm(X[:, None, :] - POINTS[None], axis=2), axis=1)
    assert np.median(nearest) < 0.01
    assert {"t_s", "camera_status"} <= set(rows[0])
    # t_s in UTC seconds, as the README says (it counted from the command's start)
    import time

    t_s = np.array([float(r["t_s"]) for r in rows])
    assert (t_s > time.time() - 300).all() and (t_s <= time.time()).all(), t_s[:3]
    assert (np.diff(t_s) >= 0).all()


def test_a_camera_that_dies_mid_stream_is_reported_and_the_fixes_are_kept(rig, tmp_path):
    path, frames = rig
    streams = Streams(frames, stop_after=10)
    try:
        res = run_locate(path, streams, tmp_path / "fixes.csv")
    finally:
        streams.close()
    assert res.returncode == 0, res.stderr
    assert "camera C1: stream ended after" in res.stderr
    assert "Traceback" not in res.stderr
    rows = list(csv.DictReader((tmp_path / "fixes.csv").open()))
    assert 3 <= sum(r["status"] == "ok" for r in rows) <= 12


def test_grouper_reports_a_camera_that_never_answers():
    def dead():
        raise ConnectionRefusedError("connection refused")
        yield  # pragma: no cover

    events = []
    grouper = LiveGrouper({"C1": lambda: iter([b"a", b"b"]), "C2": dead}, tolerance=0.01,
                          on_event=events.append)
    sets = list(grouper)
    assert any("camera C2: connection refused after 0 frames" in e for e in events)
    assert [fs.frames for fs in sets] == [{"C1": b"a"}, {"C1": b"b"}]
    assert grouper.stats.missing["C2"] >= 1 or grouper.stats.ended["C2"]
