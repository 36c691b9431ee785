"""Robots, not dots (issue 29): a deployment's bodies: block, the pose of a body from its LEDs'
rays at their own times, `vlpcal track` rows and MQTT topics of bodies, and `vlpcal simulate
--body`."""

import csv
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from test_several_leds import crossing_events, square_rig

from vlpcal import deployment
from vlpcal.blink import BlinkCode
from vlpcal.bodies import angles, pose_from_points, rotation
from vlpcal.sim.streams import BODY_LAYOUTS, body_blocks, body_leds
from vlpcal.tracking import Tracker

CODES = [BlinkCode("L1", "0010111101", 10), BlinkCode("L2", "0011001111", 10),
         BlinkCode("L3", "0101010111", 10)]


def body_rig(n=2):
    doc = square_rig(CODES[:n]).to_dict()
    doc["bodies"] = [{"id": "R1", "leds": {k: list(v) for k, v in BODY_LAYOUTS[n].items()}}]
    return deployment.from_dict(doc, "rig.yaml")


@pytest.mark.parametrize("bodies, expected", [
    ([{"id": "R1", "leds": {"L1": [0, 0, 0]}}], "bodies[0].leds: expected 2 to 16"),
    ([{"id": "L1", "leds": {"L1": [0, 0, 0], "L2": [1, 0, 0]}}], "also an LED's id"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L9": [1, 0, 0]}}], "bodies[0].leds.L9: not an LED"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L2": [0, 0, 0]}}], "two LEDs at the same place"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L2": [1, 0]}}], "bodies[0].leds.L2: expected a list"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L2": [1, 0, 0]}},
      {"id": "R2", "leds": {"L1": [0, 0, 0], "L3": [1, 0, 0]}}], "already on body R1"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L2": [float("nan"), 0, 0]}}], "leds.L2[0]"),
    ({"R1": 1}, "bodies: expected a list"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0.1], "L2": [0, 0, 0.3]}}], "one vertical line"),
    ([{"id": "R1", "leds": {"L1": [0, 0, 0], "L2": [2e5, 0, 0]}}], "leds.L2[0]"),
])
def test_the_bodies_block_is_checked(bodies, expected):
    doc = square_rig(CODES).to_dict()
    doc["bodies"] = bodies
    with pytest.raises(deployment.DeploymentError) as e:
        deployment.from_dict(doc, "site.yaml")
    assert str(e.value).startswith("site.yaml: ") and expected in str(e.value), str(e.value)


def test_the_bodies_block_round_trips_and_meets_the_schema(tmp_path):
    import json

    import jsonschema

    dep = body_rig(3)
    deployment.save(dep, tmp_path / "d.yaml")
    back = deployment.load(tmp_path / "d.yaml").bodies
    assert [b.id for b in back] == ["R1"] and back[0].full_pose
    assert not body_rig(2).bodies[0].full_pose  # two LEDs: the heading only
    schema = json.loads(deployment.SCHEMA_PATH.read_text())
    jsonschema.validate(dep.to_dict(), schema)
    bad = dep.to_dict()
    bad["bodies"][0]["leds"]["L1"] = [0, 0]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_angles_and_points_give_back_the_rotation():
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = rng.uniform([-np.pi, -1.4, -np.pi], [np.pi, 1.4, np.pi])
        assert np.allclose(angles(rotation(*a)), a)
        body = rng.normal(size=(4, 3))
        pos = rng.normal(size=3)
        got_pos, got = pose_from_points(body, pos + body @ rotation(*a).T)
        assert np.allclose(got_pos, pos) and np.allclose(rotation(*got), rotation(*a))
    # two points: the heading of a level body
    pos, ang = pose_from_points([[0.15, 0, 0.2], [-0.15, 0, 0.2]],
                                [[1.0, 1.15, 0.2], [1.0, 0.85, 0.2]])
    assert np.allclose(ang, [np.pi / 2, 0, 0]) and np.allclose(pos, [1, 1, 0])


def _robot(n, seconds, seed=0, heading=None):
    """A robot carrying n blinking LEDs on a circle under the square rig: its spots, truth."""
    def origin(t):
        a = 1.5 * np.asarray(t, float) / 0.5
        return np.stack([1.3 + 0.5 * np.cos(a), 1.2 + 0.5 * np.sin(a),
                         np.zeros(np.shape(a))], -1)

    leds, yaw = body_leds(origin, BODY_LAYOUTS[n], seed=seed, heading=heading)
    return leds, origin, yaw


def _body_rows(dep, leds, seconds, keep=lambda t, cid, spots: spots):
    tr = Tracker(dep, period=1 / 30, spots=len(leds))
    rows = []
    for t, cid, spots in crossing_events(dep, leds, seconds):
        rows += tr.update_spots(cid, t, keep(t, cid, spots))
    rows += tr.finish()
    return rows


@pytest.mark.parametrize("n", [2, 3])
def test_a_robot_carrying_blinking_leds_gets_its_position_and_heading(n):
    leds, origin, yaw = _robot(n, 20.0)
    dep = body_rig(n)
    rows = _body_rows(dep, leds, 20.0)
    body = [r for r in rows if r.led == "R1" and r.status == "ok"]
    assert len(body) > 0.5 * len([r for r in rows if r.led == "L1"])
    T = np.array([r.t for r in body])
    e = np.linalg.norm(np.array([r.position for r in body]) - origin(T), axis=1)
    e_yaw = np.abs(np.angle(np.exp(1j * (np.array([r.pose[0] for r in body]) - yaw(T)))))
    assert np.mean(e) < 0.005 and np.degrees(np.mean(e_yaw)) < 1.0, (np.mean(e), e_yaw.mean())
    sigma_yaw = np.array([r.pose[3] for r in body])
    assert np.median(e_yaw / sigma_yaw) < 2  # an honest sigma_yaw
    pitch = np.array([r.pose[1] for r in body])
    if n == 2:
        assert np.isnan(pitch).all()  # two LEDs: the heading only, the tilt not claimed
    else:  # level: the fitted tilt is small where three LEDs gave it
        full = np.isfinite(pitch)
        assert full.sum() > 0.5 * len(body)
        assert np.degrees(np.mean(np.abs(pitch[full]))) < 1.0
    led_rows = [r for r in rows if r.led in ("L1", "L2", "L3") and r.status == "ok"]
    assert all(r.pose is None for r in led_rows)


@pytest.mark.parametrize("x, said", [(0.15, False), (0.16, True), (15.0, True), (0.06, True)])
def test_a_layout_in_other_units_or_measured_wrong_is_said(x, said):
    """From a hostile probe: a bodies: block in centimetres gave no body row and no word; one
    measured 1 cm off gave rows skewed by it, without a word."""
    leds, _, _ = _robot(2, 8.0)
    doc = body_rig(2).to_dict()
    doc["bodies"][0]["leds"]["L1"] = [x, 0.0, 0.15]  # the robot's: ±0.15 m
    tr = Tracker(deployment.from_dict(doc, "rig.yaml"), period=1 / 30, spots=2)
    for t, cid, spots in crossing_events(body_rig(2), leds, 8.0):
        tr.update_spots(cid, t, spots)
    tr.finish()
    misfits = tr.layout_misfits()
    assert bool(misfits) == said, [m.message() for m in misfits]
    if said:
        assert misfits[0].leds == ("L1", "L2") and abs(misfits[0].measured - 0.30) < 0.005
        assert f"{x + 0.15:.3f} m apart" in misfits[0].message()


@pytest.fixture(scope="module")
def line_robot(tmp_path_factory):
    out = tmp_path_factory.mktemp("line") / "sim"
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--profile", "paper-2024",
                          "--test-points", "0", "--robot-speed", "1.5", "--body", "2",
                          "--seconds", "10", "--out", str(out)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    return out


@pytest.mark.parametrize("x, said", [(0.15, False), (0.16, True), (15.0, True), (0.06, True)])
def test_a_layout_measured_wrong_is_said_under_the_papers_line_of_cameras(x, said, line_robot,
                                                                         tmp_path):
    """From a newcomer: under the paper's three cameras in a line, 10 s gave only 10 moments
    both LEDs were placed, short of the 30 a verdict then waited for, so a layout in
    centimetres or 1 cm off went unsaid. Ten measures 0.5 mm apart are sure enough. From a
    hostile probe: a layout too small (0.7 ×) was never judged (a measure counted only when
    its sigmas were small beside the layout's distance), its rows decimetres off at ok; and
    rows given before a verdict were written. Offline, the file holds none of them."""
    out = line_robot
    doc = deployment.load(out / "truth.yaml").to_dict()
    doc["bodies"][0]["leds"]["L1"] = [x, 0.0, 0.15]
    deployment.save(deployment.from_dict(doc, "x"), tmp_path / "d.yaml")
    res = subprocess.run([sys.executable, "-m", "vlpcal", "track", "-d", str(tmp_path / "d.yaml"),
                          "--frames", str(out / "streams"), "--out", str(tmp_path / "t.csv")],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert ("warning: body R1: its LEDs L1 and L2 lay 0.30" in res.stderr) == said, res.stderr
    body_rows = [r for r in csv.DictReader(open(tmp_path / "t.csv")) if r["led"] == "R1"]
    assert (len(body_rows) == 0) == said, len(body_rows)


def test_a_track_that_goes_on_as_another_is_named_by_the_phases_its_codes_were_read_at(
        line_robot, tmp_path):
    """From a newcomer: under the paper's three cameras in a line a robot's LED tracks end
    often (one camera alone sees the loop's ends) and each new track read its code afresh, a
    whole repeat and more: 58 % of the LED rows went under a track id and the body had 128
    rows in 10 s. The LEDs' codes keep their phases, so a few bits read at them name it."""
    res = subprocess.run([sys.executable, "-m", "vlpcal", "track", "-d",
                          str(line_robot / "truth.yaml"), "--frames", str(line_robot / "streams"),
                          "--out", str(tmp_path / "t.csv")], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    rows = [r for r in csv.DictReader(open(tmp_path / "t.csv")) if r["status"] == "ok"]
    leds = [r for r in rows if r["led"] != "R1"]
    assert sum(r["led"].startswith("T") for r in leds) < 0.45 * len(leds)
    assert sum(r["led"] == "R1" for r in rows) > 180
    # and named no worse: LED rows over 5 cm from the truth of their LED were 5.8 % (13 of
    # 226; 10 of them 0.14 s where two tracks one camera alone saw swapped spots in its image,
    # left in issue 29), now 13 of 338
    truth = {}
    for r in csv.DictReader(open(line_robot / "streams.truth.csv")):
        truth.setdefault(r["led"], []).append([float(r[k]) for k in ("t", "x", "y", "z")])
    named = [r for r in leds if r["led"] in truth]
    off = []
    for r in named:
        path = np.array(sorted(truth[r["led"]]))
        at = [np.interp(float(r["t"]), path[:, 0], path[:, k]) for k in (1, 2, 3)]
        off.append(np.linalg.norm(np.subtract(at, [float(r[k]) for k in "xyz"])))
    assert np.mean(np.array(off) > 0.05) < 0.05


def test_cameras_of_another_scale_are_said_by_the_bodys_layout(line_robot, tmp_path):
    """From a newcomer: the cameras' plan at half scale (about the room's centre, heights
    kept) fits every ray — rays alone cannot tell a plan scaled about the cameras' height — so
    nothing was said and the body's rows came 1.3 m off at ok. Its LEDs, 0.15 m apart where
    the layout has 0.3, say it, and the body gives no rows."""
    doc = deployment.load(line_robot / "truth.yaml").to_dict()
    room = np.array(doc["site"]["room"], float)
    c = room.mean(axis=0)
    for cam in doc["cameras"]:
        cam["position"] = [*((np.array(cam["position"][:2]) - c) * 0.5 + c),
                           cam["position"][2]]
    deployment.save(deployment.from_dict(doc, "x"), tmp_path / "half.yaml")
    res = subprocess.run([sys.executable, "-m", "vlpcal", "track", "-d",
                          str(tmp_path / "half.yaml"), "--frames", str(line_robot / "streams"),
                          "--out", str(tmp_path / "t.csv")], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert "its LEDs L1 and L2 lay 0.15" in res.stderr and "same scale" in res.stderr
    assert not [r for r in csv.DictReader(open(tmp_path / "t.csv")) if r["led"] == "R1"]


def test_a_body_whose_leds_no_two_cameras_share_is_still_placed():
    """Two cameras, each seeing one of the robot's two LEDs only, for 0.2 s at a time: no
    LED is placed by two cameras then, the body is (its rays at their own times, its shape)."""
    leds, origin, yaw = _robot(2, 12.0)
    dep = body_rig(2)
    names = [m.led for m in leds]

    def split(t, cid, spots):
        if int(t / 0.4) % 2 == 0 or t < 4.0:
            return spots
        spots = spots.copy()
        # C1 and C2 see L1 only, C3 and C4 L2 only (spots in no LED's order: by nearness)
        cam = dep.camera(cid)
        want = names.index("L1") if cid in ("C1", "C2") else names.index("L2")
        uv, _, _ = cam.project(leds[want].path(np.array([t])))
        near = np.linalg.norm(spots - uv, axis=1)
        return np.where((near == np.nanmin(near))[:, None] if np.isfinite(near).any()
                        else False, spots, np.nan)

    rows = _body_rows(dep, leds, 12.0, split)
    body = [r for r in rows if r.led == "R1" and r.t >= 4.0 and int(r.t / 0.4) % 2 == 1]
    assert len(body) > 50
    T = np.array([r.t for r in body])
    e = np.linalg.norm(np.array([r.position for r in body]) - origin(T), axis=1)
    assert np.median(e) < 0.01


def test_track_writes_and_publishes_a_simulated_bodys_rows(broker, tmp_path):
    """simulate --robot-speed --body 2, then track: the body's rows in the file with their
    pose columns (empty on LED rows), and on prefix/bodies/R1."""
    from test_mqtt import Listener

    out = tmp_path / "sim"
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--profile",
                          "paper-2024", "--robot-speed", "1.2", "--body", "2", "--seconds",
                          "8", "--test-points", "0", "--out", str(out)], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert deployment.load(out / "truth.yaml").bodies[0].id == "R1"
    listen = Listener(broker.url("out"))
    res = subprocess.run([sys.executable, "-m", "vlpcal", "track", "-d", str(out / "truth.yaml"),
                          "--frames", str(out / "streams"), "--out", str(tmp_path / "t.csv"),
                          "--publish", broker.url("out")], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert "bodies R1" in res.stderr
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert list(rows[0])[-4:] == ["yaw", "pitch", "roll", "sigma_yaw"]
    body = [r for r in rows if r["led"] == "R1"]
    assert len(body) > 50 and all(r["yaw"] and not r["pitch"] for r in body)
    # the robot's own truth, at each camera frame's time (a newcomer had to work it out)
    truth = {r["t"]: r for r in csv.DictReader(open(out / "streams.bodies.truth.csv"))}
    e = [np.hypot(float(r["x"]) - float(truth[r["t"]]["x"]),
                  float(r["y"]) - float(truth[r["t"]]["y"])) for r in body if r["status"] == "ok"]
    e_yaw = [abs(np.angle(np.exp(1j * (float(r["yaw"]) - float(truth[r["t"]]["yaw"])))))
             for r in body if r["status"] == "ok"]
    assert np.mean(e) < 0.005 and np.degrees(np.mean(e_yaw)) < 1.0, (np.mean(e), e_yaw)
    assert all(not r["yaw"] for r in rows if r["led"] != "R1")
    import time

    time.sleep(0.5)
    got = listen.on("/bodies/R1")
    listen.close()
    assert len(got) == len(body) and {"yaw", "sigma_yaw"} <= set(got[0])
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--body", "2", "--out",
                          str(tmp_path / "x")], capture_output=True, text=True)
    assert res.returncode == 2 and "--robot-speed" in res.stderr


def test_a_simulated_robot_published_live_is_tracked_as_a_body(broker, tmp_path):
    """From a newcomer: simulate --publish --body 2 published one steady LED, so the live
    chain of a body could not be rehearsed. Now its cameras publish both LEDs' spots, each
    blinking its code, and track --spots with the same seed's deployment places the body."""
    import time

    out = tmp_path / "sim"
    run = [sys.executable, "-m", "vlpcal"]
    res = subprocess.run(run + ["simulate", "--profile", "paper-2024", "--robot-speed", "1.5",
                                "--body", "2", "--seconds", "1", "--test-points", "0", "--out",
                                str(out)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    trk = subprocess.Popen(run + ["track", "-d", str(out / "truth.yaml"), "--spots",
                                  broker.url("lab"), "--out", str(tmp_path / "t.csv"),
                                  "--duration", "14", "--fps", "30"], stderr=subprocess.PIPE,
                           text=True)
    time.sleep(2.0)  # subscribed
    res = subprocess.run(run + ["simulate", "--profile", "paper-2024", "--robot-speed", "1.5",
                                "--body", "2", "--seconds", "10", "--publish",
                                broker.url("lab")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and "robot carrying 2 blinking LEDs" in res.stderr, res.stderr
    _, err = trk.communicate(timeout=60)
    assert trk.returncode == 0, err
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    body = [r for r in rows if r["led"] == "R1" and r["status"] == "ok"]
    assert len(body) > 50, err
    assert {"L1", "L2"} <= {r["led"] for r in rows}, err


def test_body_blocks_describe_the_simulated_robot():
    leds, _ = body_leds(lambda t: np.zeros(np.shape(t) + (3,)), BODY_LAYOUTS[3])
    blocks = body_blocks(leds, BODY_LAYOUTS[3], "R7")
    doc = square_rig().to_dict()
    doc.update(blocks)
    dep = deployment.from_dict(doc, "x")
    assert dep.bodies[0].id == "R7" and len(dep.leds) == 3


@pytest.mark.parametrize("profile, n, seed", [("cheap-wide", 2, 5), ("paper-2024", 3, 2),
                                              ("paper-square", 2, 4)])
def test_a_robots_leds_keep_their_names_and_its_heading_never_turns_round(profile, n, seed,
                                                                         tmp_path):
    """Runs of a robot at 1.5 m/s that went wrong before the naming fixes of issue 29's second
    and third sessions: with two LEDs on cheap-wide (seed 5) a fifth of the body rows turned
    the robot half round — a track named by the body's shape took its sibling's spot at the
    end of a dark run; with three on the paper's line (seed 2) a third of the LED rows were
    under another LED's name — held tracks passed names and blink histories to siblings. On
    the paper's cameras in a 2 × 2 grid with two LEDs (seed 4) the robot ran half round for
    2.5 s: a track whose code no longer read kept its name while it followed its sibling."""
    from vlpcal.datasets import read_async_frames
    from vlpcal.detection import detect_several
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.streams import robot_path, simulate_streams
    from vlpcal.sim.writers import deployment_of

    if profile == "paper-square":  # benchmarks/tracking.py's: the rig of these tests
        base = replace(get_profile("paper-2024"), nominal=tuple(square_rig().cameras),
                       room=((0, 0), (2.6, 0), (2.6, 2.4), (0, 2.4)))
    else:
        base = get_profile(profile)
    scene = make_scene(replace(base, name=profile), seed)
    origin = robot_path(scene, 1.5, 0.0, seed)
    leds, yaw = body_leds(origin, BODY_LAYOUTS[n], seed=seed)
    simulate_streams(scene, tmp_path, leds, 20.0, seed=seed)
    dep = deployment_of(scene, "true", body_blocks(leds, BODY_LAYOUTS[n]))
    folder = read_async_frames(tmp_path)
    cams = {c.id: c for c in dep.cameras}
    found = {}
    for cid in folder.camera_ids:
        mine = [no for _, c, no in folder.events if c == cid]
        uv = detect_several([folder.frame(cid, no) for no in mine], n,
                            shape=(cams[cid].height, cams[cid].width))
        found.update({(cid, no): u for no, u in zip(mine, uv)})
    tr = Tracker(dep, period=1 / 30, spots=n)
    rows = []
    for t, cid, no in folder.events:
        rows += tr.update_spots(cid, t, found[(cid, no)])
    rows += tr.finish()
    body = [r for r in rows if r.pose is not None and r.status == "ok"]
    T = np.array([r.t for r in body])
    e_yaw = np.abs(np.angle(np.exp(1j * (np.array([r.pose[0] for r in body]) - yaw(T)))))
    e = np.linalg.norm(np.array([r.position for r in body]) - origin(T), axis=1)
    assert len(body) > 100 and not (e_yaw > np.pi / 2).any()
    assert (e > 0.05).mean() < 0.01, (e > 0.05).sum()
    truth = {m.led: m.path for m in leds}
    led_rows = [r for r in rows if r.pose is None and r.status == "ok" and r.led in truth]
    named_wrong = [np.linalg.norm(r.position - truth[r.led](r.t)) > 0.05 for r in led_rows]
    assert np.mean(named_wrong) < 0.02, sum(named_wrong)


def _probe_robot(origin, heading, codes, prefix):
    """A two-LED robot as the hostile probe built it: LED phases from one draw per robot."""
    from vlpcal.sim.streams import MovingLed

    rng = np.random.default_rng([0, 29, 2])
    out = []
    for (led, b), pattern in zip(BODY_LAYOUTS[2].items(), codes):
        code = BlinkCode(prefix + led, pattern, 10.0)
        lever = np.asarray(b, float)
        out.append(MovingLed(prefix + led, lambda t, b=lever: origin(t)
                             + np.einsum("...ij,j->...i", rotation(heading(t)), b),
                             code, float(rng.uniform(0, code.period))))
    return out


def _two_robots_tracked(scene, a, b, tmp_path):
    """Robots ``a`` and ``b`` (R1, R2) rendered as ``vlpcal simulate`` does, each camera's
    frames detected and tracked as ``vlpcal track`` does: (rows, the fit watch's verdicts)."""
    from vlpcal.datasets import read_async_frames
    from vlpcal.detection import detect_several
    from vlpcal.sim.streams import simulate_streams
    from vlpcal.sim.writers import deployment_of

    blocks = body_blocks(a, BODY_LAYOUTS[2], "R1")
    more = body_blocks(b, BODY_LAYOUTS[2], "R2")
    blocks = {k: blocks[k] + more[k] for k in blocks}
    simulate_streams(scene, tmp_path / "s", a + b, 10.0, seed=0)
    dep = deployment_of(scene, "true", blocks)
    folder = read_async_frames(tmp_path / "s")
    found = {}
    for cam in dep.cameras:
        mine = [no for _, c, no in folder.events if c == cam.id]
        uv = detect_several([folder.frame(cam.id, no) for no in mine], 4,
                            shape=(cam.height, cam.width))
        found.update({(cam.id, no): u for no, u in zip(mine, uv)})
    tr = Tracker(dep, period=1 / 30)
    rows, said = [], []
    for t, cid, no in folder.events:
        rows += tr.update_spots(cid, t, found[(cid, no)])
        if tr.fit.misfit() is not None:
            said.append(tr.fit.misfit().message())
    return rows + tr.finish(), said


def test_two_robots_side_by_side_are_not_taken_for_a_wrong_deployment(tmp_path):
    """From a hostile probe: two two-LED robots driving side by side 0.4 m apart under the
    paper's line of cameras — their four LEDs' first tracks took each other's spots, and the
    fit watch stopped the right deployment after 31 moments (61 % not placed). It now waits
    for as many moments per LED a frame is searched for as one LED's."""
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.streams import robot_path

    scene = make_scene(get_profile("paper-2024"), 0)
    path = robot_path(scene, 1.0, height=0.0, seed=0)

    def heading(t):
        v = path(np.asarray(t, float) + 1e-3) - path(np.asarray(t, float) - 1e-3)
        return np.arctan2(v[..., 1], v[..., 0])

    def beside(d):
        def at(t):
            t = np.asarray(t, float)
            v = path(t + 1e-3) - path(t - 1e-3)
            n = np.stack([-v[..., 1], v[..., 0], 0 * v[..., 0]], -1)
            return path(t) + d * n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-9)
        return at

    a = _probe_robot(beside(0.2), heading, ("0010111101", "0011001111"), "A")
    b = _probe_robot(beside(-0.2), heading, ("0101010111", "0001011011"), "B")
    rows, said = _two_robots_tracked(scene, a, b, tmp_path)
    assert not said, said[0]
    assert {r.led for r in rows if r.pose is not None} == {"R1", "R2"}


def test_a_robot_crossing_another_of_its_shape_never_lends_it_an_led(tmp_path):
    """From a hostile probe: two robots of one layout crossing, each facing along its line
    (driving to and fro, backing up): an LED of one, no code naming it yet, lay as far from
    the other's named LED as that one's sibling, and was named by the shape — twelve R1 rows
    0.3 m and 48–138° off at ok. A shape names a track only when no other unnamed track fits
    there too and the body's latest pose does not put the LED elsewhere."""
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.streams import crossing_paths

    scene = make_scene(get_profile("paper-2024"), 0)
    paths = crossing_paths(scene.profile.room, 1.5, n=2, height=0.0, seed=0)
    facing = []
    for p in paths:
        v = p(np.array(0.3)) - p(np.array(0.29))
        facing.append(float(np.arctan2(v[1], v[0])))
    a = _probe_robot(paths[0], lambda t: np.full(np.shape(t), facing[0]),
                     ("0010111101", "0011001111"), "A")
    b = _probe_robot(paths[1], lambda t: np.full(np.shape(t), facing[1]),
                     ("0101010111", "0001011011"), "B")
    rows, _ = _two_robots_tracked(scene, a, b, tmp_path)
    for body, path, yaw in (("R1", paths[0], facing[0]), ("R2", paths[1], facing[1])):
        mine = [r for r in rows if r.led == body and r.status == "ok"]
        assert len(mine) > 100, body
        T = np.array([r.t for r in mine])
        off = np.linalg.norm(np.array([r.position for r in mine]) - path(T), axis=1)
        turned = np.abs(np.angle(np.exp(1j * (np.array([r.pose[0] for r in mine]) - yaw))))
        assert off.max() < 0.05 and np.degrees(turned.max()) < 20, (body, off.max(),
                                                                   np.degrees(turned.max()))
