"""benchmarks/online.py replay end to end on a small generated graph, and its merge of repeats.

What the replays cost is measured in BENCHMARKS.md; here the table is checked for form and for
what holds on any graph: the repeats of a deterministic replay agree, the ratio of repeated runs
gives its range, and a repeat that disagrees stops the bench. (No timing is asserted.)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from egnc.datasets import grid_world
from egnc.io import write_g2o

ROOT = Path(__file__).parents[1]
SCRIPT = ROOT / "benchmarks" / "online.py"
sys.path.insert(0, str(SCRIPT.parent))  # the benchmarks are scripts, imported as test_fuzz imports fuzz

from _lib import online_replay  # noqa: E402


def test_repeats_alternate_and_give_the_ratio_range(tmp_path):
    write_g2o(grid_world(2, 300, seed=3).graph, tmp_path / "tiny.g2o")
    rows_file = tmp_path / "rows.jsonl"
    command = [sys.executable, str(SCRIPT), "--datasets", "tiny", "--percents", "30", "--irl", ""]
    done = subprocess.run(
        [*command, "--repeats", "2", "--json", str(rows_file)],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "EGNC_DATASETS": str(tmp_path)},
    )
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("| tiny ")]
    assert [line.split("|")[3].strip() for line in lines] == ["egnc", "risam"]
    ratio = lines[0].split("|")[-2].strip()
    assert "(" in ratio and ratio.endswith("x")  # "median (min-max) / iterations"
    rows = [json.loads(line) for line in rows_file.read_text().splitlines()]
    assert [row["repeats"] for row in rows] == [2, 2]
    egnc, risam = rows
    assert len(egnc["time_ratios"]) == 2 and "time_ratios" not in risam
    assert all(ratio > 0 for ratio in egnc["time_ratios"])
    assert egnc["P"] == egnc["R"] == 1.0  # a grid's few false loops, all found
    assert risam["iterations"] > egnc["iterations"] > 0


def test_repeats_that_differ_stop_the_bench():
    row = {"method": "egnc", "P": 1.0, "iterations": 10, **{key: 1.0 for key in online_replay.TIMES}}
    merged = online_replay.combined([row, {**row, "total_s": 3.0}, {**row, "total_s": 2.0}])
    assert merged["total_s"] == 2.0 and merged["iterations"] == 10
    with pytest.raises(SystemExit, match="iterations"):
        online_replay.combined([row, {**row, "iterations": 11}])
