"""Fuzz the option dataclasses: random valid and invalid field values, then a solve when accepted.

Each case sets one to three fields of `SolverOptions` and `GncOptions` to values drawn from two
pools per field: `VALID` values and `INVALID` ones (NaN, infinities, negatives, out-of-range
values, a float for an int, a string or None for a bool, unknown names). The pools are the
specification, written independently of `egnc.graph.checks`:

- a case with any invalid value must be refused at construction with an `EgncError`, `TypeError`
  or `ValueError` whose message names the field (else "accepted invalid", a bug);
- a case with valid values only is solved on a small graph with a random method, within
  `fuzz_core.TIME_LIMIT_S`: it must return finite numbers or an `EgncError` (else "crash", "hang"
  or "non-finite result").

Run from `benchmarks/fuzz.py --target options`; `tests/test_fuzz.py` runs fewer cases.
"""

from __future__ import annotations

import collections
import math
import random
from dataclasses import dataclass

import numpy as np

import egnc
from egnc.api import METHODS
from egnc.errors import EgncError

from .fuzz_core import TIME_LIMIT_S, Hang, counts_table, time_limit
from .paths import SHIPPED_DATASETS

VALID: dict[str, tuple[object, ...]] = {
    # SolverOptions; max_iterations and max_stages stay small so that a case takes milliseconds.
    "method": ("lm", "gn"),
    "max_iterations": (0, 1, 3, np.int64(7)),
    "rel_cost_tol": (0.0, 1e-12, 1e-6, 0.5, 1),
    "gradient_tol": (0.0, 1e-10, 1e-3),
    "step_tol": (0.0, 1e-12, 1e-3),
    "initial_damping": (1e-12, 1e-8, 1.0),  # at most every valid max_damping
    "max_damping": (1e3, 1e10, 1e32),
    "linear_method": ("auto", "direct"),
    "trust_weight": (1e-4, 0.5, 1.0),
    # GncOptions
    "c": (0.5, 1.0, 3.0, 10.0),
    "threshold": ("squared", "distance"),
    "outlier_threshold": ("squared", "distance"),
    "outlier_quantile": (0.5, 0.9, 0.99),
    "max_stages": (1, 3, 8),
    "refine": (True, False, np.bool_(True)),
    "readmit": (True, False),
    "readmit_quantile": (0.9, 0.9999),
    "readmit_false_alarms": (0.01, 1.0, 100.0, None),
    "warm_start": (True, False),
    "starts": ((), ("chordal",), ("runs", "elimination"), ("elimination", "chordal"), ["regrouped"]),
    "every_stage": (True, False),
    "stage_rel_cost_tol": (0.0, 1e-6, 1e-3, None),
}
NAN, INF = math.nan, math.inf
_NUMBER = (NAN, INF, -INF, None, "1e-6", True, [1.0])
INVALID: dict[str, tuple[object, ...]] = {
    "method": ("newton", "LM", None, 1, ""),
    "max_iterations": (-1, 1.5, 2.0, True, "5", None, NAN),
    "rel_cost_tol": (-1e-6, *_NUMBER),
    "gradient_tol": (-1.0, *_NUMBER),
    "step_tol": (-1e-12, *_NUMBER),
    "initial_damping": (0.0, -1.0, 1e40, *_NUMBER),  # 1e40 is above every valid max_damping
    "max_damping": (0.0, -1.0, *_NUMBER),
    "linear_method": ("cg", None, 0),
    "trust_weight": (0.0, -0.1, 1.5, *_NUMBER),
    "c": (0.0, -3.0, *_NUMBER),
    "threshold": ("cubed", None, 2),
    "outlier_threshold": ("", None),
    "outlier_quantile": (0.0, 1.0, -0.5, 1.5, *_NUMBER),
    "max_stages": (0, -1, 2.5, True, None),
    "refine": ("no", None, 0, 1.0, "False"),
    "readmit": ("yes", 1),
    "readmit_quantile": (0.0, 1.0, *_NUMBER),
    "readmit_false_alarms": (0.0, -1.0, NAN, INF, -INF, "1", True, [1.0]),  # None: per loop only
    "warm_start": ("no", 0, None),
    "starts": ("chordal", ("nearest",), ("chordal", "runs"), ("chordal", "chordal"), ("chordal", 3), None, 1),
    "every_stage": (1.0, "True"),
    "stage_rel_cost_tol": (-1e-6, NAN, INF, -INF, "1e-6", True, [1.0]),  # None: chosen by the protocol
}
SOLVER_FIELDS = ("method", "max_iterations", "rel_cost_tol", "gradient_tol", "step_tol", "initial_damping",
                 "max_damping", "linear_method", "trust_weight")  # fmt: skip
CLASSES = ("refused", "finite", "solver error", "accepted invalid", "field not named", "non-finite result",
           "crash", "hang")  # fmt: skip
BAD = ("accepted invalid", "field not named", "non-finite result", "crash", "hang")


@dataclass
class OptionsCase:
    """One case: the fields set, whether any value is invalid, and what happened."""

    fields: dict[str, object]
    invalid: bool
    outcome: str


def draw(rng: random.Random) -> tuple[dict[str, object], bool]:
    """One to three fields with a valid or an invalid value each: `(fields, any invalid)`."""
    names = rng.sample(sorted(VALID), rng.randint(1, 3))
    fields, invalid = {}, False
    for name in names:
        bad = rng.random() < 0.5
        fields[name] = rng.choice(INVALID[name] if bad else VALID[name])
        invalid |= bad
    return fields, invalid


def run_case(fields: dict[str, object], invalid: bool, graph: egnc.PoseGraph, method: str) -> str:
    """Build the options and, when they are accepted, solve `graph`; the outcome class."""
    solver = {name: value for name, value in fields.items() if name in SOLVER_FIELDS}
    gnc = {name: value for name, value in fields.items() if name not in SOLVER_FIELDS}
    try:
        with time_limit(TIME_LIMIT_S):
            options = egnc.SolverOptions(**solver)  # type: ignore[arg-type]
            gnc_options = egnc.GncOptions(**gnc)  # type: ignore[arg-type]
            if invalid:
                return "accepted invalid"
            result = egnc.solve(graph, method, linear_solver="scipy", options=options, gnc_options=gnc_options)
    except Hang:
        return "hang"
    except (EgncError, TypeError, ValueError) as error:
        if not invalid:
            return "solver error" if isinstance(error, EgncError) else "crash"
        named = any(f".{name} " in str(error) or f" {name} " in str(error) for name in fields)
        return "refused" if named and "\n" not in str(error) else "field not named"
    except Exception:  # noqa: BLE001 - the class of failure is the finding
        return "crash"
    finite = np.isfinite(result.graph.poses).all() and np.isfinite(result.residual_norms).all()
    return "finite" if finite or result.status == 5 else "non-finite result"


def fuzz_options(cases: int, seed: int) -> list[OptionsCase]:
    """Run `cases` option cases on the shipped 2D and 3D grids with false loops (first 30 poses)."""
    rng = random.Random(seed)
    graphs = [_small(name) for name in ("grid2d_outliers.g2o", "grid3d_outliers.g2o")]
    out = []
    for case in range(cases):
        fields, invalid = draw(rng)
        outcome = run_case(fields, invalid, graphs[case % 2], rng.choice(METHODS))
        out.append(OptionsCase(fields, invalid, outcome))
    return out


def _small(name: str, poses: int = 30) -> egnc.PoseGraph:
    graph = egnc.read_g2o(SHIPPED_DATASETS / name)
    return graph.subgraph_edges((graph.edges < poses).all(axis=1)).with_poses(graph.poses)


def table(results: list[OptionsCase]) -> str:
    """Markdown: per field, the cases that set it, by outcome class."""
    rows: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for case in results:
        for row in [*case.fields, "**all**"]:
            rows[row]["cases"] += 1
            rows[row]["with an invalid value"] += case.invalid
            rows[row][case.outcome] += 1
    return counts_table(rows, ["cases", "with an invalid value", *CLASSES], "field")


def run_target(cases: int, seed: int) -> tuple[str, int]:
    """The options target for `fuzz.py`: its table and the number of cases that are bugs."""
    results = fuzz_options(cases, seed)
    return table(results), sum(case.outcome in BAD for case in results)
