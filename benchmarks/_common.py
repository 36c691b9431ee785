"""Shared by the benchmark scripts: one-core setup, timing, table printing, JSON output."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

# one core, as the acceptance figures are stated (set before numpy is imported)
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

#: where tables' JSON and figures go (VLPCAL_BENCH_OUT overrides, e.g. for the smoke tests)
OUT = Path(os.environ.get("VLPCAL_BENCH_OUT", Path(__file__).resolve().parent / "out"))


def best_time(fn, repeat: int = 5) -> float:
    """Best wall time of ``repeat`` calls, seconds (the least disturbed by other load)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """Format rows as a text table; ``columns`` are (key, header, format)."""
    cells = [[h for _, h, _ in columns]]

    def cell(value, fmt):
        if value is None or (isinstance(value, float) and value != value):
            return "–"
        return format(value, fmt) if isinstance(value, (int, float)) else str(value)

    for r in rows:
        cells.append([cell(r.get(k), f) for k, _, f in columns])
    widths = [max(len(c[i]) for c in cells) for i in range(len(columns))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                       for i, (c, w) in enumerate(zip(row, widths))) for row in cells]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)


def _plain(value):
    """JSON-safe: NaN and infinities become null (strict JSON has no NaN), numpy → Python."""
    import math

    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(name: str, payload: dict) -> Path:
    """Write ``benchmarks/out/<name>.json`` atomically, with the machine it ran on."""
    import cv2
    import numpy as np

    OUT.mkdir(parents=True, exist_ok=True)
    payload = {"machine": {"python": platform.python_version(), "numpy": np.__version__,
                           "opencv": cv2.__version__, "cpu": platform.processor() or
                           platform.machine()}, **payload}
    path = OUT / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_plain(payload), indent=2, allow_nan=False))
    tmp.replace(path)
    return path
