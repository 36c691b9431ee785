"""The benchmark scripts run (tiny settings): they measure, the tests only keep them working."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_paper_benchmark_prints_every_table(tmp_path):
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "paper.py"), "--installs", "1",
         "--repeats", "1", "--profile-points", "20"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
        env={**os.environ, "VLPCAL_BENCH_OUT": str(tmp_path)})
    assert out.returncode == 0, out.stderr[-2000:]
    assert (tmp_path / "paper.json").is_file() and (tmp_path / "paper_fig13.png").is_file()
    for title in ("Table 3", "Table 4", "Fig. 14", "Fig. 15", "Fig. 16", "Every profile"):
        assert title in out.stdout
