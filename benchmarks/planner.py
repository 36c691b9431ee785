"""The layout optimiser against an exhaustive grid search, on three sites, and a large room.

Sites (160 × 120 px cameras, f = 153.3 px; k = 2 cameras over 95 % of the floor at every LED
height; predicted p95 ≤ 2 cm at 0.3 px of spot noise, DESIGN.md's reference model):
a 4 × 3 m rectangle, an L-shaped room with a pillar (keep-out), a 10 × 1.6 m corridor. For each:
the optimiser's camera count and time (`plan_site`), and the exhaustive search's over the same
counts (every family, arrangement and yaw over 12 spacings × 7 × 7 offsets per count, from the
same lower bound up to the optimiser's grid size — cameras that would hang outside the room
are dropped from both; "–" when it finds none there). Both results
are judged by `evaluate` (the model, not a surrogate). Then the time to plan a 10 × 8 m room.
Prints a table, writes benchmarks/out/planner.json.

    python benchmarks/planner.py
"""

from __future__ import annotations

import sys
import time

import _common  # noqa: F401  (one-core setup before numpy)
from _common import table, write_json

from vlpcal.planning import (
    evaluate,
    exhaustive_search,
    lower_bound,
    plan_site,
    site_from_dict,
)

CAMERA = {"width": 160, "height": 120, "fx": 153.3, "fy": 153.3, "cx": 79.5, "cy": 59.5,
          "dist": [0, 0, 0, 0, 0]}
REQ = {"heights": [0.0, 0.35], "min_cameras": 2, "coverage": 0.95, "max_error_p95": 0.02,
       "pixel_noise": 0.3}


def site(name, room, ceiling, keep_out=(), heights=None):
    return site_from_dict({
        "format": "vlpcal-site", "version": 1,
        "site": {"name": name, "ceiling_height": ceiling, "room": room,
                 "keep_out": list(keep_out)},
        "camera": CAMERA, "requirements": {**REQ, **({"heights": heights} if heights else {})},
        "families": ["linear", "triangular", "square"]})


SITES = [
    site("rectangle 4×3 m", [[0, 0], [4, 0], [4, 3], [0, 3]], 2.5),
    site("L-shape with a pillar", [[0, 0], [5, 0], [5, 2], [2.5, 2], [2.5, 4], [0, 4]], 2.8,
         keep_out=[[[1.0, 1.0], [1.4, 1.0], [1.4, 1.4], [1.0, 1.4]]]),
    site("corridor 10×1.6 m", [[0, 0], [10, 0], [10, 1.6], [0, 1.6]], 2.5),
]
#: the exhaustive grid: spacings from 0.3 to 1.0 footprint in 12 steps (~5–15 cm apart),
#: offsets on a 7 × 7 grid within one spacing, both yaws, every family and arrangement
STEPS, OFFSETS = 12, 7
LARGE = site("hall 10×8 m", [[0, 0], [10, 0], [10, 8], [0, 8]], 3.0, heights=[0.0, 0.3])


def main() -> int:
    rows = []
    for s in SITES:
        t0 = time.perf_counter()
        plan = plan_site(s)
        t_opt = time.perf_counter() - t0
        best = plan.candidates[0] if plan.candidates else None
        opt_ok = best is not None and evaluate(s, best.cameras).meets
        # the exhaustive search over the same counts: up to the optimiser's answer
        t0 = time.perf_counter()
        ex_best = None
        # grid sizes, as the optimiser counts them (cameras outside the room are dropped after)
        grid_n = best.nx * (best.ny if best.family != "linear" else 1) if best else 40
        for n in range(lower_bound(s), grid_n + 1):
            found = exhaustive_search(s, n, steps=STEPS, offsets=OFFSETS)
            if found:
                ex_best = found[0]
                break
        t_ex = time.perf_counter() - t0
        rows.append({"site": s.name, "optimiser_cameras": best.count if best else None,
                     "optimiser_family": best.family if best else "–",
                     "optimiser_p95_cm": best.evaluation.p95 * 100 if best else None,
                     "optimiser_s": t_opt, "verified": opt_ok,
                     "exhaustive_cameras": ex_best.count if ex_best else None,
                     "exhaustive_s": t_ex, "speedup": t_ex / t_opt})
    print("Fewest cameras meeting the requirements (k = 2 over 95 %, p95 ≤ 2 cm at 0.3 px, "
          "LED at 0–0.35 m), optimiser vs exhaustive grid search")
    print(table(rows, [("site", "site", ""), ("optimiser_cameras", "optimiser", "d"),
                       ("optimiser_family", "family", ""), ("optimiser_p95_cm", "p95 cm", ".2f"),
                       ("optimiser_s", "time s", ".1f"),
                       ("exhaustive_cameras", "exhaustive", "d"),
                       ("exhaustive_s", "time s", ".1f"), ("speedup", "speed-up", ".1f")]))
    t0 = time.perf_counter()
    large = plan_site(LARGE)
    t_large = time.perf_counter() - t0
    lb = large.candidates[0] if large.candidates else None
    print(f"\n{LARGE.name}: {lb.count if lb else '–'} cameras "
          f"({lb.family if lb else '–'}) in {t_large:.1f} s on one core")
    # the exhaustive search stops at the optimiser's count: "–" means it needs more cameras
    never_more = all(r["optimiser_cameras"] is not None and (r["exhaustive_cameras"] is None or
                     r["optimiser_cameras"] <= r["exhaustive_cameras"]) for r in rows)
    faster = all(r["speedup"] >= 5 for r in rows)
    print(f"optimiser never needs more cameras: {'yes' if never_more else 'NO'}; at least 5× "
          f"faster: {'yes' if faster else 'NO'}; 10 × 8 m under 60 s: "
          f"{'yes' if t_large < 60 else 'NO'}")
    path = write_json("planner", {"rows": rows, "large_s": t_large,
                                  "large_cameras": lb.count if lb else None})
    print(f"wrote {path}")
    return 0 if never_more and faster and t_large < 60 else 1


if __name__ == "__main__":
    sys.exit(main())
