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


def test_capture_exits_1_when_every_camera_sends_too_slowly(tmp_path):
    """Cameras that send, but too slowly to make a frame, stopped `survey capture`
    with exit 2 (a user's mistake) where the README documents 1, as a live `locate` without
    frames exits: each camera named with why, nothing written."""
    import subprocess
    import sys
    import threading
    import time
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    from vlpcal import deployment
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.writers import deployment_of

    stop = threading.Event()

    class Trickle(BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
            self.end_headers()
            try:  # a byte every half second: never a whole frame within the read timeout
                while not stop.is_set():
                    self.wfile.write(b"-")
                    self.wfile.flush()
                    time.sleep(0.5)
            except OSError:
                pass

        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Trickle)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/stream"
    dep = deployment_of(make_scene(get_profile("paper-2024"), 0), "true")
    deployment.save(dep, tmp_path / "dep.yaml")
    (tmp_path / "points.csv").write_text("point_id,x,y,z\nS1,1.0,0.8,0.0\n")
    try:
        res = subprocess.run(
            [sys.executable, "-m", "vlpcal", "survey", "capture", "-d", str(tmp_path / "dep.yaml"),
             "--points", str(tmp_path / "points.csv"), "--survey", str(tmp_path / "s"), "--yes",
             "--camera", f"C1={url}", "--camera", f"C2={url}", "--camera", f"C3={url}"],
            capture_output=True, text=True, timeout=120)
    finally:
        stop.set()
        server.shutdown()
        server.server_close()
    assert res.returncode == 1, (res.returncode, res.stderr)
    assert "no camera answered (C1: " in res.stderr and "sends too slowly" in res.stderr, \
        res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "s").exists()
