"""benchmarks/least_squares.py scale and robust_speed.py --grid3d end to end on tiny generated grids.

The figures themselves (times, memory) are what the scripts measure, so they are only checked for
form and consistency here; BENCHMARKS.md records them at scale.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from egnc.bench.gtsam import gtsam_available

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"


def rows(script: str, *args: str) -> list[list[str]]:
    """Run a benchmark script; the data rows of the table it prints, split into cells."""
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *args], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("| ")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    table = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[1:]]
    assert table and all(len(row) == len(header) for row in table), done.stdout
    return table


@pytest.mark.skipif(not gtsam_available(), reason="needs the bench extra's gtsam")
def test_ls_scale_egnc_and_gtsam_reach_the_same_cost_and_ratios_divide_the_medians():
    table = rows("least_squares.py", "scale", "--poses", "300", "--backends", "scipy", "--runs", "2")
    by_solver = {row[2]: row for row in table}
    assert set(by_solver) == {"egnc scipy", "gtsam"}
    egnc, gtsam = by_solver["egnc scipy"], by_solver["gtsam"]
    assert egnc[0] == gtsam[0] == "300" and int(egnc[1]) == int(gtsam[1]) > 299  # odometry and loops
    for row in (egnc, gtsam):
        wall, solve, mib = float(row[3]), float(row[4]), float(row[5])
        assert 0 < solve < wall and mib > 0 and int(row[7]) >= 1 and row[8] == "yes"
    # Both minimize the same 0.5 sum r^2 on a clean grid, from the same guess.
    assert float(egnc[6]) == pytest.approx(float(gtsam[6]), rel=1e-4)
    # Whole processes take tenths of a second, so their printed two decimals hold the ratio to a few %.
    assert float(egnc[9]) == pytest.approx(float(egnc[3]) / float(gtsam[3]), rel=0.05)
    assert float(egnc[10]) > 0
    assert gtsam[9] == gtsam[10] == ""


def test_ls_scale_reports_a_process_over_the_time_limit_as_not_finished():
    options = ("--poses", "200", "--backends", "scipy", "--no-gtsam", "--timeout", "0.01")
    table = rows("least_squares.py", "scale", *options)
    assert len(table) == 1 and table[0][2] == "egnc scipy" and table[0][3].startswith("not finished after")


@pytest.mark.parametrize("clean_init", ["auto", "file", "chordal"])
def test_robust_speed_grid3d_rows_are_3d_grids_with_their_decisions(clean_init):
    table = rows(
        "robust_speed.py",
        *("--datasets", "", "--grid3d", "300", "--percent", "30", "--backends", "scipy", "--clean-init", clean_init),
    )
    assert len(table) == 1
    row = table[0]
    assert row[:4] == ["grid3d-300", "30", "1", "scipy"]
    assert row[4] in ("file", "chordal") and (clean_init == "auto" or row[4] == clean_init)
    clean_s, robust_s, ratio = float(row[5]), float(row[6]), float(row[7])
    assert clean_s > 0 and robust_s > 0 and ratio == pytest.approx(robust_s / clean_s, rel=0.05, abs=0.05)
    rejected, false = (int(part) for part in row[12].split(" / "))
    assert false > 0 and rejected > 0 and int(row[10]) >= 1 and int(row[11]) >= 1  # analyses, rounds
    assert 0 <= float(row[13]) <= 1 and 0 <= float(row[14]) <= 1


def test_robust_speed_repeats_give_the_median_ratio_and_its_range():
    options = ("--datasets", "", "--grid", "300", "--percent", "30", "--backends", "scipy", "--repeats", "3")
    (row,) = rows("robust_speed.py", *options)
    assert row[:4] == ["grid2d-300", "30", "1", "scipy"]
    median, spread = row[7].split(" ")
    low, high = (float(part) for part in spread.strip("()").split("-"))
    assert low <= float(median) <= high and float(row[5]) > 0 and float(row[6]) > 0


def test_robust_speed_refuses_repeats_that_decide_differently():
    sys.path.insert(0, str(BENCHMARKS))  # the benchmarks are scripts, imported as test_fuzz imports fuzz
    import robust_speed

    first = {"clean_s": 1.0, "robust_s": 3.0, "clean_mib": 10.0, "peak_mib": 15.0, "rejected": 5}
    merged = robust_speed.combined([first, first | {"clean_s": 2.0, "robust_s": 2.0}, first])
    assert merged["ratio"] == 3.0 and merged["ratio_range"] == (1.0, 3.0) and merged["clean_s"] == 1.0
    with pytest.raises(SystemExit, match="rejected"):
        robust_speed.combined([first, first | {"rejected": 6}])
