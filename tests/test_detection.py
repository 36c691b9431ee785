import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlpcal import sim
from vlpcal.detection import (
    AT_EDGE,
    CORRUPT,
    DEFAULT_DETECTOR,
    DETECTORS,
    NO_SPOT,
    TOO_DIM,
    WRONG_SIZE,
    detect_spot,
    detect_spots,
)

#: per-axis worst error (px) on noise-free Gaussian spots, σ 0.7–1.3 px, no JPEG (measured
#: maxima: highest 0.50, mean2 0.50, nip 0.080, nip_eq5 0.50, gauss 0.0006, centroid 0.031,
#: blob 0.034)
NOISE_FREE_BOUND = {"highest": 0.5, "mean2": 0.5, "nip": 0.09, "nip_eq5": 0.5, "gauss": 0.002,
                    "centroid": 0.035, "blob": 0.035}


@given(x0=st.floats(-0.49, 0.49), y0=st.floats(-0.49, 0.49),
       cx=st.floats(0.5, 30), cy=st.floats(0.5, 30))
def test_nip_returns_the_exact_parabola_vertex(x0, y0, cx, cy):
    """NI-P (eqs. 4–6) is the 3-point parabola vertex: exact on a sampled paraboloid."""
    v, u = np.mgrid[0:120, 0:160].astype(float)
    uc, vc = 70 + x0, 50 + y0
    img = 1000.0 - cx * (u - uc) ** 2 - cy * (v - vc) ** 2
    img = np.maximum(img, 0.0)
    spot = detect_spot(img, "nip")
    assert spot.ok
    assert spot.u == pytest.approx(uc, abs=1e-9)
    assert spot.v == pytest.approx(vc, abs=1e-9)


@pytest.mark.parametrize("method", DETECTORS)
@pytest.mark.parametrize("sigma", [0.7, 1.0, 1.3])
def test_noise_free_gaussian_error_within_stated_bound(method, sigma, rng):
    n = 400
    u, v = rng.uniform(20, 140, n), rng.uniform(20, 100, n)
    frames = np.full((n, 120, 160), 20.0)
    sim.add_spots(frames, u, v, sim.SpotLook(sigma, 200.0))
    res = detect_spots(frames, method)
    assert res.ok.all()
    err = np.maximum(np.abs(res.u - u), np.abs(res.v - v))
    assert err.max() <= NOISE_FREE_BOUND[method]


def jpeg_frames(u, v, look=None, distractors=(), seed=1):
    frames = sim.render(u, v, look=look or sim.SpotLook(), distractors=distractors, seed=seed)
    return [sim.encode_jpeg(f, 80) for f in frames]


def test_default_survives_saturated_flat_top(rng):
    n = 300
    u, v = rng.uniform(20, 140, n), rng.uniform(20, 100, n)
    jpegs = jpeg_frames(u, v, sim.SpotLook(1.0, 600.0))
    best = detect_spots(jpegs, DEFAULT_DETECTOR)
    nip = detect_spots(jpegs, "nip")
    assert best.saturated.all()
    rms = lambda r: np.sqrt(np.mean((r.u - u) ** 2 + (r.v - v) ** 2))  # noqa: E731
    assert rms(best) < 0.06
    assert rms(nip) > 4 * rms(best)


def test_default_picks_the_led_beside_a_reflection_and_says_so(rng):
    n = 200
    u, v = rng.uniform(30, 130, n), rng.uniform(30, 90, n)
    jpegs = jpeg_frames(u, v, distractors=[(6, 4, sim.SpotLook(1.6, 70.0))])
    res = detect_spots(jpegs)
    assert (res.blobs > 1).all()
    assert "chose 1 of" in res[0].note
    assert np.sqrt(np.mean((res.u - u) ** 2 + (res.v - v) ** 2)) < 0.1


def test_default_ignores_a_brighter_wide_lamp(rng):
    n = 100
    u, v = rng.uniform(60, 130, n), rng.uniform(30, 90, n)
    jpegs = jpeg_frames(u, v, distractors=[(-40, 10, sim.SpotLook(4.0, 400.0))])
    res = detect_spots(jpegs)
    assert np.abs(res.u - u).max() < 0.3 and np.abs(res.v - v).max() < 0.3
    # the paper's detector follows the lamp
    assert np.abs(detect_spots(jpegs, "nip").u - u).mean() > 10


def test_default_prefers_the_led_to_a_lamp_cut_by_the_frame_edge(rng):
    u, v = rng.uniform(112, 120, 50), rng.uniform(20, 100, 50)
    jpegs = jpeg_frames(u, v, distractors=[(45, 0, sim.SpotLook(4.0, 400.0))])
    res = detect_spots(jpegs)
    assert res.ok.all()
    assert np.abs(res.u - u).max() < 0.3


@pytest.mark.parametrize("method", DETECTORS)
@pytest.mark.parametrize("data", [b"", b"not a jpeg", b"\xff\xd8\xff\xe0garbage"])
def test_corrupt_bytes_give_corrupt_frame(method, data):
    spot = detect_spot(data, method)
    assert spot.reason == CORRUPT and np.isnan(spot.u)


def test_truncated_jpeg_is_corrupt_but_padding_is_fine():
    good = jpeg_frames([80.0], [60.0])[0]
    assert detect_spot(good[: len(good) // 2]).reason == CORRUPT
    assert detect_spot(good + b"\x00" * 16).ok


def test_dark_dim_and_edge_frames_have_reasons():
    dark = jpeg_frames([np.nan], [np.nan])[0]
    assert detect_spot(dark).reason == NO_SPOT
    dim = sim.render([80.0], [60.0], look=sim.SpotLook(0.9, 9.0),
                     sensor=sim.Sensor(read_noise=0.3, shot_gain=0.0))[0]
    assert detect_spot(dim).reason == TOO_DIM
    edge = sim.render([0.2], [60.0])[0]
    for method in ("nip", "centroid", "blob"):
        assert detect_spot(edge, method).reason == AT_EDGE


def test_batch_matches_single_and_handles_mixed_inputs(rng):
    u, v = rng.uniform(20, 140, 20), rng.uniform(20, 100, 20)
    jpegs = jpeg_frames(u, v, distractors=[(5, 5, sim.SpotLook(1.5, 60.0))])
    frames = list(jpegs) + [b"", np.zeros((60, 80), np.uint8)]
    batch = detect_spots(frames)
    for i, data in enumerate(jpegs):
        single = detect_spot(data)
        assert batch[i].u == pytest.approx(single.u, abs=1e-9)
        assert batch[i].blobs == single.blobs
    assert batch.reasons[-2:] == [CORRUPT, WRONG_SIZE]  # empty bytes; a frame of another size


def test_colour_frames_are_converted():
    gray = sim.render([70.3], [40.6])[0]
    colour = np.repeat(gray[:, :, None], 3, axis=2)
    assert detect_spot(colour).u == pytest.approx(detect_spot(gray).u, abs=1e-9)


def test_nip_eq5_is_the_printed_formula_twice_the_vertex_offset():
    """Eq. 5 as printed: x = (P2 − P1) / (2P − P1 − P2) + x_P (lines of slope ±step, eq. 1)."""
    img = np.full((30, 30), 10.0)
    img[15, 14:17] = [60.0, 100.0, 80.0]  # P1, P, P2 along x
    img[14, 15], img[16, 15] = 70.0, 70.0
    assert detect_spot(img, "nip_eq5").u == pytest.approx(15 + 20 / 60)
    assert detect_spot(img, "nip").u == pytest.approx(15 + 20 / 120)
    assert detect_spot(img, "nip_eq5").v == pytest.approx(15.0)


def test_frames_that_cannot_be_measured_are_corrupt_not_errors():
    good = sim.render([40.2], [30.7])[0].astype(float)
    nan = good.copy()
    nan[5, 5] = np.nan
    batch = detect_spots(np.stack([good, nan]))
    assert batch.reasons == [None, CORRUPT]
    assert detect_spot(nan).reason == CORRUPT
    assert detect_spot(np.zeros((1, 1))).reason == CORRUPT
    assert len(detect_spots(np.zeros((0, 120, 160)))) == 0
    assert detect_spots(np.zeros((2, 0, 0))).reasons == [CORRUPT, CORRUPT]
    assert len(detect_spots([])) == 0


def test_colour_frames_of_any_dtype_are_converted_without_wrapping():
    gray = sim.render([70.3], [40.6])[0]
    colour16 = np.repeat(gray[:, :, None], 3, axis=2).astype(np.uint16)
    assert detect_spot(colour16).u == pytest.approx(detect_spot(gray).u, abs=1e-6)


def test_unknown_detector_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown detector 'foo'"):
        detect_spot(np.zeros((10, 10)), "foo")


def test_one_frame_path_equals_the_batch(rng):
    """detect_frame (the live path, one frame a call) gives what detect_several gives for the
    same frames: plain, saturated, beside a reflection, beside a wide lamp, at the edge, dim,
    dark, several LEDs, a float frame, and frames that cannot be measured."""
    from vlpcal.detection import MISSING, detect_frame, detect_several

    n = 40
    u, v = rng.uniform(3, 157, n), rng.uniform(3, 117, n)
    frames = (jpeg_frames(u, v) + jpeg_frames(u, v, sim.SpotLook(1.0, 600.0))
              + jpeg_frames(u, v, distractors=[(6, 4, sim.SpotLook(1.6, 70.0))])
              + jpeg_frames(u, v, distractors=[(-40, 10, sim.SpotLook(4.0, 400.0))])
              + jpeg_frames([0.2, 159.5, 80.0], [60.0, 3.0, 119.3])
              + jpeg_frames([np.nan], [np.nan])
              + [sim.render([80.0], [60.0], look=sim.SpotLook(0.9, 9.0),
                            sensor=sim.Sensor(read_noise=0.3, shot_gain=0.0))[0]]
              + [sim.render([70.3], [40.6])[0].astype(float)])
    two = sim.render(rng.uniform(20, 130, 10), rng.uniform(20, 95, 10),
                     distractors=[(20, 15, sim.SpotLook(1.0, 200.0))])
    frames += [sim.encode_jpeg(f, 85) for f in two]
    for k in (1, 3):
        batch = detect_several(frames, k, shape=(120, 160))
        for i, f in enumerate(frames):
            one, why = detect_frame(f, k, shape=(120, 160))
            assert why is None
            np.testing.assert_allclose(one, batch[i], atol=1e-9, err_msg=f"frame {i}, k {k}")
    assert np.isfinite(batch[-10:, :2]).all()  # two LEDs found in each of the last frames
    # frames that cannot be measured, and odd k: the same answers and reasons as the batch
    tiny = np.full((15, 200), 20, np.uint8)
    tiny[7, 100] = 200
    huge = bytearray(frames[0])
    sof = huge.find(b"\xff\xc0")
    huge[sof + 5:sof + 9] = (60000).to_bytes(2, "big") * 2
    odd = [sim.encode_jpeg(tiny), sim.encode_jpeg(np.full((120, 1), 20, np.uint8)),
           bytes(huge), sim.encode_jpeg(np.full((240, 320), 20, np.uint8))[:500],
           sim.encode_jpeg(np.full((8, 8), 20, np.uint8)), frames[0]]
    for f in odd:
        for shape in (None, (120, 160), (8, 8)):
            for k in (0, 1, 2.5):
                one, why = detect_frame(f, k, shape=shape)
                many, whys = detect_several([f], k, shape=shape, reasons=True)
                np.testing.assert_allclose(one, many[0], atol=1e-9)
                assert why == whys[0], (shape, k, why, whys)
    good = frames[0]
    assert detect_frame(good[: len(good) // 2])[1] == CORRUPT
    assert detect_frame(b"not a jpeg")[1] == CORRUPT
    assert detect_frame(good, shape=(240, 320))[1] == WRONG_SIZE
    assert detect_frame(np.zeros((60, 80), np.uint8), shape=(120, 160))[1] == WRONG_SIZE
    assert detect_frame(None)[1] == MISSING


def test_one_frame_path_gives_the_batch_reason_for_every_frame(rng):
    """detect_frame(every_reason=True), as the locator's live sets use it, gives each frame the
    spot and the reason detect_spots gives it: measured, no_spot (dark, a lamp alone), too_dim,
    at_edge (centre on the border, or within a pixel of it), corrupt_frame, wrong_size,
    missing, a float frame; for every detector."""
    from vlpcal.detection import DETECTORS, detect_frame, detect_spots

    n = 12
    u, v = rng.uniform(3, 157, n), rng.uniform(3, 117, n)
    quiet = sim.Sensor(read_noise=0.3, shot_gain=0.0)
    frames = (jpeg_frames(u, v) + jpeg_frames(u, v, sim.SpotLook(1.0, 600.0))
              + jpeg_frames(u[:4], v[:4], distractors=[(6, 4, sim.SpotLook(1.6, 70.0))])
              + jpeg_frames([0.2, 159.5, 80.0, 0.6, 1.4], [60.0, 3.0, 119.3, 50.0, 30.0])
              + jpeg_frames([np.nan], [np.nan])
              + [sim.encode_jpeg(sim.render([80.0], [60.0], look=sim.SpotLook(0.9, a),
                                            sensor=quiet)[0]) for a in (3.0, 6.0, 9.0, 14.0)]
              + [sim.render([70.3], [40.6])[0].astype(float), None, b"not a jpeg",
                 sim.encode_jpeg(np.full((240, 320), 20, np.uint8))])
    lamp = np.full((120, 160), 20.0)
    yy, xx = np.mgrid[:120, :160]
    lamp += 200 * np.exp(-((xx - 60) ** 2 + (yy - 50) ** 2) / (2 * 12.0 ** 2))
    frames.append(sim.encode_jpeg(lamp.astype(np.uint8)))
    for method in DETECTORS:
        batch = detect_spots(frames, method, shape=(120, 160))
        for i, f in enumerate(frames):
            uv, why = detect_frame(f, 1, method, shape=(120, 160), every_reason=True)
            assert why == batch[i].reason, (method, i, why, batch[i].reason)
            # blob is measured step by step: against the whole batch; the others are the batch
            # of one (mean2's two brightest pixels, on a tie, depend on the stack's layout)
            expected = batch.uv[i] if method == "blob" else \
                detect_spots([f], method, shape=(120, 160)).uv[0]
            np.testing.assert_allclose(uv[0], expected, atol=1e-9, err_msg=f"{method} {i}")
    reasons = {s.reason for s in detect_spots(frames, shape=(120, 160))}
    assert {None, "no_spot", "too_dim", "at_edge", "corrupt_frame", "wrong_size",
            "missing"} <= reasons


def test_quiet_stderr_interleaved_across_threads_restores_the_real_stderr():
    """Two decoders' quiet spells that overlap (A in, B in, A out, B out, as two camera threads
    do) leave file descriptor 2 on the real stderr, not on the null device."""
    import os

    from vlpcal.detection.decoding import _QuietStderr

    before = os.fstat(2)
    a, b = _QuietStderr(), _QuietStderr()
    a.__enter__()
    b.__enter__()
    assert os.fstat(2).st_ino != before.st_ino or os.fstat(2).st_dev != before.st_dev
    a.__exit__(None, None, None)
    b.__exit__(None, None, None)
    after = os.fstat(2)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, np.int16])
@pytest.mark.parametrize("k", [1, 2, 55, 56])
def test_row_medians_are_numpys_in_value_and_dtype(dtype, k, rng):
    """The detector's row medians (a partition, kept off np.median, whose NaN check imports
    numpy.ma at every start) equal np.median's, dtype included."""
    from vlpcal.detection.windows import _medians

    a = (rng.random((300, k)) * 255).astype(dtype)
    expected, got = np.median(a, axis=1), _medians(a)
    assert got.dtype == expected.dtype and np.array_equal(got, expected)
