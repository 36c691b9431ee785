"""A warehouse on MQTT: 1 000 cameras' spots through one Mosquitto into N zone locators cut by
``vlpcal zones``, on this one machine, at rising frame rates until messages are lost.

The site: ``--cameras`` of the paper's cameras (160 × 120) 4 m up in a grid 2.0 × 1.5 m apart
(every floor point seen by two or more), cut into N zones (``vlpcal.planning.zones``); one
robot's LED per zone drives a loop in the middle of its zone (away from the borders, so each
zone's cameras see one LED). Every camera captures at ``fps`` from its own random phase and
publishes every frame on ``site/spots/<camera_id>`` — its spot (true projection + 0.05 px of
noise) where it sees the LED, else ``{"t": …}`` — played on schedule by one Python process;
``vlpcal locate --spots … --zone Z --publish …`` per zone; a subscriber in its own process
records when each fix arrives. Per run: spot messages the locators got against those sent to
their cameras' topics (a border camera's go to two zones), fixes published against received,
fixes/s, latency from a fix's capture time to its arrival at the subscriber (p50, p99, after
the first second), whether the cameras' player kept its schedule, and CPU (% of one core) of
each locator (its own rusage), the broker and the player. The rate rises while nothing is
lost; the table shows every rate tried, the summary the highest held.

This machine has 2 cores for the player, the broker, the subscriber and every locator: the
figures are what one small machine holds, and per locator what one core would carry.

Prints a table; writes benchmarks/out/site.json.

    python benchmarks/site.py [--cameras 1000] [--processes 2 4] [--fps 1 2 5 10 30]
                              [--seconds 10]
"""

from __future__ import annotations

import argparse
import json
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

from vlpcal.deployment import Deployment, save
from vlpcal.geometry import paper_camera
from vlpcal.planning.zones import cut_zones
from vlpcal.sim.broker import Broker
from vlpcal.sim.streams import Timing, capture_times

from mqtt import LISTENER  # the fixes' subscriber, as benchmarks/mqtt.py runs it

HEIGHT, PITCH_X, PITCH_Y = 4.0, 2.0, 1.5
#: s: latency percentiles are of the fixes after this (each process's start apart)
WARM_UP = 1.0
SPEED = 1.0

#: a locator that says its own CPU time when it ends ("@cpu user system", s)
LOCATOR = r"""
import atexit, resource, sys
atexit.register(lambda: print("@cpu %.3f %.3f" % resource.getrusage(resource.RUSAGE_SELF)[:2],
                              file=sys.stderr, flush=True))
from vlpcal.cli import main
main(sys.argv[1:], prog_name="vlpcal", standalone_mode=False)
"""


def site(cameras: int, processes: int):
    """The grid of cameras, cut into ``processes`` zones, and a path per zone: (deployment,
    paths: zone id → function of t)."""
    cols = int(np.ceil(np.sqrt(cameras * PITCH_Y / PITCH_X * 2)))
    rows = int(np.ceil(cameras / cols))
    cams = [paper_camera(f"C{k + 1:04d}", (PITCH_X * (k % cols + 0.5), PITCH_Y * (k // cols + 0.5),
                                           HEIGHT)) for k in range(cameras)]
    w, h = PITCH_X * cols, PITCH_Y * rows
    room = [[0, 0], [w, 0], [w, h], [0, h]]
    dep = Deployment(f"warehouse-{cameras}", HEIGHT + 0.5, room, cams, [], {})
    zoning = cut_zones(dep, processes)
    dep = Deployment(dep.name, dep.ceiling_height, room, cams, [], {"zones": zoning.block()})
    paths = {}
    for z in zoning.zones:
        (x0, y0), _, (x1, y1), _ = z.polygon
        cx, cy, rx, ry = (x0 + x1) / 2, (y0 + y1) / 2, abs(x1 - x0) / 4, abs(y1 - y0) / 4

        def path(t, cx=cx, cy=cy, rx=rx, ry=ry):
            a = SPEED * np.asarray(t, float) / max(rx, ry)
            return np.stack([cx + rx * np.cos(a), cy + ry * np.sin(a),
                             np.full(np.shape(a), 0.15)], axis=-1)

        paths[z.id] = path
    return dep, zoning, paths


def schedule(dep, paths, fps: float, seconds: float, seed: int) -> list:
    """Every camera's every frame: (t, camera id, spot or None)."""
    rng = np.random.default_rng(seed)
    out = []
    for cam in dep.cameras:
        t = capture_times(Timing(fps=fps, jitter=0.0005, drop=0.0), seconds, rng)
        best = None
        for path in paths.values():  # the LED this camera sees, if any (one at most)
            uv, _, inside = cam.project(path(t), margin=2.0)
            if inside.any():
                best = (uv + rng.normal(0, 0.05, uv.shape), inside)
                break
        for k, tt in enumerate(t):
            spot = None
            if best is not None and best[1][k]:
                spot = (float(best[0][k, 0]), float(best[0][k, 1]))
            out.append((float(tt), cam.id, spot))
    return sorted(out)


def _cpu(pid: int) -> float:
    """s of CPU a process has used (user + system), from /proc."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def run(broker, dep_path, dep, zoning, events, fps: float, seconds: float) -> dict:
    import paho.mqtt.client as mqtt

    tmp = dep_path.parent
    arrivals = tmp / f"arrivals-{time.time_ns()}.tsv"
    listen = subprocess.Popen([sys.executable, "-c", LISTENER, str(broker.port), str(arrivals)])
    procs = {}
    for z in zoning.zones:
        cmd = [sys.executable, "-c", LOCATOR, "locate", "-d", str(dep_path), "--spots",
               broker.url("site"), "--publish", broker.url("out"), "--duration",
               str(seconds + 3), "--zone", z.id,
               "--out", str(tmp / f"fixes-{z.id}-{time.time_ns()}.csv")]
        procs[z.id] = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    time.sleep(2.5)  # subscribed
    broker_cpu = _cpu(broker.proc.pid)
    player_cpu = time.process_time()
    cam = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    cam.max_queued_messages_set(0)
    cam.connect("127.0.0.1", broker.port)
    cam.loop_start()
    start_mono, start_utc = time.monotonic() + 0.2, time.time() + 0.2
    late = np.zeros(len(events))
    for i, (t, cid, spot) in enumerate(events):
        wait = start_mono + t - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        late[i] = time.monotonic() - start_mono - t
        doc = {"t": round(start_utc + t, 6)}
        if spot:
            doc.update(u=round(spot[0], 4), v=round(spot[1], 4))
        cam.publish(f"site/spots/{cid}", json.dumps(doc, separators=(",", ":")))
    player_cpu = time.process_time() - player_cpu
    cam.disconnect()
    cam.loop_stop()
    received = published = 0
    cpu = {}
    for zid, p in procs.items():
        _, err = p.communicate(timeout=180)
        m = re.search(r"spots: (\d+) messages|(\d+) spot messages", err)
        received += int(m.group(1) or m.group(2)) if m else 0
        m = re.search(r"published (\d+) messages", err)
        published += int(m.group(1)) if m else 0
        m = re.search(r"@cpu ([\d.]+) ([\d.]+)", err)
        cpu[zid] = float(m.group(1)) + float(m.group(2)) if m else float("nan")
        if p.returncode != 0:
            raise RuntimeError(err)
    broker_cpu = _cpu(broker.proc.pid) - broker_cpu
    time.sleep(0.5)
    listen.terminate()
    listen.wait(timeout=10)
    got = [(float(a), json.loads(b)) for a, b in
           (line.split("\t", 1) for line in arrivals.read_text().splitlines() if "\t" in line)]
    placed = [(now, msg) for now, msg in got if msg["x"] is not None]
    steady = [(now, msg) for now, msg in placed if msg["t"] - start_utc >= WARM_UP]
    lat = np.array([now - msg["t"] for now, msg in steady]) * 1000
    cams_of = {z.id: set(z.cameras) for z in zoning.zones}
    want = sum(1 for _, cid, _ in events for ids in cams_of.values() if cid in ids)
    span = seconds + 3 + 2.5  # each locator's life: its --duration and its start

    def pct(q):
        return float(np.percentile(lat, q)) if len(lat) else float("nan")

    return {"locators": len(zoning.zones), "fps": fps, "cameras": len(dep.cameras),
            "messages_per_s": len(events) / seconds, "spots_expected": want,
            "spots_received": received, "spots_lost": want - received,
            "fixes_published": published, "fixes_received": len(got),
            "fixes_lost": published - len(got), "fixes_per_s": len(placed) / seconds,
            "latency_p50_ms": pct(50), "latency_p99_ms": pct(99),
            "player_late_p99_ms": float(np.percentile(late, 99) * 1000),
            "locator_cpu_pct": float(np.nanmax(list(cpu.values())) / span * 100),
            "broker_cpu_pct": broker_cpu / seconds * 100,
            "player_cpu_pct": player_cpu / seconds * 100,
            "max_zone_cameras": int(zoning.loads.max())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cameras", type=int, default=1000)
    ap.add_argument("--processes", type=int, nargs="+", default=[2, 4])
    ap.add_argument("--fps", type=float, nargs="+", default=[1, 2, 5, 10, 30])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows, held = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        broker = Broker(tmp)
        try:
            for n in args.processes:
                dep, zoning, paths = site(args.cameras, n)
                save(dep, tmp / f"site-{n}.yaml")
                for fps in sorted(args.fps):
                    events = schedule(dep, paths, fps, args.seconds, args.seed)
                    row = run(broker, tmp / f"site-{n}.yaml", dep, zoning, events, fps,
                              args.seconds)
                    rows.append(row)
                    print(f"  {n} locators, {fps:g} fps: {row['spots_lost']} spots lost, "
                          f"{row['fixes_lost']} fixes lost, p99 {row['latency_p99_ms']:.1f} ms",
                          file=sys.stderr)
                    kept_up = row["player_late_p99_ms"] < 1000 / fps
                    if row["spots_lost"] or row["fixes_lost"] or not kept_up:
                        break
                    held[n] = row
        finally:
            broker.stop()
    print(f"{args.cameras} cameras (the paper's, {HEIGHT:g} m up, {PITCH_X:g} × {PITCH_Y:g} m "
          f"apart), one LED per zone, every frame published; {args.seconds:g} s a run; one "
          "run each (rates rise until a message is lost or the cameras' player falls behind)")
    print(table(rows, [("locators", "zones", "d"), ("max_zone_cameras", "cameras/zone", "d"),
                       ("fps", "fps", "g"), ("messages_per_s", "spot msgs/s", ".0f"),
                       ("spots_lost", "spots lost", "d"), ("fixes_lost", "fixes lost", "d"),
                       ("fixes_per_s", "fixes/s", ".1f"), ("latency_p50_ms", "p50 ms", ".1f"),
                       ("latency_p99_ms", "p99 ms", ".1f"),
                       ("player_late_p99_ms", "player late p99 ms", ".1f"),
                       ("locator_cpu_pct", "locator CPU %", ".0f"),
                       ("broker_cpu_pct", "broker CPU %", ".0f"),
                       ("player_cpu_pct", "player CPU %", ".0f")]))
    for n, row in held.items():
        per = row["messages_per_s"] / row["locators"]
        print(f"{n} zones: held {row['fps']:g} fps without loss ({row['messages_per_s']:.0f} "
              f"spot messages/s, {per:.0f} per locator at {row['locator_cpu_pct']:.0f} % of a "
              "core)")
    out = write_json("site", {"cameras": args.cameras, "seconds": args.seconds, "rows": rows,
                              "held": {str(k): v for k, v in held.items()}})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
