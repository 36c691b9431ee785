"""The live page's cost and delay (issue 30): `vlpcal track --camera …` on a simulated live
site (four MJPEG cameras on 127.0.0.1 at 30 fps, each on its own clock, a robot's LED at
1.5 m/s), with and without `--view` and a headless Chromium watching the page. Per run: the
tracker process's CPU time per camera frame (user + system, from the OS), and, with the
view, the page's delay from a frame's capture to its drawing on the page (p50, p95) and from
a row's time to its drawing. Runs alternate, without and with; medians over the repeats.

    python benchmarks/view.py [--repeats 3] [--seconds 8]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common  # noqa: F401  (one-core setup before numpy)
import numpy as np
from _common import table, write_json

from vlpcal.deployment import save
from vlpcal.sim.mjpeg import StreamServer
from vlpcal.sim.scene import make_scene
from vlpcal.sim.streams import robot_path, simulate_streams
from vlpcal.sim.writers import deployment_of

CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def one_run(root: Path, dep, seconds: float, view: bool, run: int) -> dict:
    """One live run of `vlpcal track` (a fresh stream server), its CPU per frame, and with
    ``view`` the page's delays as Chromium saw them."""
    server = StreamServer(root / "s", latency=0.001, latency_jitter=0.002, start=3.0)
    out = root / f"t{run}{'-view' if view else ''}.csv"
    cmd = [sys.executable, "-m", "vlpcal", "track", "-d", str(root / "d.yaml"), "--out",
           str(out), "--duration", str(seconds + 3.5)]
    cmd += [f"--camera={c.id}={server.url(c.id)}" for c in dep.cameras]
    if view:
        cmd += ["--view", "127.0.0.1:0"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    latency, updates, err = {}, 0, []
    cpu = CpuSampler(proc.pid)
    try:
        if view:
            from playwright.sync_api import sync_playwright

            line = proc.stderr.readline()
            err.append(line)
            m = re.search(r"view: (http://\S+)", line)
            if not m:
                raise SystemExit(f"track --view said no address: {line}{proc.stderr.read()}")
            url = m.group(1)
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(url)
                while not _ended(proc):
                    time.sleep(0.1)
                latency = page.evaluate("window.vlpcalView.latencies()")
                updates = page.evaluate("window.vlpcalView.updates")
                browser.close()
        while not _ended(proc):
            time.sleep(0.1)
        err += proc.stderr.readlines()
        # the tracker's own CPU (not the browser's, also this script's child): its rusage
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    finally:
        if proc.returncode is None:
            proc.kill()
        server.close()
    total = usage.ru_utime + usage.ru_stime
    text = "".join(err)
    m = re.search(r"(\d+) camera frames", text)
    if proc.returncode != 0 or not m:
        raise SystemExit(f"track failed ({proc.returncode}): {text}")
    frames = int(m.group(1))
    # while the cameras stream (their first second and last left out): the CPU a frame
    # costs once the command runs, its start-up (imports, the page's maps) apart
    busy = cpu.rate(server.t0 + 1.0, server.t0 + seconds - 1.0)
    row = {"view": view, "run": run, "frames": frames, "cpu_s": total,
           "cpu_us_per_frame": 1e6 * busy / (frames / seconds)}
    if view:
        row.update({k: (v * 1000 if v is not None else float("nan")) for k, v in
                    (("frame_p50_ms", latency.get("frame_p50")),
                     ("frame_p95_ms", latency.get("frame_p95")),
                     ("row_p50_ms", latency.get("row_p50")),
                     ("row_p95_ms", latency.get("row_p95")))})
        row["updates_per_s"] = updates / (seconds + 3.5)
    return row


class CpuSampler:
    """A process's CPU time (user + system, from /proc), sampled every 50 ms in a thread."""

    def __init__(self, pid: int):
        import threading

        self.samples: list = []  # (monotonic s, CPU s)
        self._path = Path(f"/proc/{pid}/stat")
        self._tick = os.sysconf("SC_CLK_TCK")
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        while True:
            try:
                fields = self._path.read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                return
            if fields[0] == "Z":  # ended
                return
            self.samples.append((time.monotonic(),
                                 (int(fields[11]) + int(fields[12])) / self._tick))
            time.sleep(0.05)

    def rate(self, t0: float, t1: float) -> float:
        """CPU seconds per second between monotonic times ``t0`` and ``t1``."""
        s = np.array(self.samples)
        a, b = np.interp([t0, t1], s[:, 0], s[:, 1])
        return float((b - a) / (t1 - t0))


def _ended(proc) -> bool:
    """Whether the process has ended, without reaping it (its rusage is read when it is)."""
    try:
        return os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
    except ChildProcessError:
        return True


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).parent))
    from tracking import paper_square

    scene = make_scene(paper_square(), args.seed)
    dep = deployment_of(scene, "true")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        save(dep, root / "d.yaml")
        simulate_streams(scene, root / "s", robot_path(scene, 1.5), args.seconds,
                         seed=args.seed)
        for k in range(args.repeats):
            for view in (False, True):
                rows.append(one_run(root, dep, args.seconds, view, k))
    print(f"`vlpcal track` live, paper-square (4 cameras at 30 fps, a robot at 1.5 m/s, "
          f"{args.seconds:g} s of stream), without and with --view and Chromium on the page; "
          f"{args.repeats} runs each, alternating")
    print(table(rows, [("view", "view", ""), ("run", "run", "d"), ("frames", "frames", "d"),
                       ("cpu_us_per_frame", "CPU µs/frame", ".0f"),
                       ("frame_p50_ms", "frame→page p50 ms", ".0f"),
                       ("frame_p95_ms", "frame→page p95 ms", ".0f"),
                       ("row_p50_ms", "row→page p50 ms", ".0f"),
                       ("row_p95_ms", "row→page p95 ms", ".0f"),
                       ("updates_per_s", "page updates/s", ".1f")]))
    base = float(np.median([r["cpu_us_per_frame"] for r in rows if not r["view"]]))
    seen = [r for r in rows if r["view"]]
    viewed = float(np.median([r["cpu_us_per_frame"] for r in seen]))
    summary = {"cpu_us_per_frame": base, "cpu_us_per_frame_view": viewed,
               "view_cost": viewed / base - 1,
               **{k: float(np.median([r[k] for r in seen])) for k in
                  ("frame_p50_ms", "frame_p95_ms", "row_p50_ms", "row_p95_ms",
                   "updates_per_s")}}
    ok = summary["view_cost"] <= 0.10
    print(f"median CPU per frame: {base:.0f} µs without, {viewed:.0f} µs with the view "
          f"({100 * summary['view_cost']:+.1f} %; target ≤ +10 %: {'met' if ok else 'NOT met'});"
          f" page delay from capture: frames p50 {summary['frame_p50_ms']:.0f} ms, p95 "
          f"{summary['frame_p95_ms']:.0f} ms; rows p50 {summary['row_p50_ms']:.0f} ms, p95 "
          f"{summary['row_p95_ms']:.0f} ms")
    write_json("view", {"runs": rows, "summary": summary, "target_met": ok})
    return 0


if __name__ == "__main__":
    sys.exit(main())
