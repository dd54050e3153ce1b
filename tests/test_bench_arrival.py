"""benchmarks/bench_arrival.py end to end on a shipped graph: its row has the figures it promises.

What the prediction is worth is measured on the shared datasets (BENCHMARKS.md); here the row is
only checked for form and consistency.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[1]


def test_the_row_counts_predicted_and_decided_updates():
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_arrival.py"), "--datasets", "grid2d", "--percents", "30"],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "EGNC_DATASETS": str(ROOT / "datasets")},
    )
    assert done.returncode == 0, done.stderr
    rows = [line.strip("|").split("|") for line in done.stdout.splitlines() if line.startswith("| grid2d")]
    assert len(rows) == 1
    name, percent, seed, loop_updates, predicted, first_stage, decided, kept, lower, moved = map(str.strip, rows[0])
    median, p99 = map(float, first_stage.split(" / "))
    assert (name, percent, seed) == ("grid2d", "30", "0")
    assert 0 < int(predicted) and 0 < int(decided) < int(loop_updates)
    assert 0 <= median <= p99 < 1  # the predicted first stage is within a factor of 10 of the solved one
    assert all(0 <= int(count) <= int(decided) for count in (kept, lower, moved))
