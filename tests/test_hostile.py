"""Hostile and careless files against every reader of YAML and TOML (issue 14): one line that
names the file and what was expected, exit 2, no traceback, bounded time and memory."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "layouts" / "paper-linear.site.yaml"
DEPLOYMENT = ROOT / "layouts" / "paper-linear.deployment.yaml"


def _bomb(levels=9, width=9) -> str:
    """The 'billion laughs': each level an anchored list of aliases to the one before."""
    lines = ['l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * width) + "]")
    return "\n".join(lines) + f"\nformat: *l{levels - 1}\n"


HOSTILE = {
    "duplicate key": (DEPLOYMENT.read_text() + "\ncameras: []\n", "duplicate key 'cameras'"),
    "alias bomb": (_bomb(), "aliases"),
    "deep flow nesting": ("[" * 50_000 + "]" * 50_000, "nested deeper than"),
    "deep block nesting": ("".join(" " * i + "-\n" for i in range(500)), "nested deeper than"),
    "not UTF-8": (b"format: vlpcal-deployment\nname: \xff\xfe\n", "not UTF-8"),
    "not YAML": ("format: [unclosed\n", "not valid YAML"),
}


def _vlpcal(*args, cwd=None, timeout=60, prelude=""):
    """Run the command in a child process (``prelude``: Python run first, e.g. a limit); its
    output, exit code and peak memory (MB)."""
    # VmHWM: this process's peak since its exec (getrusage's ru_maxrss can carry the forked
    # parent's, a large pytest, across the exec)
    code = (prelude + "\nimport sys; from vlpcal.cli import main\n"
            "try:\n    main(sys.argv[1:], prog_name='vlpcal')\n"
            "finally:\n"
            "    hwm = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM')]\n"
            "    print(f'@maxrss {hwm[0]}', file=sys.stderr)\n")
    r = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True,
                       text=True, timeout=timeout, cwd=cwd)
    err = [line for line in r.stderr.splitlines() if not line.startswith("@maxrss")]
    rss = [int(line.split()[1]) for line in r.stderr.splitlines() if line.startswith("@maxrss")]
    return r.returncode, r.stdout, err, rss[0] / 1024 if rss else None


def _write(path: Path, content):
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)


@pytest.mark.parametrize("case", sorted(HOSTILE))
@pytest.mark.parametrize("role", ["deployment", "site", "import base"])
def test_hostile_yaml_is_one_line(tmp_path, case, role):
    content, fragment = HOSTILE[case]
    bad = tmp_path / "bad.yaml"
    _write(bad, content)
    before = bad.read_bytes()
    if role == "deployment":
        args = ["check", "--site", SITE, "-d", bad]
    elif role == "site":
        args = ["plan", "--site", bad, "--out", tmp_path / "out.yaml"]
    else:
        cams = tmp_path / "cams.toml"
        cams.write_text("[cam_0]\nname = 'C1'\n")
        args = ["import", "--cameras", cams, "-b", bad, "-o", tmp_path / "out.yaml"]
    code, out, err, rss = _vlpcal(*args)
    lines = [line for line in (out.splitlines() + err) if line.strip()]
    assert code == 2, (out, err)
    assert len(lines) == 1 and "Traceback" not in lines[0], lines
    assert str(bad) in lines[0]
    if role != "import base" or fragment != "not valid YAML":
        assert fragment in lines[0], lines
    assert rss is not None and rss < 500, f"{rss:.0f} MB"
    assert bad.read_bytes() == before and not (tmp_path / "out.yaml").exists()


@pytest.mark.parametrize("kind", ["fifo", "folder", "too big"])
def test_special_files_are_refused_by_type_and_size(tmp_path, kind):
    bad = tmp_path / "bad.yaml"
    if kind == "fifo":
        os.mkfifo(bad)  # opening it for reading would wait for a writer forever
    elif kind == "folder":
        bad.mkdir()
    else:
        with open(bad, "wb") as f:
            f.truncate(64 * 2 ** 20)  # sparse: 64 MB of zeros without the disk
    code, out, err, _ = _vlpcal("check", "--site", SITE, "-d", bad, timeout=30)
    lines = [line for line in (out.splitlines() + err) if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in lines[0], lines
    assert str(bad) in lines[0] or "bad.yaml" in lines[0]


def test_deeply_nested_opencv_and_toml_camera_files(tmp_path):
    """OpenCV's FileStorage parser recurses without a limit (a segfault) and TOML's raises
    RecursionError: both are one line."""
    cv = tmp_path / "cams.yaml"
    cv.write_text("%YAML:1.0\ncameras:\n" + "[" * 200_000 + "]" * 200_000 + "\n")
    toml = tmp_path / "cams.toml"
    toml.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    for cams in (cv, toml):
        code, out, err, _ = _vlpcal("import", "--cameras", cams, "-b", SITE, "-o",
                                    tmp_path / "out.yaml")
        lines = [line for line in (out.splitlines() + err) if line.strip()]
        assert code == 2 and len(lines) == 1 and "Traceback" not in lines[0], lines
        assert str(cams) in lines[0]
        assert not (tmp_path / "out.yaml").exists()


def test_an_error_quotes_a_huge_value_briefly(tmp_path):
    """A value that is wrong is quoted in the error cut short, however large it is."""
    doc = DEPLOYMENT.read_text().replace("name:", "name: [" + ", ".join(["1"] * 100_000)
                                         + "]\nold_name:", 1)
    bad = tmp_path / "big-value.yaml"
    bad.write_text(doc)
    code, out, err, _ = _vlpcal("check", "--site", SITE, "-d", bad)
    lines = [line for line in (out.splitlines() + err) if line.strip()]
    assert code == 2 and len(lines) == 1 and len(lines[0]) < 400, lines


def test_reader_limits_are_what_the_module_says():
    from vlpcal.reading import MAX_DEPTH, MAX_NODES, nesting_depth, shown

    assert 5 <= nesting_depth("a:\n  b:\n    - [1, [2, 3]]\n") <= 6  # an upper estimate
    assert nesting_depth("s: '[[[['\n") == 1  # brackets inside quotes do not count
    assert MAX_DEPTH >= 8 and MAX_NODES >= 100_000
    assert len(shown(list(range(10 ** 6)))) < 100


def _shared_deployment(cameras: int = 40) -> dict:
    """The paper's deployment with ``cameras`` cameras whose lens lists are one list object
    each (a script's deployment): yaml.safe_dump writes them as an anchor and aliases."""
    import yaml

    doc = yaml.safe_load(DEPLOYMENT.read_text())
    first = doc["cameras"][0]
    dist, rotation = first["dist"], first["rotation"]
    doc["cameras"] = [dict(first, id=f"C{i + 1}", dist=dist, rotation=rotation,
                           position=[0.1 + 3.4 * i / cameras, 0.9, 2.3]) for i in range(cameras)]
    return doc


def test_a_deployment_written_by_pyyaml_with_aliases_is_read(tmp_path):
    """PyYAML writes a list shared by 40 cameras as &id001 once and *id001 79 times: read as
    the document it stands for (issue 31), as a command reads it too."""
    import yaml

    from vlpcal.deployment import load

    path = tmp_path / "shared.yaml"
    path.write_text(yaml.safe_dump(_shared_deployment(40)))
    assert path.read_text().count("*id00") >= 78  # aliases, as PyYAML writes them
    dep = load(path)
    assert len(dep.cameras) == 40 and dep.cameras[39].id == "C40"
    assert all(c.dist == dep.cameras[0].dist for c in dep.cameras)
    code, out, err, _ = _vlpcal("show", path)
    assert code == 0 and "C40" in out, (out, err)


@pytest.mark.parametrize("case", ["bomb", "deep through aliases", "holds itself"])
def test_aliases_that_multiply_deepen_or_loop_are_refused(case):
    """Aliases are counted as what they expand to: a bomb whose document is 30 lines, a
    value nested 20 deep named inside 20 levels, a value that holds itself: one line each."""
    from vlpcal.reading import MAX_DEPTH, MAX_NODES, ReadError, load_yaml

    if case.startswith("bomb"):  # 100 × 100 × 100 × 100 = 10⁸ values from 4 lines
        text = _bomb(levels=4, width=100).replace('"lol", ' * 8, '"lol", ' * 99)
        fragment = f"more than {MAX_NODES} values with its aliases"
    elif case.startswith("deep"):
        half = MAX_DEPTH // 2 + 2
        text = "a: &a " + "[" * half + "]" * half + "\nb: " + "[" * half + "*a" + "]" * half
        fragment = "nested deeper than"
    else:
        text = "a: &a [1, *a]\n"
        fragment = "inside the value it names"
    with pytest.raises(ReadError, match=fragment) as e:
        load_yaml("x.yaml", text=text)
    assert "\n" not in str(e.value) and str(e.value).startswith("x.yaml: line ")


@pytest.mark.parametrize("command", ["locate", "export", "import", "survey plan",
                                     "survey plan png", "plan", "calibrate"])
def test_no_command_writes_over_its_own_input(tmp_path, command):
    """--out naming the command's own input (or a name whose companion would land on it) is
    one line, exit 2, before any work; the input is unchanged."""
    import shutil

    dep = tmp_path / "deployment.yaml"
    shutil.copy(DEPLOYMENT, dep)
    site = tmp_path / "site.yaml"
    shutil.copy(SITE, site)
    frames = tmp_path / "frames"
    (frames / "f1").mkdir(parents=True)
    args, victim = {
        "locate": (["locate", "-d", dep, "--observations", tmp_path / "obs.csv", "--out",
                    tmp_path / "obs.csv"], tmp_path / "obs.csv"),
        "export": (["export", "-d", dep, "--to", "opencv", "-o", dep], dep),
        "import": (["import", "--cameras", dep, "-b", site, "-o", site], site),
        "survey plan": (["survey", "plan", "-d", dep, "--out", dep.with_suffix(".csv")], None),
        "survey plan png": (["survey", "plan", "-d", dep, "--out", tmp_path / "map.png"], None),
        "plan": (["plan", "--site", site, "--out", site], site),
        "calibrate": (["survey", "calibrate", "-d", dep, "--survey", tmp_path, "--out",
                       tmp_path / "deployment.yaml"], dep),
    }[command]
    if command == "survey plan":  # its map would land on a file given as the deployment
        dep.with_suffix(".png").write_bytes(b"not a picture")
        args = ["survey", "plan", "-d", dep.with_suffix(".png"), "--out",
                dep.with_suffix(".csv")]
        shutil.copy(DEPLOYMENT, dep.with_suffix(".png"))
        victim = dep.with_suffix(".png")
    (tmp_path / "obs.csv").write_text("frame_id,camera_id,u,v\nf1,C1,80,60\nf1,C2,70,60\n")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    code, out, err, _ = _vlpcal(*args)
    lines = [line for line in (out.splitlines() + err) if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in lines[0], lines
    after = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert after == before, f"{victim} or another file changed"


def test_a_bad_observations_file_leaves_stdout_clean(tmp_path):
    """The fixes go to stdout for a pipe: an input refused before any fix prints its one-line
    error and nothing on stdout (not a CSV header a reader would take for an empty result)."""
    bad = tmp_path / "obs.csv"
    bad.write_text("frame,cam,x\n1,2,3\n")
    code, out, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--observations", bad)
    assert code == 2 and out == "" and len([e for e in err if e.strip()]) == 1, (out, err)


def test_a_small_jpeg_declaring_a_huge_image_is_not_decoded(tmp_path):
    """A 2 kB JPEG whose header says 32000 × 32000 (a gigabyte to decode): refused from its
    header, the frame set keeps its row, memory stays small."""
    import cv2
    import numpy as np

    img = np.zeros((120, 160), np.uint8)
    img[55:65, 75:85] = 255
    frame = cv2.imencode(".jpg", img)[1].tobytes()
    bomb = bytearray(frame)
    at = bomb.find(b"\xff\xc0")
    bomb[at + 5:at + 9] = (32000).to_bytes(2, "big") * 2
    (tmp_path / "frames" / "f1").mkdir(parents=True)
    (tmp_path / "frames" / "f1" / "C1.jpg").write_bytes(bytes(bomb))
    for cid in ("C2", "C3"):
        (tmp_path / "frames" / "f1" / f"{cid}.jpg").write_bytes(frame)
    out = tmp_path / "fixes.csv"
    code, _, err, rss = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", tmp_path / "frames",
                                "--out", out)
    assert code == 0, err
    rows = out.read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("f1,")
    assert rss is not None and rss < 500, f"{rss:.0f} MB"


def _jpeg_bomb(frame: bytes) -> bytes:
    """``frame`` with its header declaring 32000 × 32000 (a gigabyte to decode)."""
    bomb = bytearray(frame)
    at = bomb.find(b"\xff\xc0")
    bomb[at + 5:at + 9] = (32000).to_bytes(2, "big") * 2
    return bytes(bomb)


def test_a_cameras_usual_size_is_judged_from_its_frames_not_its_first():
    import cv2
    import numpy as np

    from vlpcal.detection import spread, usual_size

    frame = cv2.imencode(".jpg", np.zeros((120, 160), np.uint8))[1].tobytes()
    bomb = _jpeg_bomb(frame)
    assert usual_size([bomb, frame, frame]) == (120, 160)  # one damaged set: not the size
    assert usual_size([bomb, bomb, frame]) == (32000, 32000)  # most frames: the size
    assert usual_size([bomb, frame]) is None  # no majority: nothing to judge by
    assert usual_size([None, b"", b"not a jpeg"]) is None
    assert spread(range(100), 5) == [0, 25, 50, 74, 99] and spread([1, 2], 9) == [1, 2]


def test_one_frame_set_of_huge_jpegs_is_its_rows_status_not_the_runs_refusal(tmp_path):
    """A folder whose first frame set is three 2 kB JPEGs declaring 32000 × 32000 refused the
    whole run ("frames of another size", judged from each camera's first frame): the set's
    row says wrong_size, the other sets are located, memory stays small."""
    import csv

    import cv2
    import numpy as np

    img = np.zeros((120, 160), np.uint8)
    img[55:65, 75:85] = 255
    frame = cv2.imencode(".jpg", img)[1].tobytes()
    for fid in ("f1", "f2", "f3"):
        (tmp_path / "frames" / fid).mkdir(parents=True)
        for cid in ("C1", "C2", "C3"):
            (tmp_path / "frames" / fid / f"{cid}.jpg").write_bytes(
                _jpeg_bomb(frame) if fid == "f1" else frame)
    out = tmp_path / "fixes.csv"
    code, _, err, rss = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", tmp_path / "frames",
                                "--out", out)
    assert code == 0, err
    rows = {r["frame_id"]: r for r in csv.DictReader(out.open())}
    assert sorted(rows) == ["f1", "f2", "f3"] and rows["f1"]["status"] != "ok"
    assert "wrong_size" in "".join(rows["f1"].values())
    assert rss is not None and rss < 500, f"{rss:.0f} MB"
    # a folder whose every set is of another size is still the wrong deployment's
    for fid in ("f2", "f3"):
        for cid in ("C1", "C2", "C3"):
            (tmp_path / "frames" / fid / f"{cid}.jpg").write_bytes(_jpeg_bomb(frame))
    code, _, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", tmp_path / "frames",
                              "--out", out)
    assert code == 2 and "frames of another size" in err[-1], err


# -- the output discipline: full disks, special targets, killed runs (vlpcal.writing) ----------

#: a child whose files may not grow past 100 bytes: what a full disk looks like to a writer
FULL_DISK = ("import resource, signal\nsignal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
             "resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))")
SURVEY = ROOT / "surveys" / "paper-2024"


def _outputs(tmp_path, command):
    """(args, the files the command writes) for a command writing into ``tmp_path``."""
    obs = SURVEY / "spots.csv"
    return {
        "export": (["export", "-d", DEPLOYMENT, "--to", "opencv", "-o", tmp_path / "c.yaml"],
                   ["c.yaml"]),
        "import": (["import", "--cameras", tmp_path / "in" / "cams.toml", "-b", SITE, "-o",
                    tmp_path / "i.yaml"], ["i.yaml"]),
        "locate": (["locate", "-d", SURVEY / "truth.yaml", "--observations", obs, "--out",
                    tmp_path / "f.csv"], ["f.csv"]),
        "survey plan": (["survey", "plan", "-d", DEPLOYMENT, "--out", tmp_path / "p.csv"],
                        ["p.csv", "p.png"]),
        "check --maps": (["check", "--site", SITE, "-d", DEPLOYMENT, "--maps",
                          tmp_path / "m.png"], ["m.png"]),
        "calibrate": (["survey", "calibrate", "-d", SURVEY / "nominal.yaml", "--survey",
                       SURVEY / "survey", "--out", tmp_path / "cal.yaml", "--folds", "2"],
                      ["cal.yaml", "cal.report.json", "cal.png"]),
    }[command]


def _snapshot(folder: Path) -> dict:
    return {p.name: (p.is_symlink(), p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def font_cache():
    """matplotlib's font cache made before a child that cannot write files draws a figure."""
    import matplotlib.font_manager  # noqa: F401


@pytest.mark.parametrize("command", ["export", "import", "locate", "survey plan",
                                     "check --maps", "calibrate"])
def test_a_full_disk_is_one_line_and_loses_nothing(tmp_path, command, font_cache):
    """Every command that writes, on a disk that takes no more bytes: one line naming the
    output, exit 2, the previous files as they were, no temporary file left."""
    args, files = _outputs(tmp_path, command)
    if command == "import":  # a camera file to import, from vlpcal export
        (tmp_path / "in").mkdir()
        assert _vlpcal("export", "-d", DEPLOYMENT, "--to", "anipose", "-o",
                       tmp_path / "in" / "cams.toml")[0] == 0
    for name in files:
        (tmp_path / name).write_bytes(b"the previous " + name.encode())
    before = _snapshot(tmp_path)
    code, out, err, _ = _vlpcal(*args, prelude=FULL_DISK, timeout=120)
    lines = [line for line in err if line.startswith("Error")]  # calibrate also reports
    assert code == 2, (out, err)
    assert len(lines) == 1 and "Traceback" not in "".join(err), err
    assert files[-1] in lines[0] or any(f in lines[0] for f in files), lines
    assert "nothing was replaced" in lines[0] or "cannot write" in lines[0], lines
    assert _snapshot(tmp_path) == before


def test_a_symlink_at_out_is_written_through_and_stays_a_link(tmp_path):
    real = tmp_path / "real.yaml"
    real.write_text("old")
    link = tmp_path / "link.yaml"
    link.symlink_to(real)
    code, out, err, _ = _vlpcal("export", "-d", DEPLOYMENT, "--to", "opencv", "-o", link)
    assert code == 0, err
    assert link.is_symlink() and real.read_text().startswith("%YAML")


@pytest.mark.parametrize("command", ["export", "locate", "survey plan"])
def test_a_fifo_at_out_is_refused_without_waiting(tmp_path, command):
    args, files = _outputs(tmp_path, command)
    os.mkfifo(tmp_path / files[0])
    code, out, err, _ = _vlpcal(*args, timeout=30)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "special file" in lines[0], lines
    assert (tmp_path / files[0]).is_fifo()


#: a pid no process can have (beyond Linux's largest pid_max)
DEAD = 4_194_305


def test_what_a_killed_run_left_is_reclaimed_by_the_next(tmp_path):
    """Staged files of a dead writer go; a staged folder too; another live writer's stay."""
    stale = tmp_path / f".c.yaml.{DEAD}.1.vlpcal-tmp"
    stale.write_text("half a file")
    stale_dir = tmp_path / f".frames.{DEAD}.2.vlpcal-tmp"
    (stale_dir / "f1").mkdir(parents=True)
    alive = tmp_path / f".c.yaml.{os.getpid()}.3.vlpcal-tmp"  # this pytest is alive
    alive.write_text("being written")
    code, _, err, _ = _vlpcal("export", "-d", DEPLOYMENT, "--to", "opencv", "-o",
                              tmp_path / "c.yaml")
    assert code == 0, err
    assert not stale.exists() and not stale_dir.exists() and alive.exists()


@pytest.mark.parametrize("when", ["while staging", "while renaming"])
def test_a_set_killed_midway_ends_old_or_new_never_mixed(tmp_path, when):
    """SIGKILL (nothing Python can catch) in the middle of writing a two-file set: after the
    next writer in the folder, both files are the old ones or both the new ones."""
    a, b = tmp_path / "a.png", tmp_path / "a.yaml"
    a.write_text("old a")
    b.write_text("old b")
    kill = {"while staging": "tmp_b.write_text('half')",
            "while renaming": "real = os.replace\n"
                              "def replace(s, t):\n"
                              "    real(s, t)\n"
                              "    os.kill(os.getpid(), signal.SIGKILL)\n"
                              "os.replace = replace\n"}[when]
    code = ("import os, signal\nfrom vlpcal.writing import OutputSet\n"
            f"s = OutputSet({str(a)!r}, {str(b)!r})\n"
            "tmp_a, tmp_b = s.stage()\ntmp_a.write_text('new a')\n"
            + ("tmp_b.write_text('half')\nos.kill(os.getpid(), signal.SIGKILL)\n"
               if when == "while staging" else "tmp_b.write_text('new b')\n" + kill
               + "s.commit()\n"))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60)
    assert r.returncode == -9, r.stderr
    if when == "while renaming":
        assert (a.read_text(), b.read_text()) == ("new a", "old b")  # mixed, for now
    res, _, err, _ = _vlpcal("export", "-d", DEPLOYMENT, "--to", "opencv", "-o",
                             tmp_path / "other.yaml")
    assert res == 0, err
    pair = (a.read_text(), b.read_text())
    assert pair == {"while staging": ("old a", "old b"),
                    "while renaming": ("new a", "new b")}[when]
    assert not [p for p in tmp_path.iterdir() if ".vlpcal-" in p.name]


def test_sigterm_removes_the_staged_output(tmp_path):
    """A service manager's SIGTERM to the demo (which stages its whole folder from the start):
    a short message, no traceback, no staged folder left, no output."""
    import signal
    import time

    out = tmp_path / "demo"
    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "demo", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path)
    deadline = time.monotonic() + 60
    while not [p for p in tmp_path.iterdir() if ".vlpcal-" in p.name]:
        assert time.monotonic() < deadline and proc.poll() is None, "the demo never started"
        time.sleep(0.05)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0 and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_two_files_of_one_set_may_not_be_one_file(tmp_path):
    from vlpcal.writing import OutputError, OutputSet

    with pytest.raises(OutputError, match="two of its files"):
        OutputSet(tmp_path / "x.png", tmp_path / "x.png")


# -- ids that are safe everywhere they go ------------------------------------------------------

BAD_IDS = ["=HYPERLINK(\"http://x\")", "+1+1", "-C1", "@SUM(A1)", "C 1", "C1:ok", "C1+C2",
           "a\nb", ".hidden", "x" * 65, "C/1", "Ç1"]


@pytest.mark.parametrize("bad", BAD_IDS, ids=range(len(BAD_IDS)))
def test_a_bad_camera_id_in_a_deployment_is_one_line(tmp_path, bad):
    import yaml

    doc = yaml.safe_load(DEPLOYMENT.read_text())
    doc["cameras"][0]["id"] = bad
    path = tmp_path / "d.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, out, err, _ = _vlpcal("locate", "-d", path, "--observations",
                                SURVEY / "spots.csv")
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "cameras[0].id" in lines[0], lines
    assert "expected a camera id (letters, digits" in lines[0]


@pytest.mark.parametrize("where", ["points.csv point_id", "observations frame_id",
                                   "observations camera_id", "frames folder",
                                   "frame file", "toml name"])
def test_a_bad_id_in_any_file_is_one_line_naming_it(tmp_path, where):
    bad = "=cmd|' /C calc'!A0"
    if where == "points.csv point_id":
        bundle = tmp_path / "survey"
        bundle.mkdir()
        (bundle / "points.csv").write_text(f"point_id,x,y,z\n{bad},1,1,0\n")
        args = ["survey", "calibrate", "-d", DEPLOYMENT, "--survey", bundle, "--out",
                tmp_path / "cal.yaml"]
    elif where.startswith("observations"):
        obs = tmp_path / "obs.csv"
        row = f"{bad},C1,80,60" if "frame" in where else f"f1,{bad},80,60"
        obs.write_text(f"frame_id,camera_id,u,v\n{row}\n")
        args = ["locate", "-d", DEPLOYMENT, "--observations", obs, "--out",
                tmp_path / "f.csv"]
    elif where.startswith("frame"):
        frames = tmp_path / "frames"
        if where == "frames folder":  # a folder name that is not even UTF-8
            (frames / os.fsdecode(b"f\xff1")).mkdir(parents=True)
            (frames / os.fsdecode(b"f\xff1") / "C1.jpg").write_bytes(b"\xff\xd8\xff\xd9")
        else:
            (frames / "f1").mkdir(parents=True)
            (frames / "f1" / "C1 copy.jpg").write_bytes(b"\xff\xd8\xff\xd9")
        args = ["locate", "-d", DEPLOYMENT, "--frames", frames, "--out", tmp_path / "f.csv"]
    else:
        toml = tmp_path / "cams.toml"
        assert _vlpcal("export", "-d", DEPLOYMENT, "--to", "anipose", "-o", toml)[0] == 0
        toml.write_text(toml.read_text().replace('name = "C1"', 'name = "C\\n1"'))
        args = ["import", "--cameras", toml, "-b", SITE, "-o", tmp_path / "i.yaml"]
    code, out, err, _ = _vlpcal(*args)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in lines[0], lines
    assert "expected" in lines[0] and "id (letters, digits" in lines[0], lines
    assert not [p for p in tmp_path.iterdir() if p.suffix in (".csv", ".yaml")
                and p.name not in ("obs.csv",)], "an output was written"


def test_cells_a_spreadsheet_would_run_are_neutralised():
    from vlpcal.writing import spreadsheet_safe

    assert spreadsheet_safe("=1+1") == "'=1+1" and spreadsheet_safe("@A1") == "'@A1"
    assert spreadsheet_safe("-0.25") == "-0.25" and spreadsheet_safe(-0.25) == -0.25
    assert spreadsheet_safe("C1+C2") == "C1+C2" and spreadsheet_safe("") == ""


def test_a_million_row_points_file_is_read_in_linear_time(tmp_path):
    """A duplicate at the end of 10⁶ rows: one line within the timeout (the old check
    compared each id with every one before it: hours); since issue 31 the rows are counted
    before any is parsed, so the file is refused for its size first."""
    bundle = tmp_path / "survey"
    bundle.mkdir()
    rows = "".join(f"P{i},1,1,0\n" for i in range(10 ** 6))
    (bundle / "points.csv").write_text("point_id,x,y,z\n" + rows + "P7,1,1,0\n")
    code, out, err, rss = _vlpcal("survey", "calibrate", "-d", DEPLOYMENT, "--survey", bundle,
                                  "--out", tmp_path / "cal.yaml", timeout=120)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "10000" in lines[0].replace(",", "").replace(
        " ", "") and "points" in lines[0], lines
    # below the cap the duplicate is still found
    rows = "".join(f"P{i},1,1,0\n" for i in range(9_000))
    (bundle / "points.csv").write_text("point_id,x,y,z\n" + rows + "P7,1,1,0\n")
    code, out, err, rss = _vlpcal("survey", "calibrate", "-d", DEPLOYMENT, "--survey", bundle,
                                  "--out", tmp_path / "cal.yaml", timeout=120)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "duplicate point_id 'P7'" in lines[0], lines


# -- numbers checked for what they are ---------------------------------------------------------

NUMBERS = {  # key path in the deployment → (value, what the message must say)
    "fx huge": (("cameras", 0, "fx"), 1e308, "0.01× to 1000× the image width"),
    "fx tiny": (("cameras", 0, "fx"), 1e-3, "0.01× to 1000× the image width"),
    "cx far off": (("cameras", 0, "cx"), 1e9, "principal point within one image"),
    "position 1e308": (("cameras", 0, "position"), [1e308, 0, 2], "-100000 to 100000 m"),
    "camera 50 km away": (("cameras", 0, "position"), [50_000, 0, 2], "ten times the room"),
    "rotation 100 rad": (("cameras", 0, "rotation"), [100, 0, 0], "up to 4π long"),
    "distortion 1e5": (("cameras", 0, "dist"), [1e5, 0, 0, 0, 0], "-1000 to 1000"),
    "ceiling 1e200": (("site", "ceiling_height"), 1e200, "0 to 100000 m"),
    "width 1e9": (("cameras", 0, "width"), 10 ** 9, "up to 65535"),
    "room 1e200": (("site", "room"), [[0, 0], [1e200, 0], [1e200, 1], [0, 1]],
                   "-100000 to 100000 m"),
}


@pytest.mark.parametrize("case", list(NUMBERS))
def test_a_number_out_of_its_range_is_one_line_with_the_range(tmp_path, case):
    import yaml

    keys, value, fragment = NUMBERS[case]
    doc = yaml.safe_load(DEPLOYMENT.read_text())
    node = doc
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    path = tmp_path / "d.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, out, err, rss = _vlpcal("check", "--site", SITE, "-d", path)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and fragment in lines[0], lines
    assert str(path) in lines[0] and "Warning" not in lines[0]
    assert rss is not None and rss < 500


@pytest.mark.parametrize("key,value,fragment", [
    ("max_error_p95", 1e9, "the room's size"),
    ("pixel_noise", 1e308, "spot noise in px"),
    ("coverage", 7, "share from 0 to 1"),
])
def test_a_site_number_out_of_range_is_one_line(tmp_path, key, value, fragment):
    import yaml

    doc = yaml.safe_load(SITE.read_text())
    doc["requirements"][key] = value
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, out, err, _ = _vlpcal("plan", "--site", path, "--out", tmp_path / "p.yaml")
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and fragment in lines[0], lines


# -- careless use caught -------------------------------------------------------------------------

def _jpeg(width=160, height=120) -> bytes:
    import cv2
    import numpy as np

    img = np.zeros((height, width), np.uint8)
    img[height // 2 - 3:height // 2 + 3, width // 2 - 3:width // 2 + 3] = 255
    return cv2.imencode(".jpg", img)[1].tobytes()


@pytest.mark.parametrize("mistake", ["other camera ids", "other image size",
                                     "spots of one camera"])
def test_locate_refuses_frames_that_are_not_for_this_deployment(tmp_path, mistake):
    frames = tmp_path / "frames"
    for f in ("f1", "f2"):
        (frames / f).mkdir(parents=True)
        for cid in ("C1", "C2", "C3"):
            name = f"cam{cid[1]}" if mistake == "other camera ids" else cid
            size = (320, 240) if mistake == "other image size" else (160, 120)
            (frames / f / f"{name}.jpg").write_bytes(_jpeg(*size))
    if mistake == "spots of one camera":
        obs = tmp_path / "obs.csv"
        obs.write_text("frame_id,camera_id,u,v\nf1,C1,80,60\nf2,C1,81,60\n")
        args = ["--observations", obs]
    else:
        args = ["--frames", frames]
    code, out, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, *args, "--out", tmp_path / "f.csv")
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert "is this the right deployment" in lines[0], lines
    expected = {"other camera ids": "other ids there: cam1, cam2, cam3",
                "other image size": "C1 320×240 (the deployment says 160×120)",
                "spots of one camera": "spots of only 1 of"}[mistake]
    assert expected in lines[0], lines
    assert not (tmp_path / "f.csv").exists()


def test_a_fifo_or_a_device_among_the_frames_is_a_corrupt_frame(tmp_path):
    """C1.jpg a FIFO (opening it would wait for a writer forever), C2.jpg a link to
    /dev/zero (reading it never ends): each frame set keeps its row, with a status."""
    frames = tmp_path / "frames"
    (frames / "f1").mkdir(parents=True)
    (frames / "f2").mkdir(parents=True)
    for f in ("f1", "f2"):
        (frames / f / "C3.jpg").write_bytes(_jpeg())
    os.mkfifo(frames / "f1" / "C1.jpg")
    (frames / "f1" / "C2.jpg").symlink_to("/dev/zero")
    for cid in ("C1", "C2"):
        (frames / "f2" / f"{cid}.jpg").write_bytes(_jpeg())
    out = tmp_path / "f.csv"
    code, _, err, rss = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", frames, "--out", out,
                                timeout=60)
    assert code == 0, err
    rows = out.read_text().splitlines()
    assert rows[1].startswith("f1,") and "C1:corrupt_frame C2:corrupt_frame" in rows[1], rows
    assert rss is not None and rss < 500


def test_a_folder_that_cannot_be_listed_is_named_and_hidden_files_are_not_frames(tmp_path):
    """A link that loops among the frame folders is one line naming it (not the output);
    a Mac's ._C1.jpg beside C1.jpg is no camera; in an asynchronous folder, a camera folder
    that cannot be entered makes its frames corrupt, not a traceback."""
    frames = tmp_path / "frames"
    (frames / "f1").mkdir(parents=True)
    for cid in ("C1", "C2"):
        (frames / "f1" / f"{cid}.jpg").write_bytes(_jpeg())
    (frames / "f1" / "._C1.jpg").write_bytes(b"\0" * 4096)
    out = tmp_path / "f.csv"
    code, _, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", frames, "--out", out)
    assert code == 0 and "._C1" not in out.read_text(), err
    (frames / "loop").symlink_to("loop")
    out.unlink()
    code, _, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", frames, "--out", out)
    assert code == 2 and len(err) == 1, err
    assert "loop: cannot be read" in err[0] and "f.csv" not in err[0] and not out.exists()
    # a link that leads to itself, given as the frames or as the output: one line, nothing made
    (tmp_path / "self").symlink_to("self")
    for args in (("--frames", tmp_path / "self", "--out", out),
                 ("--frames", frames / "f1", "--out", tmp_path / "self")):
        code, _, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, *args)
        assert code == 2 and len(err) == 1 and "self" in err[0], err
        assert not out.exists()
    from vlpcal.datasets import AsyncFrames

    (tmp_path / "async").mkdir()
    (tmp_path / "async" / "C2").symlink_to("C2")
    folder = AsyncFrames(tmp_path / "async", [(0.0, "C2", "1")], ["C2"])
    assert folder.frame("C2", "1") == b"" and folder.frame("C9", "1") is None


# -- live sources that trickle, stall or never end -------------------------------------------------

@pytest.fixture
def hostile_camera():
    """An HTTP server whose paths misbehave: /trickle sends an MJPEG part a byte every 0.1 s;
    /endless answers image/jpeg without a length and sends zeros for ever."""
    import threading
    import time
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *a):
            pass

        def do_GET(self):
            self.send_response(200)
            kind = self.path.strip("/")
            ctype = "image/jpeg" if kind == "endless" else \
                "multipart/x-mixed-replace;boundary=frame"
            self.send_header("Content-Type", ctype)
            self.end_headers()
            try:
                if kind == "endless":
                    while True:
                        self.wfile.write(b"\0" * 65536)
                head = b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: 5000\r\n\r\n"
                self.wfile.write(head)
                for _ in range(10 ** 6):
                    self.wfile.write(b"\xff")
                    self.wfile.flush()
                    time.sleep(0.1)
            except OSError:
                pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.mark.parametrize("kind,why", [("trickle", "no whole frame in 5 s"),
                                      ("endless", "more than 4 MB without a whole frame")])
def test_locate_live_from_a_trickling_or_endless_camera_ends(tmp_path, hostile_camera, kind,
                                                             why):
    """No --duration: the camera is a stopped camera after the read timeout, and with no
    camera left, locate ends (one line, exit 1, nothing written), memory bounded."""
    out = tmp_path / "live.csv"
    code, _, err, rss = _vlpcal("locate", "-d", DEPLOYMENT, "--camera",
                                f"C1={hostile_camera}/{kind}", "--out", out, timeout=60)
    lines = [line for line in err if line.startswith("Error")]
    assert code == 1 and len(lines) == 1 and why in lines[0], err
    assert not out.exists() and rss is not None and rss < 500, rss


@pytest.mark.parametrize("kind", ["wrong_size", "corrupt_frame"])
def test_live_track_whose_every_frame_is_unusable_names_the_frames(tmp_path, kind):
    """Live track of cameras sending only frames of another size (or cut short) said "no
    frame had a spot" where --frames names the frames (issue 31): the same reason, exit 2,
    no file; the summary counts them too."""
    import cv2
    import numpy as np
    from test_live import Streams

    from vlpcal import deployment
    from vlpcal.sim.profiles import get_profile
    from vlpcal.sim.scene import make_scene
    from vlpcal.sim.writers import deployment_of

    dep = tmp_path / "truth.yaml"
    deployment.save(deployment_of(make_scene(get_profile("paper-2024"), seed=5), "true"), dep)
    h, w = (240, 320) if kind == "wrong_size" else (120, 160)
    img = np.zeros((h, w), np.uint8)
    img[h // 2 - 5:h // 2 + 5, w // 2 - 5:w // 2 + 5] = 255
    jpg = cv2.imencode(".jpg", img)[1].tobytes()
    jpg = jpg if kind == "wrong_size" else jpg[:len(jpg) // 2]
    streams = Streams({c: [jpg] * 10 for c in ("C1", "C2", "C3")})
    try:
        args = ["track", "-d", dep, "--out", tmp_path / "tracks.csv"]
        for cid in ("C1", "C2", "C3"):
            args += ["--camera", f"{cid}={streams.url(cid)}"]
        code, out, err, _ = _vlpcal(*args, timeout=60)
    finally:
        streams.close()
    import re

    # every frame the run took (a frame later than the hold allows is dropped, counted apart)
    said = {"wrong_size": r"\d+ frames of another size than their camera's",
            "corrupt_frame": r"\d+ frames not whole JPEGs"}[kind]
    assert code == 2 and re.match("Error: the cameras: no rows: " + said, err[-1]), err
    assert "had a spot" not in err[-1] and "Traceback" not in "".join(err)
    assert any(re.search(said + r" \(not used\)", line) for line in err[:-1]), err
    assert not (tmp_path / "tracks.csv").exists()


def test_survey_capture_refuses_a_trickling_camera_before_the_walk(tmp_path, hostile_camera):
    points = ROOT / "surveys" / "paper-2024" / "survey" / "points.csv"
    code, out, err, _ = _vlpcal("survey", "capture", "-d", DEPLOYMENT, "--points", points,
                                "--survey", tmp_path / "s", "--yes", "--camera",
                                f"C1={hostile_camera}/trickle", timeout=60)
    lines = [line for line in err if line.startswith("Error")]
    assert code == 1 and len(lines) == 1 and "no whole frame in 5 s" in lines[0], err
    assert not (tmp_path / "s").exists()


def test_locate_to_stdout_without_q_keeps_stdout_for_the_fixes(tmp_path):
    """The progress bar goes to stderr: piped without -q, stdout is the CSV alone."""
    frames = tmp_path / "frames"
    (frames / "f1").mkdir(parents=True)
    for cid in ("C1", "C2", "C3"):
        (frames / "f1" / f"{cid}.jpg").write_bytes(_jpeg())
    code, out, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", frames)
    assert code == 0, err
    assert out.splitlines()[0].startswith("frame_id,x,y,z,status"), out[:200]


def test_show_takes_the_deployment_as_argument_or_option():
    for args in (["show", DEPLOYMENT], ["show", "-d", DEPLOYMENT]):
        code, out, err, _ = _vlpcal(*args)
        assert code == 0 and "cameras" in out.splitlines()[0], (out, err)
        assert " 360" not in out
    code, out, err, _ = _vlpcal("show")
    assert code == 2 and len([e for e in err if e.strip()]) == 1


def test_a_planted_journal_cannot_move_or_delete_anything_outside_vlpcals_names(tmp_path):
    """A hidden '.x.<dead pid>.1.vlpcal-commit' naming files elsewhere: ignored (and said so),
    never followed."""
    import json

    victim = tmp_path / "elsewhere"
    (victim / "keep").mkdir(parents=True)
    (victim / "keep" / "f").write_text("x")
    secret = tmp_path / "secret"
    secret.write_text("secret")
    out = tmp_path / "out"
    out.mkdir()
    json.dump([[str(secret), str(out / "moved"), str(victim)]],
              open(out / f".a.{DEAD}.1.vlpcal-commit", "w"))
    code, _, err, _ = _vlpcal("export", "-d", DEPLOYMENT, "--to", "opencv", "-o",
                              out / "c.yaml")
    assert code == 0, err
    assert secret.read_text() == "secret" and (victim / "keep" / "f").exists()
    assert not (out / "moved").exists() and "not a journal vlpcal wrote" in " ".join(err)


# -- the breaker's findings (a hostile-input probe of 190 inputs) ---------------------------------

@pytest.mark.parametrize("args,fragment", [
    (["survey", "plan", "-d", DEPLOYMENT, "--out", "{tmp}/s.csv", "--step", "nan"],
     "finite number"),
    (["survey", "plan", "-d", DEPLOYMENT, "--out", "{tmp}/s.csv", "--heights",
      ",".join(str(i / 200) for i in range(300))], "at most 12 numbers"),
    (["simulate", "--out", "{tmp}/sim", "--survey-step", "nan"], "finite number"),
    (["locate", "-d", DEPLOYMENT, "--camera", "C1=http://127.0.0.1:9/x", "--duration", "nan",
      "--out", "{tmp}/f.csv"], "finite number"),
    (["locate", "-d", DEPLOYMENT, "--camera", "C1=http://127.0.0.1:9/x", "--tolerance", "inf",
      "--out", "{tmp}/f.csv"], "inf is not in the range"),
    (["locate", "-d", DEPLOYMENT, "--camera", "C1=ftp://127.0.0.1/x", "--out", "{tmp}/f.csv"],
     "expected an http(s):// MJPEG URL or a video device"),
    # a URL that cannot be one is the user's to mend (exit 2), not a camera that did not
    # answer (exit 1); a password cut at its "#" is not quoted back
    (["track", "-d", DEPLOYMENT, "--camera", "C1=http://[::1/x", "--out", "{tmp}/t.csv"],
     "expected an http(s):// MJPEG URL: host, port"),
    (["locate", "-d", DEPLOYMENT, "--camera", "C1=http://robot:s3cr#t@[::1/x", "--out",
      "{tmp}/f.csv"], "expected an http(s):// MJPEG URL: host, port"),
    (["plan", "--site", SITE, "--out", "{tmp}/p.yaml", "--max-cameras", "100000"],
     "100000 is not in the range"),
])
def test_options_that_are_not_numbers_or_sources_are_one_line(tmp_path, args, fragment):
    args = [str(a).format(tmp=tmp_path) for a in args]
    code, out, err, rss = _vlpcal(*args, timeout=60)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and fragment in lines[0], lines
    assert "s3cr" not in lines[0]
    assert rss is not None and rss < 500


def test_a_number_of_5000_digits_and_yaml_12_floats(tmp_path):
    doc = DEPLOYMENT.read_text()
    huge = tmp_path / "huge.yaml"
    huge.write_text(doc.replace("fx: ", "fx: " + "9" * 5000 + " #", 1)
                    if "fx: " in doc else doc.replace("fx", "fx", 1))
    import yaml

    d = yaml.safe_load(doc)
    d["cameras"][0]["fx"] = "HUGE"
    text = yaml.safe_dump(d).replace("HUGE", "9" * 5000)
    huge.write_text(text)
    code, out, err, _ = _vlpcal("show", huge)
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "a number of 5000 digits" in lines[0], lines
    d["cameras"][0]["fx"] = "FX"
    ok = tmp_path / "e.yaml"
    ok.write_text(yaml.safe_dump(d).replace("FX", "1.533e2").replace("1.533e2", "1533e-1"))
    code, out, err, _ = _vlpcal("show", ok)
    assert code == 0 and "153.3" in out, (out, err)


def test_a_server_reply_with_escapes_and_line_breaks_is_one_printable_line(tmp_path):
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)

    def answer():
        for _ in range(4):
            try:
                c, _ = srv.accept()
            except OSError:
                return
            c.recv(4096)
            c.sendall(b"HTTP/1.0 500 \x1b]0;pwned\x07RED\r\nline2\r\n\r\n")
            c.close()

    threading.Thread(target=answer, daemon=True).start()
    port = srv.getsockname()[1]
    code, out, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--camera",
                                f"C1=http://127.0.0.1:{port}/", "--out", tmp_path / "f.csv")
    srv.close()
    text = "\n".join(err)
    assert "\x1b" not in text and "\x07" not in text, text
    errors = [line for line in err if line.startswith("Error")]
    assert code == 1 and len(errors) == 1, err


def test_two_cameras_seeing_one_pixel_is_degenerate_not_a_far_fix(tmp_path):
    """Rays that meet only hundreds of metres away: no fix (degenerate), not 'ok'."""
    frames = tmp_path / "same" / "x"
    frames.mkdir(parents=True)
    spot = _jpeg()
    for cid in ("C2", "C3"):
        (frames / f"{cid}.jpg").write_bytes(spot)
    code, out, err, _ = _vlpcal("locate", "-d", DEPLOYMENT, "--frames", tmp_path / "same",
                                "--out", "-")
    assert code == 0, err
    row = out.splitlines()[1].split(",")
    assert row[4] in ("degenerate", "outside_room") and row[1] == "", row


def test_simulate_and_demo_refuse_a_folder_holding_files_they_did_not_write(tmp_path):
    out = tmp_path / "sim"
    assert _vlpcal("simulate", "--out", out, "--test-points", "3", timeout=120)[0] == 0
    (out / "my-notes.txt").write_text("mine")
    before = _snapshot(out)
    code, o, err, _ = _vlpcal("simulate", "--out", out, "--test-points", "3", "--overwrite",
                              timeout=120)
    lines = [line for line in o.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "my-notes.txt" in lines[0], lines
    assert _snapshot(out) == before


def test_simulate_killed_leaves_no_partial_folder(tmp_path):
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "simulate", "--out",
                             str(tmp_path / "simk"), "--test-points", "200", "--trajectory",
                             "2000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not [p for p in tmp_path.iterdir() if ".vlpcal-" in p.name]:
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0 and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_capture_refuses_a_point_outside_the_room(tmp_path):
    points = tmp_path / "p.csv"
    points.write_text("point_id,x,y,z\nS1,1,1,0\nS2,1e308,0,0\n")
    code, out, err, _ = _vlpcal("survey", "capture", "-d", DEPLOYMENT, "--points", points,
                                "--survey", tmp_path / "s", "--yes", "--camera",
                                "C1=http://127.0.0.1:9/x")
    lines = [line for line in out.splitlines() + err if line.strip()]
    assert code == 2 and len(lines) == 1 and "point S2" in lines[0], lines


def test_a_600_byte_site_of_a_15_m_room_plans_in_bounded_memory(tmp_path):
    """The breaker's case: a 15 × 15 m room at --max-cameras 250 (a 225-camera plan) took
    746 MB while the lattice search judged 96 lattices at once at every sample point."""
    import yaml

    doc = yaml.safe_load(SITE.read_text())
    doc["site"]["room"] = [[0, 0], [15, 0], [15, 15], [0, 15]]
    doc["site"].pop("keep_out", None)
    site = tmp_path / "room15.yaml"
    site.write_text(yaml.safe_dump(doc))
    assert site.stat().st_size < 10_000
    code, out, err, rss = _vlpcal("plan", "-q", "--site", site, "--max-cameras", "250",
                                  "--out", tmp_path / "p.yaml", timeout=300)
    assert code == 0, err
    assert rss is not None and rss < 500, f"{rss:.0f} MB"


@pytest.mark.parametrize("plant", ["fifo", "zero", "deep", "folder", "huge pid", "odd digit"])
def test_planted_leftovers_are_ignored_without_a_hang_or_a_traceback(tmp_path, plant):
    """The re-check's findings: a journal that is a FIFO or a link to /dev/zero, nested JSON,
    a folder; names with a pid past any integer or a non-ASCII digit."""
    j = tmp_path / f".x.yaml.{DEAD}.1.vlpcal-commit"
    if plant == "fifo":
        os.mkfifo(j)
    elif plant == "zero":
        j.symlink_to("/dev/zero")
    elif plant == "deep":
        j.write_text("[" * 3000)
    elif plant == "folder":
        j.mkdir()
    elif plant == "huge pid":
        (tmp_path / ".x.99999999999999999999.1.vlpcal-tmp").write_text("x")
    else:
        (tmp_path / ".x.\u00b2.1.vlpcal-tmp").write_text("x")
    code, _, err, rss = _vlpcal("export", "-d", DEPLOYMENT, "--to", "opencv", "-o",
                                tmp_path / "x.yaml", timeout=30)
    assert code == 0 and "Traceback" not in " ".join(err), err
    assert rss is not None and rss < 500


def test_locate_interrupted_offline_keeps_the_previous_fixes(tmp_path):
    """From a hostile probe (issue 31): SIGTERM during an offline locate wrote the sets done
    so far over the previous fixes.csv and exited 0. It now keeps that file as it was and
    exits 1, as track, survey calibrate and plan do (a live run keeps its rows)."""
    import signal
    import time

    import numpy as np

    from vlpcal.deployment import load

    dep = load(DEPLOYMENT)
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(1.2, 2.4, 150_000), rng.uniform(0.5, 1.3, 150_000),
                         np.full(150_000, 0.1)])
    with open(tmp_path / "obs.csv", "w") as f:
        f.write("frame_id,camera_id,u,v\n")
        for c in dep.cameras:
            uv, _, ok = c.project(X)
            f.writelines(f"{i},{c.id},{uv[i, 0]:.3f},{uv[i, 1]:.3f}\n"
                         for i in np.flatnonzero(ok))
    (tmp_path / "fixes.csv").write_text("the previous fixes\n")
    proc = subprocess.Popen([sys.executable, "-m", "vlpcal", "locate", "-d", DEPLOYMENT,
                             "--observations", str(tmp_path / "obs.csv"), "--out",
                             str(tmp_path / "fixes.csv"), "-q"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not [p for p in tmp_path.iterdir() if ".vlpcal-" in p.name]:  # writing has begun
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.02)
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1 and "Traceback" not in err and "as it was" in err, err
    assert (tmp_path / "fixes.csv").read_text() == "the previous fixes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fixes.csv", "obs.csv"]


@pytest.mark.parametrize("provenance", [
    {"predicted": "good"}, {"predicted": {"p95_error_m": "good"}}, {"from": [1, 2]},
    {"lens": {"C1": ["k1"]}, "point_sigma_m": "1 mm"}, {"held_out_mean_m": {"x": "big"}},
    {"wand_error_m": {"mean": "x"}, "wand_m": 1},
    {"command": "\x1b]0;pwned\x07\x1b[2J", "from": {"site": "s\rforged line"}}])
def test_show_reads_any_provenance_and_prints_nothing_raw(provenance, tmp_path):
    """From a hostile probe (issue 31): seven wrongly typed provenance values were
    tracebacks in ``vlpcal show``; strings with terminal escapes reached the terminal raw (a
    new window title, a cleared screen, forged lines)."""
    import yaml

    doc = yaml.safe_load(DEPLOYMENT.read_text())
    doc["provenance"] = provenance
    doc["site"]["name"] = "lab\x1b[31m red"
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(doc))
    res = subprocess.run([sys.executable, "-m", "vlpcal", "show", str(tmp_path / "d.yaml")],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert not any(ch in res.stdout for ch in "\x1b\x07\r"), repr(res.stdout)
    assert "lab\\x1b[31m red" in res.stdout
