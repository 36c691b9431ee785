"""Every output survives every interruption (issue 31): SIGTERM or Ctrl-C (SIGINT) on any
command that writes a file leaves the previous file (or folder) byte for byte as it was, leaves
no staged file beside it, and exits 1 — whether the signal lands while the command works or
just before it renames what it staged into place. A live run (``--camera``), where a stop is
the normal end, keeps its rows so far: complete lines, exit 0 (README: locate's live input).

Each command runs in a child process on inputs big enough that it is still working when the
signal is sent; "working" is measured, not slept for: the child announces on stderr when it
has checked its output (``vlpcal.writing.destination``), and the signal goes once it has spent
a further 0.3 s of CPU on the command. The second moment holds the child, once its outputs are
staged, just before the first rename (a timing hook around ``os.replace`` in
:mod:`vlpcal.writing`; everything else runs as it is)."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYOUTS = ROOT / "layouts"
SITE = LAYOUTS / "paper-linear.site.yaml"
DEPLOYMENT = LAYOUTS / "paper-linear.deployment.yaml"

#: run first in the child: says "@checked" the first time an output is checked, and with
#: VLPCAL_TEST_PAUSE=k holds the k-th set written in VLPCAL_TEST_WORK (its files staged and
#: complete) just before its first rename, saying "@renaming"
PRELUDE = r"""
import os, sys, time
from pathlib import Path
from vlpcal import writing

_destination = writing.destination
def _checked(*a, **k):
    if not _checked.said:
        _checked.said = True
        print("@checked", file=sys.stderr, flush=True)
    return _destination(*a, **k)
_checked.said = False
writing.destination = _checked

_work = os.environ.get("VLPCAL_TEST_WORK")
_pause = int(os.environ.get("VLPCAL_TEST_PAUSE") or 0)
_commit = writing.OutputSet.commit
_state = {"n": 0, "hold": False}
def _counted(self):
    if any(str(t.parent) == _work and writing.MARK not in t.name for t in self.targets):
        _state["n"] += 1
        _state["hold"] = _state["n"] == _pause
    return _commit(self)
writing.OutputSet.commit = _counted

class _Os:
    def __getattr__(self, name):
        return getattr(os, name)
    def replace(self, a, b):
        if _state["hold"]:
            _state["hold"] = False
            print("@renaming", file=sys.stderr, flush=True)
            time.sleep(60)
        return os.replace(a, b)
writing.os = _Os()

from vlpcal.cli import main
main(sys.argv[1:], prog_name="vlpcal")
"""


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A simulated install: truth.yaml, nominal.yaml, survey/, frames/ (300 sets), streams/
    (a robot for 20 s, cameras not synchronised); 60 000 frame sets of spots; an anipose
    TOML."""
    root = tmp_path_factory.mktemp("interrupts")
    res = subprocess.run([sys.executable, "-m", "vlpcal", "simulate", "--out", str(root / "sim"),
                          "--trajectory", "300", "--robot-speed", "0.5", "--seconds", "20"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    from vlpcal.deployment import load

    dep = load(root / "sim" / "truth.yaml")
    n = 60_000
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(1.2, 2.4, n), rng.uniform(0.5, 1.3, n), np.full(n, 0.1)])
    with open(root / "spots.csv", "w") as f:
        f.write("frame_id,camera_id,u,v\n")
        for c in dep.cameras:
            uv, _, ok = c.project(X)
            f.writelines(f"{i},{c.id},{uv[i, 0]:.3f},{uv[i, 1]:.3f}\n" for i in np.flatnonzero(ok))
    res = subprocess.run([sys.executable, "-m", "vlpcal", "export", "-d", DEPLOYMENT, "--to",
                          "anipose", "-o", str(root / "cams.toml")], capture_output=True,
                         text=True, timeout=60)  # cameras another tool calibrated, for import
    assert res.returncode == 0, res.stderr
    return root


def _previous(work: Path, names) -> None:
    """What an earlier run left: each output with content of its own."""
    for name in names:
        if name.endswith("/"):  # a folder an earlier simulate or demo wrote
            folder = work / name.rstrip("/")
            folder.mkdir()
            if name == "demo/":
                (folder / "summary.json").write_text('{"written_by": "vlpcal demo"}\n')
                (folder / "planned.yaml").write_text("the earlier demo's plan\n")
            else:
                (folder / "truth.yaml").write_text("the earlier simulation\n")
                (folder / "survey").mkdir()
                (folder / "survey" / "points.csv").write_text("point_id,x,y,z\n")
        else:
            (work / name).write_bytes(f"the previous {name}\n".encode() + bytes(range(256)))


def _snapshot(folder: Path) -> dict:
    """Every entry under ``folder`` (hidden ones too): its bytes, or that it is a folder."""
    return {str(p.relative_to(folder)): ("<folder>" if p.is_dir() else p.read_bytes())
            for p in sorted(folder.rglob("*"))}


def _cpu(pid: int) -> float:
    """The child's CPU time so far, s (user + system, all threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Child:
    """``vlpcal ARGS`` in a child process under :data:`PRELUDE`, its stderr in a file."""

    def __init__(self, args, cwd: Path, work: Path, pause: int = 0):
        self.err_path = cwd / "stderr.txt"
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "VLPCAL_TEST_WORK": str(work),
               "VLPCAL_TEST_PAUSE": str(pause)}
        with open(self.err_path, "w") as err:
            self.proc = subprocess.Popen([sys.executable, "-c", PRELUDE, *map(str, args)],
                                         stdout=subprocess.DEVNULL, stderr=err, cwd=cwd,
                                         env=env)

    def stderr(self) -> str:
        return self.err_path.read_text(errors="replace")

    def wait_for(self, marker: str, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while marker not in self.stderr():
            assert self.proc.poll() is None, f"ended ({self.proc.returncode}) before {marker}:" \
                f"\n{self.stderr()}"
            assert time.monotonic() < deadline, f"no {marker} in {timeout} s:\n{self.stderr()}"
            time.sleep(0.01)

    def working(self, cpu: float = 0.3, timeout: float = 60, marker: str = "@checked") -> None:
        """Returns once the command has spent ``cpu`` s of CPU after checking its output (or
        after saying ``marker``)."""
        self.wait_for(marker, timeout)
        start, deadline = _cpu(self.proc.pid), time.monotonic() + timeout
        while _cpu(self.proc.pid) - start < cpu:
            assert self.proc.poll() is None, f"ended ({self.proc.returncode}) before the " \
                f"signal: give it more to do\n{self.stderr()}"
            assert time.monotonic() < deadline
            time.sleep(0.01)

    def signal(self, signum) -> tuple:
        assert self.proc.poll() is None, "the command ended before the signal"
        self.proc.send_signal(signum)
        code = self.proc.wait(timeout=60)
        return code, self.stderr()


# command → (its arguments, given the sim folder S and the outputs' folder W; the outputs an
# earlier run left, "name/" for a folder)
COMMANDS = {
    "plan": (lambda s, w: ["plan", "--site", SITE, "--out", w / "p.yaml"], ["p.yaml", "p.png"]),
    "check --maps": (lambda s, w: ["check", "--site", SITE, "-d", DEPLOYMENT, "--maps",
                                   w / "maps.png"], ["maps.png"]),
    "survey plan": (lambda s, w: ["survey", "plan", "-d", s / "sim" / "nominal.yaml", "--out",
                                  w / "points.csv"], ["points.csv", "points.png"]),
    "survey calibrate": (lambda s, w: ["survey", "calibrate", "-d", s / "sim" / "nominal.yaml",
                                       "--survey", s / "sim" / "survey", "--out",
                                       w / "cal.yaml"],
                         ["cal.yaml", "cal.report.json", "cal.png"]),
    "locate --observations": (lambda s, w: ["locate", "-d", s / "sim" / "truth.yaml",
                                            "--observations", s / "spots.csv", "--out",
                                            w / "fixes.csv", "-q"], ["fixes.csv"]),
    "locate --frames --plot": (lambda s, w: ["locate", "-d", s / "sim" / "truth.yaml",
                                             "--frames", s / "sim" / "frames", "--out",
                                             w / "fixes.jsonl", "--plot", w / "fixes.png"],
                               ["fixes.jsonl", "fixes.png"]),
    "track --plot": (lambda s, w: ["track", "-d", s / "sim" / "truth.yaml", "--frames",
                                   s / "sim" / "streams", "--out", w / "tracks.csv", "--plot",
                                   w / "tracks.png"], ["tracks.csv", "tracks.png"]),
    "export": (lambda s, w: ["export", "-d", s / "sim" / "truth.yaml", "--to", "anipose", "-o",
                             w / "cams.toml"], ["cams.toml"]),
    "import": (lambda s, w: ["import", "--cameras", s / "cams.toml", "-b", DEPLOYMENT, "-o",
                             w / "imported.yaml"], ["imported.yaml"]),
    "simulate": (lambda s, w: ["simulate", "--out", w / "sim", "--overwrite"], ["sim/"]),
    "demo": (lambda s, w: ["demo", "--out", w / "demo"], ["demo/"]),
}
#: too quick to be caught working: caught only at the rename
QUICK = {"export", "import"}
#: too long to run to its rename here (31 s): its folder is renamed as simulate's is
LONG = {"demo"}


def _setup(tmp_path, sim, command):
    args, previous = COMMANDS[command]
    work = tmp_path / "out"
    work.mkdir()
    _previous(work, previous)
    return args(sim, work), work, _snapshot(work)


def _untouched(code, err, work, before):
    assert code == 1 and "Traceback" not in err, err
    assert _snapshot(work) == before, (sorted(_snapshot(work)), err)


@pytest.mark.parametrize("command,signum", [
    *((c, signal.SIGTERM) for c in sorted(set(COMMANDS) - QUICK)),
    # Ctrl-C on a few: Python raises the KeyboardInterrupt the CLI makes of SIGTERM
    *((c, signal.SIGINT) for c in ("plan", "survey calibrate", "locate --observations"))],
    ids=lambda v: v.name if isinstance(v, signal.Signals) else v)
def test_a_command_stopped_while_working_keeps_the_previous_output(tmp_path, sim, command,
                                                                   signum):
    argv, work, before = _setup(tmp_path, sim, command)
    child = Child(argv, tmp_path, work)
    child.working()
    code, err = child.signal(signum)
    _untouched(code, err, work, before)


@pytest.mark.parametrize("cpu", [0.0, 0.1, 0.2, 0.3])
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=lambda v: v.name)
def test_plan_stopped_while_the_optimiser_runs_keeps_the_previous_plan(tmp_path, sim, signum,
                                                                      cpu):
    """CasADi checks for Ctrl-C between IPOPT's iterations and swallows the KeyboardInterrupt
    the signal raises, ending that solve as one that failed: the plan went on, wrote over
    the previous one and exited 0 (now the stop is noted and raised between solves). The
    moment within the optimiser decides which way the signal lands: four are tried."""
    argv, work, before = _setup(tmp_path, sim, "plan")
    child = Child(argv, tmp_path, work)
    child.working(cpu, marker="tilted:")
    code, err = child.signal(signum)
    _untouched(code, err, work, before)


@pytest.mark.parametrize("command", sorted(set(COMMANDS) - LONG))
def test_a_command_stopped_before_its_rename_keeps_the_previous_output(tmp_path, sim, command):
    """Its new files complete and staged, the signal lands just before the first rename of
    the first set it writes, which holds every one of its outputs (a --plot run drew its
    figure after renaming its rows: a stop while drawing left new rows, an old figure)."""
    argv, work, before = _setup(tmp_path, sim, command)
    child = Child(argv, tmp_path, work, pause=1)
    child.wait_for("@renaming")
    staged = [p.name for p in work.iterdir() if ".vlpcal-tmp" in p.name]
    for name in COMMANDS[command][1]:
        assert [s for s in staged if s.startswith(f".{name.rstrip('/')}.")], (name, staged)
    code, err = child.signal(signal.SIGTERM)
    _untouched(code, err, work, before)


# -- live runs: a stop is their normal end --------------------------------------------------


@pytest.mark.parametrize("command,signum", [("locate", signal.SIGTERM),
                                            ("track", signal.SIGTERM), ("track", signal.SIGINT)],
                         ids=lambda v: v.name if isinstance(v, signal.Signals) else v)
def test_a_live_run_stopped_keeps_its_whole_rows_so_far(tmp_path, sim, command, signum):
    """``--camera``: the rows go to a new file as they are made (a live run replaces nothing:
    an existing file is refused, as it was); a stop keeps those rows, whole lines, exit 0."""
    from vlpcal.sim.mjpeg import StreamServer

    server = StreamServer(sim / "sim" / "streams")
    try:
        out = tmp_path / "out" / "rows.csv"
        out.parent.mkdir()
        argv = [command, "-d", sim / "sim" / "truth.yaml", "--out", out]
        for cid in ("C1", "C2", "C3"):
            argv += ["--camera", f"{cid}={server.url(cid)}"]
        out.write_text("the previous rows\n")
        res = subprocess.run([sys.executable, "-m", "vlpcal", *map(str, argv)],
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2 and "exists" in res.stderr, res.stderr
        assert out.read_text() == "the previous rows\n"
        out.unlink()
        child = Child(argv, tmp_path, out.parent)
        deadline = time.monotonic() + 60
        while not (out.exists() and len(out.read_text().splitlines()) > 20):
            assert child.proc.poll() is None and time.monotonic() < deadline, child.stderr()
            time.sleep(0.05)
        code, err = child.signal(signum)
    finally:
        server.close()
    assert code == 0 and "Traceback" not in err, err
    assert ("interrupted: the fixes so far are kept" if command == "locate" else
            "stopped (Ctrl-C or a signal): writing what was tracked") in err, err
    text = out.read_text()
    assert text.endswith("\n")
    rows = list(csv.reader(text.splitlines()))
    assert len(rows) > 20 and len({len(r) for r in rows}) == 1, rows[:3]
    assert sorted(p.name for p in out.parent.iterdir()) == ["rows.csv"]


def test_a_command_under_nohup_goes_on_when_the_terminal_closes(tmp_path, sim):
    """``nohup vlpcal plan …`` ignores SIGHUP (a closed terminal); the command's own stop on
    SIGHUP overrode that, so closing the terminal stopped the run nohup was asked to keep."""
    argv, work, before = _setup(tmp_path, sim, "plan")
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sys.executable, "-c", PRELUDE, *map(str, argv)],
                                stdout=subprocess.DEVNULL, stderr=err, cwd=tmp_path,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"},
                                preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
    deadline = time.monotonic() + 60
    while "@checked" not in err_path.read_text():
        assert proc.poll() is None and time.monotonic() < deadline, err_path.read_text()
        time.sleep(0.01)
    proc.send_signal(signal.SIGHUP)
    assert proc.wait(timeout=300) == 0, err_path.read_text()
    assert _snapshot(work) != before  # the plan was written
