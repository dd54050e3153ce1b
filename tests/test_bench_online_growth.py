"""benchmarks/bench_online_growth.py end to end at small sizes: one row per size, in its form.

What the updates cost at scale is measured in BENCHMARKS.md; here the rows are checked for form
and for what holds at any size: a loop update solves a region of the chain, not the whole map.
(No timing is asserted.)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[1]


def test_a_row_per_size_with_loops_solved_in_a_region():
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_online_growth.py"), "--sizes", "200,2000", "--updates", "40"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    rows = [line.strip("|").split("|") for line in lines if line.startswith("| ") and line[2].isdigit()]
    assert [int(row[0]) for row in rows] == [200, 2000]
    for _, odometry, loop, region in rows:
        odometry_p50, odometry_max = map(float, odometry.split(" / "))
        loop_p50, loop_max = map(float, loop.split(" / "))
        assert 0 < odometry_p50 <= odometry_max and 0 < loop_p50 <= loop_max
        assert 0 < int(region) < 200  # a region around the loop, not the whole map
