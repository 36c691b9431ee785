"""Cameras to and from aniposelib TOML and OpenCV FileStorage YAML."""

import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from vlpcal.cli import main
from vlpcal.deployment import Deployment, load, save
from vlpcal.geometry import Camera, rodrigues, rotation_vector
from vlpcal.interchange import (
    InterchangeError,
    from_anipose_toml,
    from_opencv_yaml,
    to_anipose_toml,
    to_opencv_yaml,
)

ROOT = Path(__file__).resolve().parents[1]

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib


def twelve_cameras() -> list[Camera]:
    """12 distinct cameras on a 4 × 3 ceiling grid, each tilted and turned its own way, with
    its own lens; ids that sort differently as text and as numbers (C1, C2, …, C10, …)."""
    rng = np.random.default_rng(5)
    cams = []
    for i in range(12):
        tilt = rodrigues(rng.normal(0, 0.05, 3)) @ rodrigues((math.pi, 0, 0))
        cams.append(Camera(f"C{i + 1}", 160 + 160 * (i % 2), 120 + 120 * (i % 2),
                           150 + i, 151 + 1.5 * i, 79.5 + rng.normal(), 59.5 + rng.normal(),
                           tuple(rng.normal(0, 0.05, 5)),
                           (0.6 + 1.2 * (i % 4), 0.5 + 1.0 * (i // 4), 2.8 + 0.01 * i),
                           rotation_vector(tilt)))
    return cams


def assert_same(a: list[Camera], b: list[Camera], tol=1e-9):
    assert [c.id for c in a] == [c.id for c in b]
    for p, q in zip(a, b):
        for key in ("width", "height", "fx", "fy", "cx", "cy"):
            assert getattr(p, key) == pytest.approx(getattr(q, key), rel=tol), (p.id, key)
        np.testing.assert_allclose(p.dist, q.dist, atol=tol)
        np.testing.assert_allclose(p.position, q.position, atol=tol)
        np.testing.assert_allclose(rodrigues(p.rotation), rodrigues(q.rotation), atol=tol)
        X = np.array([[1.0, 1.0, 0.0], [2.0, 1.5, 0.7]])
        np.testing.assert_allclose(p.project(X)[0], q.project(X)[0], atol=1e-6)


@pytest.mark.parametrize("units", ["m", "cm", "mm"])
def test_anipose_round_trip_keeps_twelve_cameras_and_their_order(units):
    cams = twelve_cameras()
    text = to_anipose_toml(cams, units)
    assert_same(from_anipose_toml(text), cams)
    # aniposelib's CameraGroup.load takes the sections in sorted (text) order: padded names
    # make that the camera order
    doc = tomllib.loads(text)
    keys = sorted(k for k in doc if k != "metadata")
    assert [doc[k]["name"] for k in keys] == [c.id for c in cams]
    assert doc["metadata"]["units"] == units
    # translations are tvec = −R · position in the stated unit
    scale = {"m": 1, "cm": 100, "mm": 1000}[units]
    c = cams[7]
    np.testing.assert_allclose(doc[keys[7]]["translation"],
                               -rodrigues(c.rotation) @ np.array(c.position) * scale)


def test_anipose_files_written_by_aniposelib_keep_their_order():
    """aniposelib writes cam_0 … cam_11 unpadded; read in number order, not text order."""
    cams = twelve_cameras()
    doc = to_anipose_toml(cams, "mm")
    for i in range(12):  # rename the padded sections as aniposelib would write them
        doc = doc.replace(f"[cam_{i:02d}]", f"[cam_{i}]")
    doc = doc.replace('units = "mm"\n', "")
    assert_same(from_anipose_toml(doc, units="mm"), cams)
    with pytest.raises(InterchangeError, match="unit is not stated"):
        from_anipose_toml(doc)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("[cam_01]", "[cam_01]\nfisheye = true"), "fisheye"),
    (lambda t: t.replace("matrix = [ [", "matrix = [ [ 1.0, ", 1), r"cam_00\]\.matrix"),
    (lambda t: t.replace('name = "C2"', 'name = "C1"'), "C1.* twice"),
    (lambda t: t + "\n[extra]\na = 1\n", r"\[extra\]: unexpected section"),
    (lambda t: t.replace("translation = [", "translation = [ nan,", 1), "translation"),
    (lambda t: "[cam_0\n" + t, "not a TOML file"),
])
def test_anipose_import_refuses_what_it_cannot_read(edit, message):
    text = edit(to_anipose_toml(twelve_cameras()))
    with pytest.raises(InterchangeError, match=message):
        from_anipose_toml(text, "calib.toml")


def test_opencv_yaml_is_read_by_filestorage_and_round_trips():
    cams = twelve_cameras()
    text = to_opencv_yaml(cams)
    fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    assert fs.getNode("camera_count").real() == 12 and fs.getNode("units").string() == "m"
    node = fs.getNode("cameras").at(3)
    c = cams[3]
    K, rvec, tvec = (node.getNode(k).mat() for k in ("camera_matrix", "rvec", "tvec"))
    # OpenCV's own projection with the exported matrices agrees with vlpcal's
    X = np.array([[1.5, 1.2, 0.3], [2.0, 0.8, 0.0]])
    dist = node.getNode("distortion_coefficients").mat()
    uv = cv2.projectPoints(X, rvec, tvec, K, dist)[0].reshape(-1, 2)
    np.testing.assert_allclose(uv, c.project(X)[0], atol=1e-6)
    assert_same(from_opencv_yaml(text), cams)


def test_cli_export_import_round_trip_through_files(tmp_path):
    cams = twelve_cameras()
    dep = Deployment("hall", 3.0, [[0, 0], [5, 0], [5, 3.5], [0, 3.5]], cams,
                     extra={"fusion": {"method": "robust", "max_residual": 1.5}})
    save(dep, tmp_path / "dep.yaml")
    run = CliRunner().invoke
    for fmt, name, units in (("anipose", "c.toml", "mm"), ("opencv", "c.yaml", "m")):
        out = run(main, ["export", "-d", str(tmp_path / "dep.yaml"), "--to", fmt,
                         "--units", units, "-o", str(tmp_path / name)])
        assert out.exit_code == 0, out.output
        out = run(main, ["import", "--cameras", str(tmp_path / name), "-b",
                         str(tmp_path / "dep.yaml"), "-o", str(tmp_path / f"{fmt}.yaml")])
        assert out.exit_code == 0, out.output
        back = load(tmp_path / f"{fmt}.yaml")
        assert_same(back.cameras, cams)
        assert back.room == dep.room and back.max_residual == 1.5


def test_cli_import_errors_are_one_line(tmp_path):
    cams = twelve_cameras()
    (tmp_path / "c.toml").write_text(to_anipose_toml(cams, "mm").replace('units = "mm"\n', ""))
    site = "layouts/paper-linear.site.yaml"
    run = CliRunner().invoke
    cases = [
        (["--cameras", str(tmp_path / "c.toml"), "-b", site], "unit is not stated"),
        # cameras under a 2.8 m ceiling do not fit a room with a 2.3 m one
        (["--cameras", str(tmp_path / "c.toml"), "-b", site, "--units", "mm"],
         "not between the floor and the 2.3 m ceiling"),
        (["--cameras", str(tmp_path / "nope.toml"), "-b", site], "cannot read"),
        (["--cameras", str(tmp_path / "c.toml"), "-b", str(tmp_path / "c.toml"),
          "--units", "mm"], "not a vlpcal deployment or site file"),
    ]
    for args, message in cases:
        out = run(main, ["import", *args, "-o", str(tmp_path / "out.yaml")])
        assert out.exit_code == 2, out.output
        lines = out.output.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], out.output
        assert not (tmp_path / "out.yaml").exists()


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("distortions = [", 'distortions = [ "a",', 1), "distortions"),
    (lambda t: t.replace('units = "m"', 'units = [ "m",]'), "unit"),
    (lambda t: t.replace("size = [ 160", "size = [ -160", 1), "size"),
    (lambda t: t.replace('name = "C1"', 'name = " "'), "name"),
])
def test_malformed_anipose_values_are_named(edit, message):
    with pytest.raises(InterchangeError, match=message):
        from_anipose_toml(edit(to_anipose_toml(twelve_cameras())), "calib.toml")


def test_opencv_import_refuses_other_yaml_in_one_line():
    text = (ROOT / "layouts/paper-linear.deployment.yaml").read_text()  # not OpenCV's
    with pytest.raises(InterchangeError, match="vlpcal-deployment file, not an OpenCV"):
        from_opencv_yaml(text, "dep.yaml")
    good = to_opencv_yaml(twelve_cameras()[:2])
    bad = good.replace("camera_matrix:", "old_matrix:", 1)
    with pytest.raises(InterchangeError, match=r"cameras\[0\]\.camera_matrix"):
        from_opencv_yaml(bad, "c.yaml")


ODD_IDS = ("true", "null", "false", "nan", "1", "01", "1.0", "1e3", "0x1F", "inf", "yes", "Null")


def _renamed(cams, ids):
    keys = ("width", "height", "fx", "fy", "cx", "cy", "dist", "position", "rotation")
    return [Camera(i, **{k: getattr(c, k) for k in keys}) for i, c in zip(ids, cams)]


def test_opencv_export_keeps_ids_yaml_would_read_as_other_values(tmp_path):
    """An id true or null was a traceback (FileStorage writes it unquoted and reads it back
    as 1 or nothing, issue 31): every id is written quoted and comes back as it was, through
    the command line too."""
    cams = _renamed(twelve_cameras(), ODD_IDS)
    text = to_opencv_yaml(cams)
    assert 'id: "true"' in text and 'id: "null"' in text
    assert_same(from_opencv_yaml(text), cams)
    dep = Deployment("hall", 3.0, [[0, 0], [5, 0], [5, 3.5], [0, 3.5]], cams)
    save(dep, tmp_path / "dep.yaml")
    run = CliRunner().invoke
    out = run(main, ["export", "-d", str(tmp_path / "dep.yaml"), "--to", "opencv", "-o",
                     str(tmp_path / "c.yaml")])
    assert out.exit_code == 0 and out.exception is None, out.output
    out = run(main, ["import", "--cameras", str(tmp_path / "c.yaml"), "-b",
                     str(tmp_path / "dep.yaml"), "-o", str(tmp_path / "back.yaml")])
    assert out.exit_code == 0, out.output
    assert [c.id for c in load(tmp_path / "back.yaml").cameras] == list(ODD_IDS)


@pytest.mark.parametrize("written, outcome", [
    ("true", "true unquoted, which OpenCV reads as a number"),
    ("false", "false unquoted, which OpenCV reads as a number"),
    ("null", "null unquoted, which OpenCV reads as nothing"),
    ("01", "01"), ("1.0", "1.0"), ("7", "7"), ("'true'", "true"), ('"null"', "null"),
])
def test_an_unquoted_id_opencv_reads_as_another_value_is_not_renamed(tmp_path, written,
                                                                      outcome):
    """A hand-written camera file with id: true was imported as camera 1 (issue 31): an id
    OpenCV cannot read as text is one line naming it; one it reads as a number keeps the
    digits as written (01 stays 01)."""
    cams = twelve_cameras()[:2]
    text = re.sub(r'id: "?C2"?\n', f"id: {written}\n", to_opencv_yaml(cams))
    assert f"id: {written}\n" in text
    if "unquoted" in outcome:
        with pytest.raises(InterchangeError, match=r"c\.yaml: cameras\[1\]\.id: " + outcome):
            from_opencv_yaml(text, "c.yaml")
        (tmp_path / "c.yaml").write_text(text)
        out = CliRunner().invoke(main, ["import", "--cameras", str(tmp_path / "c.yaml"), "-b",
                                        "layouts/paper-linear.site.yaml", "-o",
                                        str(tmp_path / "out.yaml")])
        assert out.exit_code == 2 and len(out.output.strip().splitlines()) == 1, out.output
        assert outcome in out.output and not (tmp_path / "out.yaml").exists()
    else:
        assert [c.id for c in from_opencv_yaml(text)] == ["C1", outcome]


def test_import_drops_what_was_learned_for_other_cameras(tmp_path):
    """The same ids with new poses: the region map and corrections no longer hold."""
    root = ROOT / "surveys/paper-2024"
    run = CliRunner().invoke
    out = run(main, ["export", "-d", f"{root}/nominal.yaml", "--to", "anipose", "-o",
                     str(tmp_path / "nominal.toml")])
    assert out.exit_code == 0
    out = run(main, ["import", "--cameras", str(tmp_path / "nominal.toml"), "-b",
                     f"{root}/calibrated.yaml", "-o", str(tmp_path / "mixed.yaml")])
    assert out.exit_code == 0 and "dropped fusion.region_map" in out.output
    mixed = load(tmp_path / "mixed.yaml")
    assert mixed.region_map is None and mixed.fusion != "region"
    # the calibrated cameras themselves: everything kept
    run(main, ["export", "-d", f"{root}/calibrated.yaml", "--to", "anipose", "-o",
               str(tmp_path / "cal.toml")])
    out = run(main, ["import", "--cameras", str(tmp_path / "cal.toml"), "-b",
                     f"{root}/calibrated.yaml", "-o", str(tmp_path / "same.yaml")])
    assert out.exit_code == 0 and "dropped" not in out.output
    assert load(tmp_path / "same.yaml").region_map is not None
