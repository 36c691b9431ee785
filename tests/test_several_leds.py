"""Several LEDs in view (issue 16): spots ranked per frame, blink codes read along each track
(identity through crossings), the deployment's ``leds:`` block checked."""

import numpy as np
import pytest

from vlpcal import deployment
from vlpcal.blink import BlinkCode, check_codes, decode
from vlpcal.deployment import Deployment
from vlpcal.geometry import paper_camera
from vlpcal.sim.streams import MovingLed, Timing, capture_times, crossing_paths
from vlpcal.tracking import Tracker

CODES = [BlinkCode("R1", "0010111101", 10.0), BlinkCode("R2", "0011001111", 10.0),
         BlinkCode("R3", "0101010111", 10.0)]
ROOM = [[0, 0], [2.6, 0], [2.6, 2.4], [0, 2.4]]


def square_rig(leds=None):
    cams = [paper_camera(f"C{k + 1}", (0.95 + 0.7 * (k % 2), 0.85 + 0.7 * (k // 2), 2.3))
            for k in range(4)]
    extra = {"leds": [{"id": c.led, "pattern": c.pattern, "bit_rate": c.bit_rate}
                      for c in leds]} if leds else {}
    return Deployment("square", 2.3, ROOM, cams, [], extra)


def test_a_code_counts_the_lit_bits_a_track_saw_dark():
    """A track that follows another LED sees its own code's lit bits dark where that LED is
    dark: its own code misses none, all dark misses every lit bit, the two LEDs' AND some."""
    code, other = CODES[1], CODES[0]
    t = np.arange(0, code.period, 1 / 30)
    assert code.missed(t, code.lit(t, 0.03), 0.03, 0.2) == 0
    assert code.missed(t, np.zeros(len(t), bool), 0.03, 0.2) == code.pattern.count("1")
    both = code.lit(t, 0.03) & other.lit(t, 0.05)
    assert 0 < code.missed(t, both, 0.03, 0.2) < code.pattern.count("1")


def test_a_code_at_a_known_phase_reads_a_few_bits_and_counts_the_wrong_ones():
    code = CODES[1]
    t = np.arange(0.3, 0.8, 1 / 30)  # half a repeat: five bits
    assert code.wrong(t, code.lit(t, 0.03), 0.03, 0.2) == (0, 5)
    assert code.wrong(t, ~code.lit(t, 0.03), 0.03, 0.2) == (5, 5)
    assert code.wrong(t, CODES[0].lit(t, 0.05), 0.03, 0.2)[0] > 0  # another LED's


def test_a_blink_code_names_its_led_at_any_phase_and_a_steady_light_none():
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0, 3.0, 400))
    for code in CODES:
        lit = code.lit(t, rng.uniform(0, 1)) ^ (rng.random(len(t)) < 0.04)  # misreads
        assert decode(t, lit, CODES)[0] == code.led
        assert decode(t[t < 0.5], lit[t < 0.5], CODES)[0] is None  # less than one repeat
    assert decode(t, np.ones(len(t), bool), CODES)[0] is None
    assert check_codes(CODES) is None
    assert "cannot be told apart" in check_codes([*CODES, BlinkCode("R4", "0111101001", 10)])
    assert check_codes([CODES[0], BlinkCode("R4", "0111101001", 20)]) is None


@pytest.mark.parametrize("leds, expected", [
    ([{"id": "R1", "pattern": 1101, "bit_rate": 10}], "leds[0].pattern: expected a quoted"),
    ([{"id": "R1", "pattern": "1101", "bit_rate": 10}, {"id": "R2", "pattern": "0111",
                                                         "bit_rate": 10}], "cannot be told"),
    ([{"id": "R1", "pattern": "12", "bit_rate": 10}], "0 (dark) and 1 (lit)"),
    ([{"id": "R1", "pattern": "0000", "bit_rate": 10}], "lit at least once"),
    ([{"id": "R1", "pattern": "1101", "bit_rate": 0}], "leds[0].bit_rate: expected a positive"),
    ([{"id": "R1", "pattern": "1101"}], "leds[0].bit_rate: missing"),
    ([{"id": "R1", "pattern": "1101", "bit_rate": 1, "colour": 2}], "leds[0].colour: unknown"),
    ([{"id": "R1", "pattern": "1101", "bit_rate": 1}, {"id": "R1", "pattern": "1001",
                                                        "bit_rate": 1}], "id R1 given twice"),
    ({"R1": "1101"}, "leds: expected a list"),
])
def test_the_leds_block_is_checked(leds, expected):
    doc = square_rig().to_dict()
    doc["leds"] = leds
    with pytest.raises(deployment.DeploymentError, match=None) as e:
        deployment.from_dict(doc, "site.yaml")
    assert str(e.value).startswith("site.yaml: ") and expected in str(e.value)


def test_the_leds_block_round_trips_and_meets_the_schema(tmp_path):
    import json

    import jsonschema

    from vlpcal.deployment import SCHEMA_PATH

    dep = square_rig(CODES)
    deployment.save(dep, tmp_path / "d.yaml")
    assert deployment.load(tmp_path / "d.yaml").leds == CODES
    schema = json.loads(SCHEMA_PATH.read_text())
    jsonschema.validate(dep.to_dict(), schema)
    bad = dep.to_dict()
    bad["leds"][0]["pattern"] = "10x"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_detect_several_ranks_the_spots_and_pads_with_nan():
    from vlpcal.detection import detect_several
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.render import encode_jpeg
    from vlpcal.sim.scene import make_scene, render_camera

    scene = make_scene(get_profile("paper-2024"), 0)
    cam = scene.true[0]
    pts = np.array([[[1.0, 0.8, 0.15], [1.3, 1.0, 0.15], [1.2, 0.6, 0.5]]] * 4)
    on = np.array([[1, 1, 1], [1, 0, 1], [0, 0, 1], [0, 0, 0]], bool)
    imgs, inside = render_camera(cam, pts, scene.profile.look,
                                 [np.random.default_rng(i) for i in range(4)], on=on)
    assert inside.shape == (4, 3) and inside.all()
    found = detect_several([encode_jpeg(f, 90) for f in imgs], 3)
    truth = cam.project(pts[0])[0]
    for i in range(4):
        got = found[i][np.isfinite(found[i]).all(axis=1)]
        assert len(got) == on[i].sum()  # the dark LEDs leave NaN rows, at the end
        assert np.isnan(found[i, len(got):]).all()
        if len(got):
            d = np.linalg.norm(got[:, None] - truth[None, on[i]], axis=2)
            assert np.all(d.min(axis=1) < 0.3)


def crossing_events(dep, leds, seconds, seed=0):
    """(t, camera, spots K×2) with each camera on its own clock; a dark LED gives no spot."""
    rng = np.random.default_rng(seed)
    events = []
    for cam in dep.cameras:
        t = capture_times(Timing(), seconds, rng)
        spots = []
        for m in leds:
            uv, _, inside = cam.project(m.path(t), margin=1.0)
            uv = uv + rng.normal(0, 0.05, uv.shape)
            spots.append(np.where((inside & m.lit(t))[:, None], uv, np.nan))
        spots = np.stack(spots, axis=1)
        spots = np.array([s[rng.permutation(len(s))] for s in spots])  # in no LED's order
        events += list(zip(t, [cam.id] * len(t), spots))
    return sorted(events, key=lambda e: e[0])


def labels_along(rows, leds):
    """Per true LED, the labels of the rows that are its (nearest, within 5 cm), in time."""
    T = np.array([r.t for r in rows])
    P = np.array([r.position for r in rows])
    d = np.linalg.norm(np.stack([m.path(T) for m in leds], axis=1) - P[:, None], axis=2)
    who = np.where(d.min(axis=1) < 0.05, d.argmin(axis=1), -1)
    assert (who >= 0).mean() > 0.98
    return [[rows[i] for i in np.flatnonzero(who == k)] for k in range(len(leds))]


@pytest.mark.parametrize("coded", [True, False])
def test_three_crossing_leds_keep_their_identity(coded):
    paths = crossing_paths(ROOM, 1.5, 3)
    phases = [0.13, 0.71, 0.42]
    leds = [MovingLed(c.led, p, c if coded else None, ph)
            for c, p, ph in zip(CODES, paths, phases)]
    dep = square_rig(CODES if coded else None)
    tr = Tracker(dep, period=1 / 30)
    assert tr.spots == (3 if coded else 1)
    tr = Tracker(dep, period=1 / 30, spots=3)
    rows = []
    for t, cid, spots in crossing_events(dep, leds, 20.0):
        rows += tr.update_spots(cid, t, spots)
    rows += tr.finish()
    for m, mine in zip(leds, labels_along(rows, leds)):
        names = [r.led for r in mine]
        if coded:  # named by its code within three repeats, and never by another's
            named = [r for r in mine if r.led.startswith("R")]
            assert {r.led for r in named} == {m.led}
            assert named[0].t - mine[0].t < 3 * m.code.period
        else:  # one anonymous track all along
            assert len(set(names)) == 1 and names[0].startswith("T")


def test_a_camera_clock_that_jumps_is_not_believed_and_a_reboot_is_followed():
    """From a hostile probe: one stamp a million seconds off had moved every later frame of
    that camera; a camera whose clock restarts (a reboot) never recovered."""
    from vlpcal.live import ClockSync, _stamp

    clock, rng = ClockSync(), np.random.default_rng(0)
    offset, errors = 500.0, []
    for i in range(600):
        t = i / 30
        if i == 300:
            offset = 10_000.0  # rebooted: its clock now reads otherwise
        stamp = t - offset + (1e6 if i == 30 else 0.0)
        host = clock.add(stamp, t + 0.004 + rng.exponential(0.003))
        if i > 40:
            errors.append(host - t)
    assert clock.restarts == 1 and clock.ignored >= 1
    assert np.max(np.abs(errors)) < 0.05
    assert _stamp("1e308") is None and _stamp("nan") is None and _stamp("12.5") == 12.5


def test_blink_codes_far_apart_in_rate_are_read_within_bounds():
    """From a hostile probe: a 10 kbit/s code beside a 0.1 bit/s one took 3 GB and crashed."""
    codes = [BlinkCode("A", "01" * 32, 10_000), BlinkCode("B", "01", 0.1)]
    t = np.sort(np.random.default_rng(0).uniform(0, 60, 20_000))
    led, _, _ = decode(t, np.ones(len(t), bool), codes)  # a steady light: neither
    assert led is None
    doc = square_rig().to_dict()
    doc["leds"] = [{"id": f"L{i}", "pattern": format(i + 1, "07b"), "bit_rate": 10}
                   for i in range(70)]
    with pytest.raises(deployment.DeploymentError, match="1 to 64"):
        deployment.from_dict(doc, "site.yaml")
