"""Seeded fuzzing (benchmarks/fuzz.py): mutated real and generated g2o files never crash egnc.

Reading a mutant gives a `PoseGraph` or an `EgncError`; solving an accepted one gives a result or
an `EgncError`, a strict-JSON report, and nothing on stdout. `python benchmarks/fuzz.py` runs more
cases and prints the table in RELIABILITY.md.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import fuzz  # noqa: E402

CASES = 240
SEED = 11


@pytest.fixture(scope="module")
def outcomes() -> list[fuzz.Outcome]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mutants are meant to be odd; the outcomes are checked
        return fuzz.fuzz(CASES, SEED)


def test_fuzz_exercises_every_operator_and_both_outcomes_of_reading(outcomes):
    assert len(outcomes) == CASES
    assert {outcome.operator for outcome in outcomes} == set(fuzz.OPERATORS)
    reads = {outcome.read for outcome in outcomes}
    assert {"graph", "clean error"} <= reads
    assert sum(len(outcome.solves) for outcome in outcomes) > CASES // 2  # many mutants are solved


def test_no_crash_no_stdout_no_invalid_json(outcomes, capfd):
    problems = [(k, outcome.operator, fuzz.bad(outcome)) for k, outcome in enumerate(outcomes)]
    problems = [(k, operator, found) for k, operator, found in problems if set(found) - {"non-finite result"}]
    assert problems == []
    assert capfd.readouterr().out == ""


def test_solutions_are_finite_or_a_reported_failure(outcomes):
    non_finite = [(k, outcome.operator) for k, outcome in enumerate(outcomes) if "non-finite result" in outcome.solves]
    assert non_finite == []
