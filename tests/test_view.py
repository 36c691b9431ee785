"""The live page (issue 30): its hub never holds a command up, its server asks for the token
off loopback and loads nothing from outside, and in a real browser (Debian's Chromium,
headless) it shows a simulated live site as the command tracks it."""

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from vlpcal.deployment import load
from vlpcal.view import ViewHub
from vlpcal.view.hub import ROWS_KEPT
from vlpcal.view.scene import scene, site_of
from vlpcal.view.server import STATIC, ViewError, ViewServer, parse_bind

LAYOUT = Path(__file__).parents[1] / "layouts" / "paper-linear.deployment.yaml"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: without a browser these tests are skipped — except in CI, which installs one and asks
#: for them (a skip there would hide them)
needs_browser = pytest.mark.skipif(
    not Path(CHROMIUM).exists() and os.environ.get("VLPCAL_BROWSER_TESTS") != "required",
    reason="Debian's chromium is not installed (.ci/run installs it)")


class _Row:
    def __init__(self, t, led, xyz):
        self.t, self.led, self.position = t, led, np.array(xyz, float)
        self.sigma_m, self.cameras, self.status, self.pose = 0.001, "C1+C2", "ok", None


def test_the_hub_keeps_every_row_for_a_page_and_only_the_latest_frame():
    hub = ViewHub({"C1": (160, 120)})
    for k in range(5):
        hub.frame("C1", 100.0 + k, [[10.0 + k, 20.0], [np.nan, np.nan]], jpeg=b"j%d" % k)
    hub.track_rows([_Row(1.0 + k, "L1", (k, 0, 0)) for k in range(7)], utc=1000.0)
    seen: dict = {}
    cams, rows, missed = hub.since(0, seen)
    assert cams["C1"]["seq"] == 5 and cams["C1"]["uv"] == [[14.0, 20.0]]  # NaN: no spot
    assert [r["n"] for r in rows] == list(range(1, 8)) and rows[0]["t"] == 1001.0
    assert missed == 0
    assert hub.latest_frame("C1")[0] == 5 and hub.latest_frame("C1")[3] == b"j4"
    cams, rows, missed = hub.since(7, seen)  # nothing new: nothing sent
    assert cams == {} and rows == [] and missed == 0
    # a page far behind is told how many rows it can no longer read, then reads on
    hub.track_rows([_Row(k, "L1", (0, 0, 0)) for k in range(ROWS_KEPT + 3)])
    cams, rows, missed = hub.since(7, seen)
    assert missed == 3 and rows[0]["n"] == 11


def test_bind_addresses_are_read_as_a_person_writes_them():
    assert parse_bind("127.0.0.1:8765") == ("127.0.0.1", 8765)
    assert parse_bind(":9000") == ("127.0.0.1", 9000)
    assert parse_bind("9000") == ("127.0.0.1", 9000)
    assert parse_bind("0.0.0.0") == ("0.0.0.0", 8765)
    assert parse_bind("[::1]:80") == ("::1", 80)
    with pytest.raises(ViewError, match="port 0–65535"):
        parse_bind("host:99999")


def _get(url):
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read(), dict(e.headers)


def test_off_loopback_the_view_refuses_a_request_without_its_token():
    dep = load(LAYOUT)
    server = ViewServer(scene(site_of(dep), dep.cameras), ViewHub({}), "0.0.0.0", 0)
    try:
        base = f"http://127.0.0.1:{server.port}/"
        assert server.token and server.token in server.url
        for path in ("", "scene", "events", "static/view.js", "frame/C1"):
            status, body, _ = _get(base + path)
            assert status == 403 and b"token" in body, path
        status, _, _ = _get(base + "scene?token=wrong" + server.token)
        assert status == 403
        status, body, headers = _get(base + f"scene?token={server.token}")
        assert status == 200 and json.loads(body)["name"] == dep.name
        assert "default-src 'self'" in headers["Content-Security-Policy"]
        assert server.refused == 6
    finally:
        server.close()
    # on loopback it is open, and says so by printing no token
    server = ViewServer(scene(site_of(dep), dep.cameras), None, "127.0.0.1", 0)
    try:
        assert server.token is None and "token" not in server.url
        assert _get(f"http://127.0.0.1:{server.port}/scene")[0] == 200
    finally:
        server.close()


def test_a_port_in_use_is_one_line_not_a_traceback():
    dep = load(LAYOUT)
    first = ViewServer(scene(site_of(dep), dep.cameras), None, "127.0.0.1", 0)
    try:
        res = subprocess.run([sys.executable, "-m", "vlpcal", "view", str(LAYOUT), "--bind",
                              f"127.0.0.1:{first.port}", "--duration", "1"],
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2 and "cannot serve the view there" in res.stderr
        assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    finally:
        first.close()


def test_the_page_loads_nothing_from_outside():
    for f in STATIC.iterdir():
        text = f.read_text()
        assert not re.search(r"(https?:)?//[a-z0-9]", text.replace("http://", "")
                             .replace("https://", "")), f  # no URL of another host
        assert "http://" not in text and "https://" not in text, f


def test_the_scene_has_each_camera_footprints_and_maps_to_hover():
    dep = load(LAYOUT)
    doc = scene(site_of(dep), dep.cameras).doc
    assert [c["id"] for c in doc["cameras"]] == [c.id for c in dep.cameras]
    lo, hi = doc["heights"]
    assert lo == 0.0 and 0 < hi < dep.ceiling_height
    cam = doc["cameras"][1]
    # a higher plane is nearer the camera: its footprint is smaller
    def area(f):  # the shoelace formula
        x, y = np.array(f)[:-1].T
        return abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))) / 2

    area = [area(f) for f in cam["footprints"]]
    assert area[1] < area[0]
    g, m = doc["grid"], doc["maps"][0]
    assert len(m["views"]) == g["nx"] * g["ny"] == len(m["error"]) == len(m["cameras"])
    # under C2 every camera of the line sees the floor; its predicted error is a few mm
    i = round((dep.cameras[1].position[0] - g["x0"]) / g["step"])
    j = round((dep.cameras[1].position[1] - g["y0"]) / g["step"])
    k = j * g["nx"] + i
    assert m["views"][k] == len(m["cameras"][k]) >= 2 and 0 < m["error"][k] < 0.02


# -- in a real browser ---------------------------------------------------------------------------
def _browser(pw):
    return pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS)


def _ready(page, timeout=30.0):
    """Wait for the page to have drawn its plan — polled from here: Playwright's own waiting
    evaluates strings, which the page's Content-Security-Policy forbids."""
    end = time.monotonic() + timeout
    while not page.evaluate("!!(window.vlpcalView && window.vlpcalView.ready)"):
        assert time.monotonic() < end, "the page never became ready"
        time.sleep(0.05)


def _url_of(proc, timeout=60):
    """The page's address, from the command's first lines on stderr."""
    end = time.monotonic() + timeout
    seen = []
    while time.monotonic() < end:
        line = proc.stderr.readline()
        if not line:
            break
        seen.append(line)
        m = re.search(r"view: (http://\S+)", line)
        if m:
            return m.group(1)
    raise AssertionError("no view address: " + "".join(seen))


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    """A simulated site of four live cameras (paper-square, MJPEG on 127.0.0.1, each on its
    own clock) and a robot's LED at 1.5 m/s, tracked by ``vlpcal track --view`` while a
    headless Chromium watches the page: the page's samples, the rows written, the truth."""
    from playwright.sync_api import sync_playwright

    sys.path.insert(0, str(Path(__file__).parent))
    from dataclasses import replace

    from test_tracking import square_rig

    from vlpcal.deployment import save
    from vlpcal.sim.mjpeg import StreamServer
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.streams import robot_path, simulate_streams
    from vlpcal.sim.writers import deployment_of

    tmp = tmp_path_factory.mktemp("view")
    scene_ = make_scene(replace(get_profile("paper-2024"), name="paper-square",
                                nominal=tuple(square_rig().cameras),
                                room=((0, 0), (2.6, 0), (2.6, 2.4), (0, 2.4))), 0)
    dep = deployment_of(scene_, "true")
    save(dep, tmp / "d.yaml")
    path = robot_path(scene_, 1.5)
    seconds = 8.0
    simulate_streams(scene_, tmp / "s", path, seconds)
    server = StreamServer(tmp / "s", latency=0.001, latency_jitter=0.002, start=4.0)
    cmd = [sys.executable, "-m", "vlpcal", "track", "-d", str(tmp / "d.yaml"), "--out",
           str(tmp / "t.csv"), "--duration", str(seconds + 4.5), "--view", "127.0.0.1:0"]
    for cam in dep.cameras:
        cmd += ["--camera", f"{cam.id}={server.url(cam.id)}"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    samples, frames = [], {}
    try:
        url = _url_of(proc)
        with sync_playwright() as pw:
            browser = _browser(pw)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            _ready(page)
            t0 = time.monotonic()
            shot = False
            while proc.poll() is None and time.monotonic() - t0 < seconds + 20:
                samples.append(page.evaluate("""() => {
                    const s = window.vlpcalView, tr = {};
                    for (const [id, t] of Object.entries(s.tracks)) tr[id] = {xyz: t.xyz, t: t.t};
                    const tiles = {};
                    for (const [id, t] of Object.entries(s.tiles))
                        tiles[id] = {seq: t.shownSeq, drawn: t.drawn};
                    return {at: Date.now() / 1000, updates: s.updates, tracks: tr, tiles};
                }"""))
                for cid in (c.id for c in dep.cameras) if len(samples) % 4 == 0 else ():
                    got = page.evaluate("id => window.vlpcalView.tileFrame(id)", cid)
                    if got and got["spots"]:
                        frames.setdefault(cid, []).append(got)
                if not shot and len(samples) > 10 and samples[-1]["tracks"]:
                    out = Path(__file__).parents[1] / "benchmarks" / "out"
                    out.mkdir(parents=True, exist_ok=True)
                    page.screenshot(path=str(out / "view-live.png"), full_page=True)
                    shot = True
                time.sleep(0.1)
            latency = page.evaluate("window.vlpcalView.latencies()")
            browser.close()
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
        server.close()
    rows = list(csv.DictReader(open(tmp / "t.csv")))
    return {"samples": samples, "frames": frames, "rows": rows, "latency": latency,
            "returncode": proc.returncode, "cameras": [c.id for c in dep.cameras]}


@needs_browser
def test_the_page_shows_each_live_camera_with_its_spot_where_the_frame_has_it(live_run):
    assert live_run["returncode"] == 0
    last = live_run["samples"][-1]
    assert sorted(last["tiles"]) == sorted(live_run["cameras"])  # four tiles
    for cid in live_run["cameras"]:
        assert last["tiles"][cid]["drawn"] > 10, cid
        checked = 0
        for got in live_run["frames"].get(cid, []):
            grey = np.array(got["grey"], float).reshape(got["height"], got["width"])
            # the spot where the frame has it: the bright blob's centroid, found here
            # independently (the top pixels above half the peak over the background)
            v, u = np.unravel_index(np.argmax(grey), grey.shape)
            lo, hi = np.median(grey), grey[v, u]
            rows_, cols_ = slice(max(v - 6, 0), v + 7), slice(max(u - 6, 0), u + 7)
            win = grey[rows_, cols_]
            w = np.clip(win - (lo + hi) / 2, 0, None)
            vv, uu = np.mgrid[rows_, cols_][:, :win.shape[0], :win.shape[1]]
            centre = np.array([(w * uu).sum(), (w * vv).sum()]) / w.sum()
            drawn = np.array(got["spots"], float)
            assert np.min(np.linalg.norm(drawn - centre, axis=1)) <= 2.0, (cid, drawn, centre)
            checked += 1
        assert checked >= 3, cid


@needs_browser
def test_the_page_moves_the_track_with_the_fixes_the_run_writes(live_run):
    rows = live_run["rows"]
    assert sum(r["status"] == "ok" for r in rows) > 100
    written = {(r["led"], round(float(r["t"]), 6)): np.array([float(r[c] or "nan") for c in "xyz"])
               for r in rows}
    shown = [(id_, s["t"], s["xyz"]) for x in live_run["samples"] for id_, s in x["tracks"].items()]
    assert len(shown) > 20
    near = []
    for id_, t, xyz in shown:
        X = written.get((id_, round(t, 6)))
        assert X is not None, (id_, t)  # a row the run wrote…
        near.append(np.linalg.norm(np.array(xyz, float) - X))
    assert max(near) <= 0.01  # … drawn where the run put it (within 1 cm)
    xy = np.array([xyz[:2] for _, _, xyz in shown])
    assert np.ptp(xy, axis=0).max() > 0.5  # and it moved on the page as the LED drove
    # the page updated at 5 Hz or more while the LED moved
    s = [x for x in live_run["samples"] if x["tracks"]]
    rate = (s[-1]["updates"] - s[0]["updates"]) / (s[-1]["at"] - s[0]["at"])
    assert rate >= 5, rate
    lat = live_run["latency"]
    assert lat["frame_p50"] is not None and 0 < lat["frame_p95"] < 2.0, lat


@needs_browser
def test_a_browser_without_the_token_is_refused_off_loopback(tmp_path):
    from playwright.sync_api import sync_playwright

    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "view", str(LAYOUT), "--bind",
                             "0.0.0.0:0", "--duration", "60"], stderr=subprocess.PIPE, text=True)
    try:
        url = _url_of(proc)
        token = url.split("token=")[1]
        bare = url.split("?")[0]
        with sync_playwright() as pw:
            browser = _browser(pw)
            page = browser.new_page()
            res = page.goto(bare)
            assert res.status == 403 and "token" in page.content()
            page.goto(url)
            _ready(page)
            assert page.evaluate("window.vlpcalView.scene.cameras.length") == 3
            page.goto(bare)  # the token given once is kept by this browser (a cookie)
            _ready(page)
            browser.close()
        assert token
    finally:
        proc.terminate()
        proc.wait(10)


def test_the_view_follows_what_a_running_track_publishes(broker):
    """``vlpcal view D --follow mqtt://…/prefix``: the fixes, tracks and bodies a running
    command publishes (and the spots the cameras publish) reach the page; a message that is
    none of them is counted, not shown."""
    import paho.mqtt.client as mqtt

    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "view", str(LAYOUT), "--bind",
                             "127.0.0.1:0", "--follow", broker.url("lab"), "--duration", "8"],
                            stderr=subprocess.PIPE, text=True)
    try:
        url = _url_of(proc)
        assert "following" in proc.stderr.readline()
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        c.connect("127.0.0.1", broker.port)
        c.loop_start()
        now = time.time()
        track = {"t": now, "led": "L1", "x": 1.2, "y": 0.9, "z": 0.15, "vx": 1.0, "vy": 0.0,
                 "vz": 0.0, "sigma_m": 0.002, "cameras": "C1+C2", "status": "ok"}
        body = dict(track, led="R1", yaw=0.5, pitch=None, roll=None, sigma_yaw=0.01)
        fix = {"t": now, "frame_id": "7", "x": None, "y": None, "z": None, "sigma_m": None,
               "cameras": "", "status": "degenerate"}
        for topic, payload in (("lab/fixes/L1", track), ("lab/bodies/R1", body),
                               ("lab/fixes/L2", fix), ("lab/spots/C2", {"t": now, "u": 80.5,
                                                                        "v": 60.25}),
                               ("lab/fixes/L3", {"t": "soon"})):
            c.publish(topic, json.dumps(payload)).wait_for_publish()
        c.disconnect()
        c.loop_stop()
        got, end = [], time.monotonic() + 10
        with urllib.request.urlopen(url + "events", timeout=10) as stream:
            for line in stream:
                if line.startswith(b"data: ") and b'"rows"' in line:
                    got.append(json.loads(line[6:]))
                rows = [r for g in got for r in g["rows"]]
                spots = [c for g in got for c in g["cameras"].items()]
                if len(rows) >= 3 and spots or time.monotonic() > end:
                    break
        ids = {r["id"]: r for r in rows}
        assert ids["L1"]["xyz"] == [1.2, 0.9, 0.15] and ids["L1"]["kind"] == "track"
        assert ids["R1"]["yaw"] == 0.5 and ids["L2"]["xyz"] is None
        assert "L3" not in ids
        assert [c["uv"] for cid, c in spots if cid == "C2"][-1] == [[80.5, 60.25]]
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=10)
    assert "1 message on" in err and "was not a fix" in err, err


def test_track_draws_its_run_on_the_plan_when_asked(tmp_path):
    """``track --plot run.png``: the paths on the plan and sigma over time, a PNG written
    beside the tracks; a name that is not .png, or the tracks' own file, is refused first."""
    sim = tmp_path / "sim"
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--profile", "paper-2024",
                          "--test-points", "0", "--robot-speed", "1.5", "--body", "2",
                          "--seconds", "3", "--out", str(sim)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    track = [sys.executable, "-m", "vlpcal", "track", "-d", str(sim / "truth.yaml"), "--frames",
             str(sim / "streams"), "--out", str(tmp_path / "t.csv")]
    res = subprocess.run(track + ["--plot", str(tmp_path / "run.jpg")], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 2 and "a PNG picture" in res.stderr, res.stderr
    same = track[:-1] + [str(tmp_path / "run.png"), "--plot", str(tmp_path / "run.png")]
    res = subprocess.run(same, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and "same file as --out" in res.stderr, res.stderr
    assert not (tmp_path / "t.csv").exists() and not (tmp_path / "run.png").exists()
    res = subprocess.run(track + ["--plot", str(tmp_path / "run.png")], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    png = (tmp_path / "run.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 20_000
    assert (tmp_path / "t.csv").exists()


def test_locate_draws_its_fixes_when_asked(tmp_path):
    """``locate --plot fixes.png``: the fixes on the plan and their sigma, written with the
    fixes; an interrupted or refused run draws nothing."""
    sim = tmp_path / "sim"
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--profile", "paper-2024",
                          "--test-points", "0", "--trajectory", "60", "--out", str(sim)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    cmd = [sys.executable, "-m", "vlpcal", "locate", "-d", str(sim / "truth.yaml"), "--frames",
           str(sim / "frames"), "--out", str(tmp_path / "f.csv")]
    res = subprocess.run(cmd + ["--plot", str(tmp_path / "f.gif")], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 2 and "a PNG picture" in res.stderr, res.stderr
    res = subprocess.run(cmd + ["--plot", str(tmp_path / "f.png")], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "f.png").read_bytes().startswith(b"\x89PNG")


def test_a_calibrated_deployment_shows_its_report(tmp_path):
    """A deployment with ``survey calibrate``'s report beside it: the page gets per camera how
    far it moved and turned, the held-out errors, and the report's figure; one without (or
    with a report that cannot be read) is shown without it."""
    from vlpcal.cli.view import _calibration

    shutil.copy(LAYOUT, tmp_path / "d.yaml")
    (tmp_path / "d.report.json").write_text(json.dumps({
        "cameras": [{"camera": "C1", "moved_m": 0.0182, "turned_deg": 0.48, "lens_model": "k1"}],
        "held_out_m": {"calibrated, all-camera LS": {"mean": 0.0052, "p95": 0.0091,
                                                     "fixed": 0.87}}}))
    (tmp_path / "d.png").write_bytes(b"\x89PNG fake")
    cal, figure = _calibration(tmp_path / "d.yaml")
    assert cal["cameras"] == [{"id": "C1", "moved_mm": 18.2, "turned_deg": 0.48, "lens": "k1"}]
    assert cal["held_out"]["calibrated, all-camera LS"]["mean_m"] == 0.0052
    assert figure == b"\x89PNG fake" and cal["figure"]
    dep = load(tmp_path / "d.yaml")
    server = ViewServer(scene(site_of(dep), dep.cameras, cal), None, "127.0.0.1", 0,
                        figure=figure)
    try:
        base = f"http://127.0.0.1:{server.port}/"
        assert json.loads(_get(base + "scene")[1])["calibration"]["cameras"][0]["id"] == "C1"
        assert _get(base + "report.png")[1] == figure
    finally:
        server.close()
    (tmp_path / "d.report.json").write_text("{not json")
    assert _calibration(tmp_path / "d.yaml") == (None, None)
    assert _calibration(LAYOUT) == (None, None)


def test_the_view_tracks_the_spots_cameras_publish(broker, tmp_path):
    """``vlpcal view D --spots mqtt://…``: the spots a site's cameras publish, on the tiles,
    and the LED tracked on the plan, nothing written."""
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.writers import write_deployments

    write_deployments(make_scene(get_profile("paper-2024"), 0), tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "view", str(tmp_path / "truth.yaml"),
                             "--bind", "127.0.0.1:0", "--spots", broker.url("lab"),
                             "--duration", "20"], stderr=subprocess.PIPE, text=True)
    try:
        url = _url_of(proc)
        pub = subprocess.Popen([sys.executable, "-m", "vlpcal", "simulate", "--profile",
                                "paper-2024", "--publish", broker.url("lab"), "--seconds", "3",
                                "--robot-speed", "1"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        rows, spots, end = [], set(), time.monotonic() + 30
        with urllib.request.urlopen(url + "events", timeout=30) as stream:
            for line in stream:
                if line.startswith(b"data: ") and b'"rows"' in line:
                    u = json.loads(line[6:])
                    rows += [r for r in u["rows"] if r["status"] == "ok"]
                    spots |= {cid for cid, c in u["cameras"].items() if c["uv"]}
                if len(rows) > 20 and len(spots) == 3 or time.monotonic() > end:
                    break
        pub.wait(60)
    finally:
        proc.terminate()
        proc.wait(20)
    assert len(rows) > 20 and spots == {"C1", "C2", "C3"}
    assert all(r["kind"] == "track" and r["xyz"] is not None for r in rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


def test_a_loopback_view_refuses_a_page_of_another_host(tmp_path):
    """From a hostile probe: bound to loopback the view answered any Host — a page of another
    site whose name a DNS rebinding points at 127.0.0.1 could read the cameras and tracks.
    Off loopback a token that is not ASCII was a 500 and a traceback, not a refusal."""
    dep = load(LAYOUT)
    server = ViewServer(scene(site_of(dep), dep.cameras), None, "127.0.0.1", 0)
    try:
        url = f"http://127.0.0.1:{server.port}/scene"
        for host, status in (("evil.example", 403), (f"evil.example:{server.port}", 403),
                             (f"localhost:{server.port}", 200), (f"127.0.0.1:{server.port}", 200),
                             (f"[::1]:{server.port}", 200)):
            req = urllib.request.Request(url, headers={"Host": host})
            try:
                with urllib.request.urlopen(req, timeout=5) as r:
                    got = r.status
            except urllib.error.HTTPError as e:
                got = e.code
            assert got == status, host
    finally:
        server.close()
    server = ViewServer(scene(site_of(dep), dep.cameras), None, "0.0.0.0", 0)
    try:
        assert _get(f"http://127.0.0.1:{server.port}/scene?token=%C3%A9")[0] == 403
    finally:
        server.close()


def test_a_plot_through_a_link_to_the_rows_is_refused(tmp_path):
    """From a hostile probe: ``--plot`` a link to the ``--out`` file wrote the figure over
    the rows, exit 0."""
    (tmp_path / "link.png").symlink_to(tmp_path / "f.csv")
    (tmp_path / "frames").mkdir()
    res = subprocess.run([sys.executable, "-m", "vlpcal", "locate", "-d", str(LAYOUT),
                          "--frames", str(tmp_path / "frames"), "--out", str(tmp_path / "f.csv"),
                          "--plot", str(tmp_path / "link.png")], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 2 and "same file as --out" in res.stderr, res.stderr


@needs_browser
def test_ids_that_name_javascript_builtins_are_ids_like_any_other(broker, tmp_path):
    """From a hostile probe: a camera called ``toString`` (or a track ``__proto__``) found a
    built-in where the page kept its tiles and tracks: every update threw, nothing drawn."""
    import paho.mqtt.client as mqtt
    from playwright.sync_api import sync_playwright

    text = LAYOUT.read_text().replace("id: C2", "id: toString")
    (tmp_path / "d.yaml").write_text(text)
    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "view", str(tmp_path / "d.yaml"),
                             "--bind", "127.0.0.1:0", "--follow", broker.url("lab"),
                             "--duration", "40"], stderr=subprocess.PIPE, text=True)
    try:
        url = _url_of(proc)
        with sync_playwright() as pw:
            browser = _browser(pw)
            page = browser.new_page()
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(url)
            _ready(page)
            time.sleep(0.5)
            c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
            c.connect("127.0.0.1", broker.port)
            c.loop_start()
            now = time.time()
            for k in range(5):
                c.publish("lab/spots/toString", json.dumps({"t": now + k / 10, "u": 80.0,
                                                            "v": 60.0})).wait_for_publish()
                for led in ("__proto__", "constructor", "L1"):
                    c.publish(f"lab/fixes/{led}", json.dumps({
                        "t": now + k / 10, "led": led, "x": 1.0 + k / 10, "y": 0.9, "z": 0.1,
                        "vx": 1.0, "vy": 0.0, "vz": 0.0, "sigma_m": 0.002, "cameras": "C1+C3",
                        "status": "ok"})).wait_for_publish()
            c.disconnect()
            c.loop_stop()
            end = time.monotonic() + 10  # (polled from here: the page's policy forbids eval)
            while page.evaluate("Object.keys(window.vlpcalView.tracks).length") < 3:
                assert time.monotonic() < end, "the tracks never came"
                time.sleep(0.1)
            got = page.evaluate("""() => ({tracks: Object.keys(window.vlpcalView.tracks).sort(),
                tile: !!window.vlpcalView.tiles["toString"].cv,
                leaked: ({}).xyz !== undefined})""")
            browser.close()
        assert not errors, errors
        assert got == {"tracks": ["L1", "__proto__", "constructor"], "tile": True,
                       "leaked": False}
    finally:
        proc.terminate()
        proc.wait(20)
