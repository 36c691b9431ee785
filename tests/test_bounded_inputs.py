"""Issue 31, items 3 and 5: zones that tile the room, and every input within a limit checked
before the work it would cost (a file past it refused in one line, in bounded time and
memory: counted, never parsed)."""

import os
import string

import numpy as np
import pytest
from click.testing import CliRunner
from test_hostile import _vlpcal

from vlpcal.cli import main as cli
from vlpcal.datasets import (
    DatasetError,
    FreeAppender,
    read_async_frames,
    read_observations,
    read_points,
    read_survey_bundle,
)
from vlpcal.deployment import Deployment, DeploymentError, from_dict, save
from vlpcal.geometry import paper_camera

CAMS = [paper_camera(f"C{k + 1}", (1.2 * (k + 1), 0.9, 2.3)) for k in range(5)]
ROOM = [[0, 0], [7.2, 0], [7.2, 1.8], [0, 1.8]]


def _box(x0, x1, y0=0.0, y1=1.8):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def _zones(*zones):
    return {"zones": [{"id": name, "polygon": polygon, "cameras": ["C1", "C2", "C3"]}
                      for name, polygon in zones]}


# -- zones ----------------------------------------------------------------------------------

@pytest.mark.parametrize("zones", [
    [("west", _box(0, 3.0)), ("east", _box(3.0, 7.2))],  # meeting along x = 3
    [("west", _box(0, 3.0004)), ("east", _box(3.0, 7.2))],  # 0.4 mm: rounding, not overlap
    [("west", _box(0, 2.9996)), ("east", _box(3.0, 7.2))],  # … nor a gap
    [("west", _box(-1, 3.0, -1, 3)), ("east", _box(3.0, 9, -1, 3))],  # past the walls
    [("site", _box(0, 7.2))],
    [("a", _box(0, 3.6, 0, 0.9)), ("b", _box(0, 3.6, 0.9, 1.8)),
     ("c", [[3.6, 0], [7.2, 0], [7.2, 1.8], [3.6, 1.8], [3.6, 0.9]])],  # a T: a vertex on a side
])
def test_zones_that_tile_the_room_are_accepted(zones):
    dep = from_dict(Deployment("line", 2.3, ROOM, CAMS, [], _zones(*zones)).to_dict(), "d.yaml")
    assert list(dep.zones) == [name for name, _ in zones]


@pytest.mark.parametrize("zones,fragments", [
    ([("west", _box(0, 3.5)), ("east", _box(3.0, 7.2))],
     ["zones: west and east overlap over 0.9 m²", "around (3.25, 0.9)", "published twice"]),
    ([("west", _box(-1, 3.0, -1, 3)),  # beyond the south wall, east reaches under west
      ("east", [[2, -1], [8, -1], [8, 1.8], [3, 1.8], [3, 0], [2, 0]])],
     ["zones: west and east overlap over 1 m² around (2.5, -0.5)", "published twice"]),
    ([("west", _box(0, 3.0)), ("east", _box(3.2, 7.2))],
     ["zones: 0.36 m² of site.room (2.78%) in no zone", "beside west and east",
      "around (3.1, 0.9)", "published by none"]),
    ([("west", _box(0, 3.0)), ("east", _box(3.0, 7.0))],  # 0.2 m at the east wall
     ["in no zone", "beside east around (7.1, 0.9)", "cover the room"]),
    ([("site", _box(0, 7.2)), ("moon", _box(10, 12))],
     ["zones[1].polygon: zone moon lies outside site.room", "publishes no fix"]),
    ([("site", _box(0, 7.2)), ("wall", _box(7.2, 9))],  # touching the room only
     ["zone wall lies outside site.room"]),
])
def test_zones_overlapping_parting_or_outside_the_room_are_refused_naming_them(zones,
                                                                               fragments):
    doc = Deployment("line", 2.3, ROOM, CAMS, [], _zones(*zones)).to_dict()
    with pytest.raises(DeploymentError) as e:
        from_dict(doc, "d.yaml")
    message = str(e.value)
    assert "\n" not in message and message.startswith("d.yaml: zones")
    for fragment in fragments:
        assert fragment in message, message


def test_a_gap_is_judged_against_the_rooms_size():
    """The slack is a share of the room: 5 mm between zones is a gap in a 7.2 m room (slack
    0.72 mm) and rounding in a 72 km one (slack 7.2 m)."""
    zones = _zones(("west", _box(0, 3.0)), ("east", _box(3.005, 7.2)))
    with pytest.raises(DeploymentError, match="in no zone"):
        from_dict(Deployment("line", 2.3, ROOM, CAMS, [], zones).to_dict())
    big = [[x * 1e4, y * 1e4] for x, y in ROOM]  # (the scene scaled whole: ceiling too)
    cams = [paper_camera(f"C{k + 1}", (1.2e4 * (k + 1), 0.9e4, 2.3e4)) for k in range(5)]
    zones = _zones(("west", _box(0, 3.0e4, 0, 1.8e4)), ("east", _box(3.0e4 + 5, 7.2e4, 0,
                                                                        1.8e4)))
    from_dict(Deployment("big", 2.3e4, big, cams, [], zones).to_dict())


def test_a_site_split_in_more_zones_than_a_site_has_machines_is_refused():
    xs = np.linspace(0, 7.2, 66)
    zones = _zones(*[(f"z{k}", _box(a, b)) for k, (a, b) in enumerate(zip(xs, xs[1:]))])
    with pytest.raises(DeploymentError, match="zones: expected a list of 1 to 64"):
        from_dict(Deployment("line", 2.3, ROOM, CAMS, [], zones).to_dict())


# -- the deployment file ------------------------------------------------------------------

def test_a_leds_block_of_a_hundred_thousand_entries_is_refused_by_the_files_size(tmp_path):
    """Found: 587 MB and 32 s in the YAML parser before the '1 to 64' refusal. A deployment
    past 1 MB is refused before it is parsed."""
    path = tmp_path / "d.yaml"
    save(Deployment("line", 2.3, ROOM, CAMS), path)
    with open(path, "a") as f:
        f.write("leds:\n" + "".join(f"  - {{id: L{i}, pattern: '0101101', bit_rate: 30}}\n"
                                    for i in range(100_000)))
    code, out, err, rss = _vlpcal("show", path, timeout=30)
    assert code == 2 and len(err) == 1 and not out, (out, err)
    assert err[0].startswith(f"Error: {path}: ") and "1048576 expected of a deployment" in err[0]
    assert rss < 100, f"{rss:.0f} MB"


# -- CSV files: counted before they are parsed ------------------------------------------------

def _rows(path, header, rows, newline_at_end=True):
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join([header, *rows])
    path.write_text(text + ("\n" if newline_at_end else ""))
    return path


@pytest.mark.parametrize("reader,cap,header,row,noun", [
    (lambda p: read_points(p), "MAX_POINTS", "point_id,x,y,z", "P{i},1,2,0", "points"),
    (lambda p: read_observations(p), "MAX_OBSERVATIONS", "frame_id,camera_id,u,v",
     "{i},C1,1,2", "spots"),
    (lambda p: read_observations(p, "set_id", several=True), "MAX_FREE_SPOTS",
     "set_id,camera_id,u,v", "{i},C1,1,2", "spots"),
    (lambda p: read_async_frames(p.parent), "MAX_TIMES_FRAMES", "camera_id,frame_no,t",
     "C1,{i},{i}", "frames"),
])
def test_each_csv_reader_counts_its_rows_before_it_parses_any(tmp_path, monkeypatch, reader,
                                                              cap, header, row, noun):
    """At the cap (with or without a last newline) the file is read; one row past it, it is
    refused by its count — before its first row, which is wrong, is ever parsed."""
    import vlpcal.datasets as datasets

    monkeypatch.setattr(datasets, cap, 5)
    rows = [row.format(i=i) for i in range(5)]
    for end in (True, False):
        reader(_rows(tmp_path / "a" / "times.csv", header, rows, end))
    bad = _rows(tmp_path / "b" / "times.csv", header, ["not,a,row,at all", *rows])
    with pytest.raises(DatasetError) as e:
        reader(bad)
    assert str(e.value).startswith(f"{bad}: more than 5 {noun} (")
    with pytest.raises(DatasetError, match="line 2"):  # under the cap the row is parsed
        reader(_rows(tmp_path / "c" / "times.csv", header, ["not,a,row,at all", *rows[1:]]))


def test_a_free_capture_resumes_only_a_file_within_the_cap(tmp_path, monkeypatch):
    import vlpcal.datasets as datasets

    monkeypatch.setattr(datasets, "MAX_FREE_SPOTS", 3)
    app = FreeAppender(tmp_path)
    for k in range(3):
        app.add({"C1": (10.0 + k, 20.0)})
    assert FreeAppender(tmp_path).set_ids == ["F000001", "F000002", "F000003"]
    app.add({"C1": (1.0, 2.0)})
    with pytest.raises(DatasetError, match="more than 3 spots"):
        FreeAppender(tmp_path)


def _deployment(tmp_path, cameras=CAMS):
    path = tmp_path / "d.yaml"
    save(Deployment("line", 2.3, ROOM, cameras), path)
    return path


def test_a_times_csv_of_a_million_frames_is_refused_in_bounded_memory(tmp_path):
    """Found: a 31 MB times.csv of 2.8 M rows took 1.19 GB and 103 s before its refusal."""
    letters = string.ascii_uppercase
    (tmp_path / "f").mkdir()
    with open(tmp_path / "f" / "times.csv", "w") as f:
        f.write("camera_id,frame_no,t\n")
        f.writelines(f"{letters[i % 26]},{i // 26},{i // 300000}\n" for i in range(1_000_000))
    code, out, err, rss = _vlpcal("track", "-d", _deployment(tmp_path), "--frames",
                                  tmp_path / "f", "--out", tmp_path / "t.csv", timeout=30)
    assert code == 2 and len(err) == 1, (out, err)
    assert err[0] == (f"Error: {tmp_path / 'f' / 'times.csv'}: more than 500000 frames (over "
                      "an hour of four cameras at 30 fps: split the recording)")
    assert rss < 100, f"{rss:.0f} MB"


def test_a_survey_of_200000_points_is_refused_before_the_calibration(tmp_path):
    """Found: 200 000 points nobody saw took survey calibrate 554 MB and over a minute."""
    (tmp_path / "s").mkdir()
    with open(tmp_path / "s" / "points.csv", "w") as f:
        f.write("point_id,x,y,z\n")
        f.writelines(f"P{i},{i % 7}.5,1.5,0\n" for i in range(200_000))
    code, out, err, rss = _vlpcal("survey", "calibrate", "-d", _deployment(tmp_path),
                                  "--survey", tmp_path / "s", "-o", tmp_path / "c.yaml",
                                  timeout=30)
    assert code == 2 and err[-1].startswith(f"Error: {tmp_path / 's' / 'points.csv'}: more "
                                            "than 10000 points ("), (out, err)
    assert rss < 100, f"{rss:.0f} MB"


def test_a_free_survey_past_its_cap_is_refused_in_bounded_memory(tmp_path):
    """Found: a free/observations.csv of 2.3 M rows took 1.23 GB."""
    letters = string.ascii_uppercase
    _rows(tmp_path / "b" / "points.csv", "point_id,x,y,z", ["R1,1,1,0", "R2,2,1,0"])
    (tmp_path / "b" / "free").mkdir()
    with open(tmp_path / "b" / "free" / "observations.csv", "w") as f:
        f.write("set_id,camera_id,u,v\n")
        f.writelines(f"{i // 26},{letters[i % 26]},1,2\n" for i in range(900_000))
    code, out, err, rss = _vlpcal("survey", "calibrate", "-d", _deployment(tmp_path),
                                  "--survey", tmp_path / "b", "-o", tmp_path / "c.yaml",
                                  timeout=30)
    assert code == 2 and "free/observations.csv: more than 800000 spots (" in err[-1], err
    assert rss < 100, f"{rss:.0f} MB"


# -- locate --observations ---------------------------------------------------------------------

def test_locate_observations_are_capped_and_a_fifo_refused_without_waiting(tmp_path,
                                                                             monkeypatch):
    import vlpcal.datasets as datasets

    dep = _deployment(tmp_path)
    os.mkfifo(tmp_path / "spots.csv")  # opening it for reading would wait for a writer
    code, out, err, _ = _vlpcal("locate", "-d", dep, "--observations", tmp_path / "spots.csv",
                                "--out", tmp_path / "f.csv", timeout=20)
    assert code == 2 and err == [f"Error: {tmp_path / 'spots.csv'}: not a regular file "
                                 "(expected a CSV file of spots)"], (out, err)
    monkeypatch.setattr(datasets, "MAX_OBSERVATIONS", 10)
    obs = _rows(tmp_path / "o.csv", "frame_id,camera_id,u,v", [f"{i},C1,1,2" for i in range(11)])
    res = CliRunner().invoke(cli, ["locate", "-d", str(dep), "--observations", str(obs),
                                   "--out", str(tmp_path / "f.csv")])
    assert res.exit_code == 2 and f"{obs}: more than 10 spots (" in res.output, res.output


def _spots(n_frames, rng):
    """An LED along the line of cameras, its spots as C1–C5 and a camera the deployment lacks
    (C9) report them, with noise; some frames seen by none of the deployment's cameras."""
    rows = []
    for k in range(n_frames):
        X = np.array([[0.5 + 6.2 * k / n_frames, 0.9 + 0.3 * np.sin(k / 7), 0.2]])
        if k % 11 == 5:
            rows.append(f"f{k},C9,100,100")
            continue
        for cam in CAMS:
            uv, _, inside = cam.project(X, margin=2.0)
            if inside[0]:
                u, v = uv[0] + rng.normal(0, 0.05, 2)
                rows.append(f"f{k},{cam.id},{u:.4f},{v:.4f}")
    rng.shuffle(rows)  # the file's order is not the frames'
    return rows


def test_locate_observations_in_chunks_gives_what_one_batch_gives(tmp_path, monkeypatch, rng):
    """The spots are located a chunk of frame sets at a time (memory bounded by the chunk,
    not the file): the fixes are the same rows, in the file's order of frames."""
    import vlpcal.cli.locate as locate

    dep = _deployment(tmp_path)
    obs = _rows(tmp_path / "o.csv", "frame_id,camera_id,u,v", _spots(200, rng))
    out = {}
    for chunk in (7, 10_000):
        monkeypatch.setattr(locate, "OBSERVATION_CHUNK", chunk)
        res = CliRunner().invoke(cli, ["locate", "-d", str(dep), "--observations", str(obs),
                                       "--out", str(tmp_path / f"{chunk}.csv")])
        assert res.exit_code == 0, res.output
        assert "ignored spots of camera(s) C9" in res.output
        out[chunk] = (tmp_path / f"{chunk}.csv").read_text().splitlines()
    assert out[7] == out[10_000] and len(out[7]) == 201
    first = list(dict.fromkeys(line.split(",")[0] for line in obs.read_text().splitlines()[1:]))
    assert [line.split(",")[0] for line in out[7][1:]] == first
    statuses = [line.split(",")[4] for line in out[7][1:]]
    assert statuses.count("ok") > 100 and statuses.count("no_spot") == 18


def test_locate_observations_at_the_cap_stay_in_bounded_memory(tmp_path):
    """Found: 3 M rows took 2.06 GB. At the cap, 500 000 spots (250 000 frame sets, two
    cameras each) took 471 MB when located in one batch; a chunk at a time, about 200 MB."""
    with open(tmp_path / "o.csv", "w") as f:
        f.write("frame_id,camera_id,u,v\n")
        f.writelines(f"{i},C1,{300 + i % 50}.5,200.5\n{i},C2,{310 + i % 50}.5,200.5\n"
                     for i in range(250_000))
    code, out, err, rss = _vlpcal("locate", "-d", _deployment(tmp_path, CAMS[:2]),
                                  "--observations", tmp_path / "o.csv", "--out",
                                  tmp_path / "f.csv", "-q", timeout=60)
    assert code == 0, err
    assert sum(1 for _ in open(tmp_path / "f.csv")) == 250_001
    assert rss < 300, f"{rss:.0f} MB"


def test_a_bundles_csv_files_are_counted_too(tmp_path, monkeypatch):
    """A survey bundle's points.csv and observations.csv go through the same counting."""
    import vlpcal.datasets as datasets

    monkeypatch.setattr(datasets, "MAX_POINTS", 2)
    _rows(tmp_path / "b" / "points.csv", "point_id,x,y,z", ["P1,1,1,0", "P2,2,1,0", "P3,3,1,0"])
    with pytest.raises(DatasetError, match=r"points.csv: more than 2 points \("):
        read_survey_bundle(tmp_path / "b")


def test_every_fix_has_exactly_one_zone_even_on_a_border_or_past_the_walls():
    """A fix on the border two zones share was published by neither (each kept what its
    polygon strictly held), and one past the walls by none: now each fix is one zone's."""
    from types import SimpleNamespace

    from vlpcal.cli.mqtt import ZoneWriter

    class Kept:
        def __init__(self):
            self.fixes = []

        def write(self, fixes, extra=None):
            self.fixes += fixes

    zones = {"west": (_box(0, 3.0), ["C1"]), "east": (_box(3.0, 7.2), ["C2"])}
    at = [(1.0, 0.5), (3.0, 0.5), (3.0, 0.0), (5.0, 1.0), (-0.2, 0.9), (7.5, 2.0),
          (3.0, -0.4), (float("nan"), 1.0)]
    fixes = [SimpleNamespace(x=x, y=y, z=0.1) for x, y in at]
    kept = {zone: Kept() for zone in zones}
    for zone in zones:
        ZoneWriter(kept[zone], zones, zone).write(fixes)
    west = {(f.x, f.y) for f in kept["west"].fixes}
    east = {(f.x, f.y) for f in kept["east"].fixes}
    assert not west & east
    assert west | east == set(at[:-1])  # every placed fix once; no position: no zone's
    assert {(1.0, 0.5), (-0.2, 0.9), (3.0, 0.5), (3.0, 0.0)} <= west  # (the border: west)
    assert {(5.0, 1.0), (7.5, 2.0)} <= east
