"""Every numbered example runs as a script, from another folder, and prints its key line."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

import egnc

EXAMPLES = Path(__file__).parents[1] / "examples"

# The line each example must print, proof that it got to its end.
KEY_LINES = {
    "01_solve_g2o.py": "wrote solved.g2o",
    "02_python_api.py": "G2oFormatError at line 2:",
    "03_from_gtsam.py": "ISAM2 on the kept factors:",
    "04_gnss_priors.py": "wrote gnss.png",
}

NEEDS = {"03_from_gtsam.py": "gtsam"}
"""The optional package an example imports (its test skips without it; ids naming gtsam are long tier)."""


@pytest.fixture(scope="module")
def run_example(tmp_path_factory):
    """`name -> (completed process, its working folder)`, each example run once per module."""
    runs = {}

    def run(name: str) -> tuple[subprocess.CompletedProcess, Path]:
        if name not in runs:
            # Not the repository root: examples must find the datasets relative to their own file.
            cwd = tmp_path_factory.mktemp(name.removesuffix(".py"))
            process = subprocess.run(
                [sys.executable, str(EXAMPLES / name)], cwd=cwd, capture_output=True, text=True, timeout=300
            )
            runs[name] = process, cwd
        return runs[name]

    return run


def test_every_example_is_listed():
    assert sorted(path.name for path in EXAMPLES.glob("[0-9][0-9]_*.py")) == sorted(KEY_LINES)


@pytest.mark.parametrize("name", sorted(KEY_LINES))
def test_example_runs(name, run_example):
    if name in NEEDS:
        pytest.importorskip(NEEDS[name])
    process, _ = run_example(name)
    assert process.returncode == 0, process.stderr
    assert process.stderr == ""
    assert any(line.startswith(KEY_LINES[name]) for line in process.stdout.splitlines()), process.stdout


def test_solve_example_writes_the_input_edges(run_example):
    process, cwd = run_example("01_solve_g2o.py")
    assert process.returncode == 0, process.stderr
    source = egnc.read_g2o(EXAMPLES.parent / "datasets" / "grid2d_outliers.g2o")
    solved = egnc.read_g2o(cwd / "solved.g2o")
    assert solved.num_poses == source.num_poses
    assert (solved.edges == source.edges).all()
    assert (solved.measurements == source.measurements).all()
    assert not (solved.poses == source.poses).all()
    # The default robust method rejects exactly the false loop closures of this file.
    rejected = re.search(r"^rejected (\d+) of \d+ loop closures, (\d+) of the (\d+) false ones$", process.stdout, re.M)
    assert rejected, process.stdout
    assert rejected[1] == rejected[2] == rejected[3]


def test_gnss_example_rejects_exactly_the_moved_fixes(run_example):
    process, _ = run_example("04_gnss_priors.py")
    assert process.returncode == 0, process.stderr
    found = re.search(r"^rejected (\d+) of \d+ fixes, (\d+) of the (\d+) moved ones$", process.stdout, re.M)
    assert found, process.stdout
    assert found[1] == found[2] == found[3] != "0"
