"""Seeded fuzzing (benchmarks/fuzz.py: the targets in benchmarks/_lib/fuzz_*.py): each target, quickly.

Files: reading a mutant gives a `PoseGraph` or an `EgncError` (always the error for the invalid
operators); solving an accepted one gives a result or an `EgncError`, a strict-JSON report, and
nothing on stdout. Options: an invalid field value is refused at construction naming the field,
valid ones solve. API: every misuse ends in a one-line `EgncError`. Checkpoints: a damaged one is
refused in one line naming the file, or resumes; an edited one does not resume. Nothing hangs.
`python benchmarks/fuzz.py --target all` runs more cases and prints the tables in RELIABILITY.md.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
from _lib import (  # noqa: E402
    fuzz_api,
    fuzz_checkpoints,
    fuzz_core,
    fuzz_files,
    fuzz_options,
)

CASES = 300
SEED = 11


@pytest.fixture(scope="module")
def outcomes() -> list[fuzz_files.Outcome]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mutants are meant to be odd; the outcomes are checked
        return fuzz_files.fuzz(CASES, SEED)


def test_fuzz_exercises_every_operator_and_both_outcomes_of_reading(outcomes):
    assert len(outcomes) == CASES
    assert {outcome.operator for outcome in outcomes} == set(fuzz_files.OPERATORS)
    reads = {outcome.read for outcome in outcomes}
    assert {"graph", "clean error"} <= reads
    assert sum(len(outcome.solves) for outcome in outcomes) > CASES // 2  # many mutants are solved


def test_no_crash_no_hang_no_stdout_no_invalid_json(outcomes, capfd):
    problems = [(k, outcome.operator, fuzz_files.bad(outcome)) for k, outcome in enumerate(outcomes)]
    problems = [(k, operator, found) for k, operator, found in problems if set(found) - {"non-finite result"}]
    assert problems == []
    assert capfd.readouterr().out == ""


def test_solutions_are_finite_or_a_reported_failure(outcomes):
    non_finite = [(k, outcome.operator) for k, outcome in enumerate(outcomes) if "non-finite result" in outcome.solves]
    assert non_finite == []


def test_invalid_mutants_are_refused_valid_ones_read_and_fix_all_has_nothing_to_optimize(outcomes):
    invalid = [outcome for outcome in outcomes if outcome.operator in fuzz_files.INVALID_OPERATORS]
    assert invalid and all(outcome.read == "clean error" for outcome in invalid)
    valid = [outcome for outcome in outcomes if outcome.operator in fuzz_files.VALID_OPERATORS]
    assert valid and all(outcome.read == "graph" for outcome in valid)  # ids at int64's limits (issue 56)
    fixed = [outcome for outcome in outcomes if outcome.operator == "fix all" and outcome.read == "graph"]
    assert fixed and all(solve == "nothing to optimize" for outcome in fixed for solve in outcome.solves)


def test_mutants_whose_poses_a_replay_meets_out_of_order_replay_online(outcomes):
    # A pose first reached by a loop closure, a prior on a later pose (issue 56): what the batch
    # solver accepts, `egnc-solve --online` replays.
    online = [outcome for outcome in outcomes if outcome.operator in fuzz_files.ONLINE_OPERATORS]
    assert online and all(outcome.read == "graph" for outcome in online)
    assert all(outcome.solves[-1] == "online finite" for outcome in online)


def test_time_limit_turns_a_hang_into_a_class():
    with pytest.raises(fuzz_core.Hang), fuzz_core.time_limit(0.05):
        while True:
            pass


def test_options_fuzz_refuses_every_invalid_value_and_solves_the_valid_ones():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = fuzz_options.fuzz_options(250, SEED)
    outcomes = {case.outcome for case in results}
    assert {"refused", "finite"} <= outcomes
    assert [case for case in results if case.outcome in fuzz_options.BAD] == []
    assert all(case.outcome == "refused" for case in results if case.invalid)
    assert {name for case in results for name in case.fields} == set(fuzz_options.VALID)


def test_options_pools_cover_every_field():
    import dataclasses

    import egnc

    names = {field.name for options in (egnc.SolverOptions, egnc.GncOptions) for field in dataclasses.fields(options)}
    assert set(fuzz_options.VALID) == set(fuzz_options.INVALID) == names


def test_api_fuzz_every_misuse_is_a_one_line_egnc_error(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = fuzz_api.fuzz_api(400, SEED, tmp_path)
    assert {case.kind for case in results} == set(fuzz_api.misuses(*_api_arguments(tmp_path)))
    valid = [case.outcome for case in results if case.kind in fuzz_api.VALID_CALLS]
    assert valid and set(valid) == {"valid call returned"}  # empty batches (issue 56)
    assert [(case.kind, case.outcome) for case in results if case.outcome not in ("clean error", *valid)] == []


def _api_arguments(tmp_path: Path) -> tuple:
    import egnc

    graph = fuzz_api._graph()
    return graph, egnc.solve(graph, "l2"), tmp_path


def test_checkpoint_fuzz_refuses_damage_in_one_line_naming_the_file_or_resumes(tmp_path):
    results = fuzz_checkpoints.fuzz_checkpoints(200, SEED, tmp_path)
    assert {case.operator for case in results} == set(fuzz_checkpoints.OPERATORS)
    assert {case.dim for case in results} == {2, 3}
    # An edited checkpoint saved again (issue 56) is refused when the replay resumes from it.
    assert {case.outcome for case in results} == {"clean error", "resumed", "refused edit"}
