"""benchmarks/bench_online_as_batch.py end to end on small files: the table's rows, each run in a child.

The figures themselves (times, decisions) are what the script measures, so they are only checked
for form and consistency here; BENCHMARKS.md records them on the shared datasets.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[1]
SCRIPT = ROOT / "benchmarks" / "bench_online_as_batch.py"


def table(*args: str) -> dict[str, list[str]]:
    """Run the script; its data rows by variant, split into cells."""
    done = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("| ")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[1:]]
    assert all(len(row) == len(header) for row in rows), done.stdout
    return {row[1]: row for row in rows}


def test_clean_and_corrupted_rows_have_figures_for_both_ways():
    rows = table("--data", str(ROOT / "datasets" / "grid2d_outliers.g2o"), "--percent", "30", "--timeout", "300")
    assert set(rows) == {"clean", "30 %"}
    for variant, row in rows.items():
        assert row[0] == "grid2d_outliers"
        batch, online = row[2:9], row[9:16]
        for cells in (batch, online):
            seconds, rejected, true_rejected, false_kept, quality, ate, mib = cells
            assert float(seconds) > 0 and float(ate) >= 0 and float(mib) > 0
            assert 0 <= int(true_rejected) <= int(rejected)
            if variant == "clean":
                assert int(false_kept) == 0 and quality.startswith("cost ") and float(quality[5:]) > 0
            else:
                precision, recall = (float(value) for value in quality.split(" / "))
                assert 0 <= precision <= 1 and 0 <= recall <= 1
        assert row[16] in ("yes", "**no**")
        assert row[17].endswith("x") and float(row[17][:-1]) > 0


def test_a_graph_the_online_solver_cannot_take_in_order_is_reported_not_replayable(tmp_path):
    # Pose 3 is first reached by the loop closure 0-3, before any odometry reaches it.
    path = tmp_path / "loop_first.g2o"
    vertices = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0)]
    edges = [(0, 1, 1, 0), (1, 2, 1, 0), (0, 3, 2, 1), (3, 4, -1, 0), (2, 4, -1, 1)]
    path.write_text(
        "".join(f"VERTEX_SE2 {k} {x} {y} {t}\n" for k, (x, y, t) in enumerate(vertices))
        + "".join(f"EDGE_SE2 {i} {j} {dx} {dy} 0 1 0 0 1 0 1\n" for i, j, dx, dy in edges)
    )
    rows = table("--data", str(path), "--percent", "", "--timeout", "120")
    assert set(rows) == {"clean"}
    row = rows["clean"]
    assert float(row[2]) > 0 and row[3] == "0"  # the batch solve takes it
    assert row[9].startswith("not replayable: ") and "pose 3" in row[9]
    assert row[16:] == ["-", "-"]
