"""`SolverOptions` and `GncOptions` check every field at construction (issue 19).

Before, `initial_damping=nan` never returned, `initial_damping=-1` returned a wrong cost marked
"converged", `gradient_tol=inf` stopped at the guess as "converged", and `warm_start="no"` acted
as True: each now fails at once with one `OptionError` naming the field.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from egnc.api import solve
from egnc.errors import EgncError, OptionError, OptionTypeError
from egnc.nonlinear.least_squares import SolverOptions
from egnc.robust.gnc import GncOptions

GRID2D = Path(__file__).parents[1] / "datasets" / "grid2d_outliers.g2o"

BAD_SOLVER_OPTIONS = [
    ("initial_damping", math.nan),
    ("initial_damping", -1.0),
    ("initial_damping", 0.0),
    ("initial_damping", 1e40),  # above max_damping: LM could never take a step
    ("gradient_tol", math.inf),
    ("gradient_tol", -1e-3),
    ("rel_cost_tol", math.nan),
    ("rel_cost_tol", -1.0),
    ("step_tol", math.inf),
    ("step_tol", -1.0),
    ("max_damping", 0.0),
    ("max_damping", -5.0),
    ("max_damping", math.inf),
    ("max_iterations", 1.5),
    ("max_iterations", -1),
    ("max_iterations", True),
    ("max_iterations", "10"),
    ("trust_weight", 0.0),
    ("trust_weight", 1.5),
    ("trust_weight", math.nan),
    ("method", "newton"),
    ("method", None),
    ("linear_method", "cg"),
    ("linear_method", ["auto"]),
]

BAD_GNC_OPTIONS = [
    ("warm_start", "no"),
    ("warm_start", 0),
    ("starts", "chordal"),
    ("starts", None),
    ("starts", ("chordal", "nearest")),
    ("starts", ("chordal", "chordal")),
    ("starts", ("chordal", "runs")),
    ("refine", None),
    ("readmit", "yes"),
    ("every_stage", 1.0),
    ("c", math.nan),
    ("c", 0.0),
    ("c", -3.0),
    ("c", "3"),
    ("max_stages", 0),
    ("max_stages", 2.0),
    ("outlier_quantile", 1.0),
    ("outlier_quantile", math.nan),
    ("readmit_quantile", 0.0),
    ("readmit_false_alarms", 0.0),
    ("readmit_false_alarms", "0.1"),
    ("stage_rel_cost_tol", -1e-6),
    ("stage_rel_cost_tol", math.inf),
    ("threshold", "cubed"),
    ("outlier_threshold", None),
]


@pytest.mark.parametrize(("name", "value"), BAD_SOLVER_OPTIONS)
def test_every_bad_solver_option_is_refused_naming_the_field(name, value):
    with pytest.raises(OptionError, match=rf"SolverOptions\.{name}\b"):
        SolverOptions(**{name: value})


@pytest.mark.parametrize(("name", "value"), BAD_GNC_OPTIONS)
def test_every_bad_gnc_option_is_refused_naming_the_field(name, value):
    with pytest.raises(OptionError, match=rf"GncOptions\.{name}\b"):
        GncOptions(**{name: value})


DEPRECATED_START_FLAGS = [
    ("chordal_start", "no"),
    ("chordal_all_start", 0),
    ("elimination_start", 1),
    ("regroup_start", "on"),
    ("runs_start", 1),
]
"""The former booleans of the starts: still checked while they are accepted."""


@pytest.mark.parametrize(("name", "value"), DEPRECATED_START_FLAGS)
def test_a_bad_deprecated_start_flag_is_refused_naming_it(name, value):
    with pytest.raises(OptionError, match=rf"GncOptions\.{name}\b"):
        GncOptions(**{name: value})


def test_an_unknown_start_is_refused_listing_the_known_ones():
    with pytest.raises(OptionError, match="unknown start 'nearest'") as refused:
        GncOptions(starts=("chordal", "nearest"))
    for name in ("runs", "chordal", "chordal-all", "regrouped", "elimination", "parts"):
        assert repr(name) in str(refused.value)


def test_the_deprecated_start_flags_warn_and_switch_starts():
    expected = r"starts=\('runs', 'chordal-all', 'regrouped', 'elimination', 'parts'\)"
    with pytest.warns(DeprecationWarning, match=expected):
        without_chordal = GncOptions(chordal_start=False)
    assert without_chordal == GncOptions(starts=("runs", "chordal-all", "regrouped", "elimination", "parts"))
    with pytest.warns(DeprecationWarning, match="starts="):
        all_off = GncOptions(
            runs_start=False, chordal_start=False, chordal_all_start=False, regroup_start=False, elimination_start=False
        )
    assert all_off.starts == ("parts",)  # the flags predate the parts start: it has none
    with pytest.warns(DeprecationWarning):
        switched = dataclasses.replace(all_off, runs_start=True, elimination_start=True)
    assert switched.starts == ("runs", "parts", "elimination")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # replacing another field keeps the starts, silently
        assert dataclasses.replace(without_chordal, c=2.0).starts == without_chordal.starts


def test_every_field_is_covered_by_a_bad_value():
    assert {f.name for f in fields(SolverOptions)} == {name for name, _ in BAD_SOLVER_OPTIONS}
    assert {f.name for f in fields(GncOptions)} == {name for name, _ in BAD_GNC_OPTIONS}


def test_option_errors_are_egnc_errors_and_the_builtin_kinds():
    with pytest.raises(OptionTypeError) as wrong_type:
        GncOptions(warm_start="no")  # type: ignore[arg-type]
    assert isinstance(wrong_type.value, (EgncError, TypeError, ValueError))
    assert isinstance(wrong_type.value, TypeError)
    with pytest.raises(OptionError) as out_of_range:
        SolverOptions(initial_damping=-1.0)
    assert isinstance(out_of_range.value, ValueError) and not isinstance(out_of_range.value, TypeError)
    assert "\n" not in str(out_of_range.value)


def test_numpy_scalars_are_accepted_and_stored_as_python_values():
    options = SolverOptions(max_iterations=np.int64(7), gradient_tol=np.float32(1e-6), initial_damping=1)
    assert options.max_iterations == 7 and type(options.max_iterations) is int
    assert type(options.gradient_tol) is float and type(options.initial_damping) is float
    gnc = GncOptions(warm_start=np.bool_(True), max_stages=np.int32(4))
    assert gnc.warm_start is True and type(gnc.max_stages) is int


def test_defaults_and_valid_edges_of_the_ranges_are_accepted():
    SolverOptions()
    GncOptions()
    SolverOptions(max_iterations=0, gradient_tol=0.0, rel_cost_tol=0.0, step_tol=0.0, trust_weight=1.0)
    SolverOptions(initial_damping=1e32, max_damping=1e32)


def test_negative_damping_no_longer_reports_a_wrong_converged_cost():
    # The reproducer of issue 19: it used to return status "converged" at a cost above the optimum.
    with pytest.raises(OptionError, match="initial_damping"):
        solve(GRID2D, "l2", options=SolverOptions(initial_damping=-1.0))
