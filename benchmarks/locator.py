"""End-to-end speed of the runtime locator, beside the JPEG-decode floor and the paper's 20 ms.

One simulated paper-2024 install (three 160 × 120 cameras), ≥ 3000 frame sets of an LED along
a robot's path. Measured on one core, medians of 5 runs:

- decode floor: grayscale ``cv2.imdecode`` of the same three JPEGs per set (nothing else);
- Python API, batch: ``Locator.locate_batch`` on all sets (decode, detect, triangulate, fuse,
  predicted uncertainty), µs per fix;
- Python API, one set at a time: ``Locator.locate``;
- ``vlpcal locate --frames DIR --out fixes.csv``: a fresh process on the folder, wall time
  including start-up, reading the files and writing the CSV (fixes/s), median of 5 runs;
  and the same process on a folder of two sets (its start-up alone). It runs as an installed
  package does, its bytecode cached (a machine that sets PYTHONDONTWRITEBYTECODE, as the one
  the figures come from does, would recompile vlpcal at every start: ~70 ms).

Targets (issue 16): ``locate_batch`` within 1.3 × the decode floor, ``vlpcal locate --frames``
within 2 ×.

Writes benchmarks/out/locator.json.

    python benchmarks/locator.py [--sets 3000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common  # noqa: F401  (one-core setup before numpy)
import numpy as np
from _common import best_time, table, write_json

from vlpcal import deployment
from vlpcal.datasets import write_frames_folder
from vlpcal.detection import decode_gray
from vlpcal.locator import Locator
from vlpcal.sim.profiles import get_profile
from vlpcal.sim.scene import make_scene, render_scene
from vlpcal.sim.writers import deployment_of, trajectory

PAPER_US = 20_000.0  # the paper's 20 ms per fix on its embedded device (abstract, section 4)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    scene = make_scene(get_profile("paper-2024"), args.seed)
    path = trajectory(scene, args.sets, height=0.15, seed=args.seed)
    t0 = time.perf_counter()
    frames, _ = render_scene(scene, path, seed=args.seed)
    print(f"rendered {args.sets} frame sets × {len(frames)} cameras in "
          f"{time.perf_counter() - t0:.0f} s")
    sets = [{c: frames[c][i] for c in frames} for i in range(args.sets)]
    jpegs = [j for s in sets for j in s.values()]
    loc = Locator(deployment_of(scene, "true"))

    # the floor and the API alternate, 5 runs each, medians: both see the same machine
    decodes, batches = [], []
    for _ in range(5):
        decodes.append(best_time(lambda: [decode_gray(j) for j in jpegs], 1))
        batches.append(best_time(lambda: loc.locate_batch(sets), 1))
    decode = float(np.median(decodes)) / args.sets * 1e6
    batch = float(np.median(batches)) / args.sets * 1e6
    few = sets[:300]
    single = best_time(lambda: [loc.locate(s) for s in few], 2) / len(few) * 1e6
    fixes = loc.locate_batch(sets)
    err = np.linalg.norm(fixes.X - path, axis=1)
    fixed = float(np.isfinite(err).mean())

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        ids = [f"{i:06d}" for i in range(args.sets)]
        write_frames_folder(tmp / "frames", ids, frames)
        dep = tmp / "truth.yaml"
        deployment.save(deployment_of(scene, "true"), dep)
        write_frames_folder(tmp / "two", ids[:2], {c: f[:2] for c, f in frames.items()})
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")

        def cli(folder: str) -> float:
            (tmp / "fixes.csv").unlink(missing_ok=True)
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "vlpcal", "locate", "-d", str(dep),
                            "--frames", str(tmp / folder), "--out", str(tmp / "fixes.csv"),
                            "-q"], check=True, env=env)
            return time.perf_counter() - t0

        cli("two")  # the bytecode cache filled, as an install does
        walls, starts = [], []
        for _ in range(5):
            starts.append(cli("two"))
            walls.append(cli("frames"))
        cli_rate = args.sets / float(np.median(walls))
        start_s = float(np.median(starts))
        rows_written = sum(1 for _ in open(tmp / "fixes.csv")) - 1

    marginal = (args.sets / cli_rate - start_s) / args.sets * 1e6
    rows = [
        {"what": "JPEG decode floor (3 × cv2.imdecode gray)", "us": decode, "ratio": 1.0},
        {"what": "Locator.locate_batch (decode+detect+fuse)", "us": batch,
         "ratio": batch / decode},
        {"what": "Locator.locate, one set at a time", "us": single, "ratio": single / decode},
        {"what": "vlpcal locate --frames (process, files, CSV)", "us": 1e6 / cli_rate,
         "ratio": 1e6 / cli_rate / decode},
        {"what": "  of which its start-up (a 2-set folder), per set", "us": start_s * 1e6
         / args.sets, "ratio": start_s * 1e6 / args.sets / decode},
        {"what": "  the rest: each set's files, fix and row", "us": marginal,
         "ratio": marginal / decode},
        {"what": "the paper, embedded device", "us": PAPER_US, "ratio": PAPER_US / decode},
    ]
    print(f"\n{args.sets} fix sets, 3 cameras, one core; {fixed:.1%} fixed, mean error "
          f"{np.nanmean(err) * 1000:.2f} mm (true cameras)")
    print(table(rows, [("what", "", ""), ("us", "µs per fix", ",.1f"),
                       ("ratio", "× decode floor", ".2f")]))
    cli_ratio = 1e6 / cli_rate / decode
    api_ok, cli_ok = batch <= 1.3 * decode, cli_ratio <= 2.0
    print(f"\nLocator.locate_batch: {batch / decode:.2f} × the decode floor "
          f"({'meets' if api_ok else 'MISSES'} ≤ 1.3×); vlpcal locate --frames: "
          f"{cli_ratio:.2f} × ({'meets' if cli_ok else 'MISSES'} ≤ 2×; {cli_rate:,.0f} "
          f"fixes/s, start-up {start_s * 1000:.0f} ms, {rows_written} rows written; "
          f"past its start-up {marginal / decode:.2f} ×)")
    out = write_json("locator", {"sets": args.sets, "rows": rows, "cli_fixes_per_s": cli_rate,
                                 "cli_start_s": start_s, "batch_vs_decode": batch / decode,
                                 "cli_vs_decode": cli_ratio,
                                 "cli_past_start_vs_decode": marginal / decode,
                                 "fixed": fixed, "mean_error_m": float(np.nanmean(err))})
    print(f"wrote {out}")
    return 0 if api_ok and cli_ok else 1


if __name__ == "__main__":
    sys.exit(main())
