"""What `egnc-solve` tells the user: the JSON report (fields documented in docs/cli.md) and the summary.

The report's layout carries a version, `schema_version`. It is raised whenever a field is renamed
or removed, or changes its type, unit or meaning; adding a field leaves it alone, so a reader
should ignore fields it does not know. A renamed field is also written under its old name, with
the same value, for one version: the version that renamed it lists it in the report's
`deprecated` object (old name -> new name) and the next version drops it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from egnc.api import Result
from egnc.graph.connectivity import describe_ids
from egnc.io.g2o_priors import counts_text
from egnc.online.replay import ReplayOutcome, latency_summary
from egnc.robust.gnc import StageReport, iteration_limited

SCHEMA_VERSION = 2
"""Version of the report's layout (module docstring). Version 1 had no `schema_version` field."""

DEPRECATED_NAMES = {
    "initial_cost": "initial_cost_all_edges",
    "final_cost": "final_cost_all_edges",
    "accepted_cost": "final_cost_accepted_edges",
}
"""Fields renamed in version 2 (old name -> new name), written under both names until version 3.

Version 2 named the costs by the edges they sum over: `Result.cost` includes the rejected loops,
the summary's figure leaves them out, and the two differ by far on a graph with outliers.
"""


def report_dict(result: Result, warnings: list[str], online: ReplayOutcome | None = None) -> dict[str, Any]:
    """The JSON report of a solve, strict JSON: non-finite numbers become null and add a warning.

    Args:
        result: the solve.
        warnings: what the reader warned about (`EgncWarning` messages); the result's own
            warnings and those about non-finite numbers are appended.
        online: the replay of an `--online` run, reported in an `online` object; None for a batch solve.
    """
    graph = result.graph
    report = {
        "schema_version": SCHEMA_VERSION,
        "method": result.method,
        "init": result.init,
        "linear_solver": result.linear_solver,
        "time_s": result.time_s,
        "initial_cost_all_edges": result.initial_cost,
        "final_cost_all_edges": result.cost,
        "final_cost_accepted_edges": result.accepted_cost,
        "truncated_cost": result.truncated_cost,
        "start": result.start,
        "iterations": result.iterations,
        "status": result.status,
        "message": result.message,
        "converged": result.converged,
        "poses": graph.num_poses,
        "edges": graph.num_edges,
        "loop_closures": int(graph.is_loop_closure.sum()),
        "known_inliers": int(result.known_inliers.sum()),
        "rejected_edges": result.rejected_edges.tolist(),
        "rejected": _rejected(result),
        "stages": [_stage(stage) for stage in result.stages],
        "timings_s": result.timings,
    }
    if graph.num_priors:  # factor indices count edges and priors in file order (docs/g2o.md)
        report.update(
            priors=graph.priors.counts(),
            prior_candidates=0 if result.prior_candidates is None else int(result.prior_candidates.sum()),
            rejected_priors=result.rejected_priors.tolist(),
        )
    if online is not None:
        report["online"] = _online(online)
    notes = [*warnings, *result.warnings]
    report = _nulls_for_non_finite(report, "", notes)
    report["warnings"] = notes
    # After the nulls, so that a non-finite value is named once, under its current name.
    report.update({old: report[new] for old, new in DEPRECATED_NAMES.items()})
    report["deprecated"] = dict(DEPRECATED_NAMES)
    return report


def _rejected_priors_line(result: Result) -> list[str]:
    """The summary's line on the priors, apart from the loops: none where priors were held quadratic."""
    if result.prior_candidates is None:
        return []
    return [f"rejected {len(result.rejected_priors)} of {int(result.prior_candidates.sum())} priors"]


def _rejected(result: Result) -> list[dict[str, Any]]:
    """The report's `rejected` list: each rejected edge with its vertex ids and its residual at both optima."""
    graph = result.graph
    return [
        {
            "edge": int(graph.edge_factor_index[k]),  # the factor index, as in `rejected_edges`
            "i": int(graph.vertex_ids[graph.edges[k, 0]]),
            "j": int(graph.vertex_ids[graph.edges[k, 1]]),
            "r_robust": float(result.robust_residual_norms[k]),
            "r": float(result.residual_norms[k]),
        }
        for k in np.flatnonzero(~result.inliers)
    ]


def _stage(stage: StageReport) -> dict[str, Any]:
    """One object of the report's `stages` list, from a `StageReport`."""
    return {
        "mu_min": _finite_or_none(stage.mu_min),
        "mu_mean": _finite_or_none(stage.mu_mean),
        "mu_max": _finite_or_none(stage.mu_max),
        "iterations": stage.iterations,
        "cost": stage.cost,
        "time_s": stage.time_s,
        "status": stage.status,
        "active_edges": stage.active_edges,
        "cg_iterations": stage.cg_iterations,
        "kind": stage.kind,
        "start": stage.start,
    }


def _online(outcome: ReplayOutcome) -> dict[str, Any]:
    """The report's `online` object: steps, resume point, time, iterations and update latency of a replay."""
    return {
        "steps": outcome.steps,
        "resumed_from": outcome.resumed_from,
        "total_s": outcome.total_s,
        "iterations": int(outcome.update_iterations.sum()),
        "update_ms": latency_summary(outcome.update_ms),
    }


def _finite_or_none(value: float) -> float | None:
    """Statistics that do not apply (NaN by design, e.g. `mu` of least squares) become null without a warning."""
    return value if math.isfinite(value) else None


def _nulls_for_non_finite(value: Any, where: str, notes: list[str]) -> Any:
    """A copy of a JSON-ready value with each non-finite float replaced by None, noting each one."""
    if isinstance(value, dict):
        return {
            key: _nulls_for_non_finite(item, f"{where}.{key}" if where else key, notes) for key, item in value.items()
        }
    if isinstance(value, list):
        return [_nulls_for_non_finite(item, f"{where}[{k}]", notes) for k, item in enumerate(value)]
    if isinstance(value, float) and not math.isfinite(value):
        notes.append(f"report field {where} is {value}, written as null")
        return None
    return value


def summary(result: Result, written: list[Path]) -> str:
    """A short human-readable summary of a solve: size, method, cost, termination, rejections, files."""
    graph = result.graph
    limited = iteration_limited(result.stages, result.start)
    if len(limited) == 1:
        stopped = f"iteration limit reached in stage {limited[0]}"
    elif limited:
        stopped = f"iteration limit reached in {len(limited)} stages: {describe_ids(np.array(limited))}"
    else:
        stopped = result.message
    if result.warnings:
        stopped += f"; warnings: {len(result.warnings)}, read them before trusting the result"
    lines = [
        f"poses {graph.num_poses}, edges {graph.num_edges}, loop closures {int(graph.is_loop_closure.sum())}"
        f"{', ' + counts_text(graph) if graph.num_priors else ''} ({graph.dim}D)",
        f"method {result.method}, linear solver {result.linear_solver}",
        f"least-squares cost {result.accepted_cost:.10g} over the {int(result.inliers.sum())} accepted edges"
        f"{f' and {graph.num_priors - len(result.rejected_priors)} priors' if graph.num_priors else ''}"
        f" ({result.cost:.10g} over all {graph.num_edges} edges, rejected ones included)",
        f"{len(result.stages)} stages, {result.iterations} iterations ({stopped})",
        f"rejected {len(result.rejected_edges)} of {int((~result.known_inliers).sum())} loop closures"
        f" (candidates: edges not known inliers)",
        *_rejected_priors_line(result),
        f"time {result.time_s:.3f} s",
    ]
    if written:
        lines.append(f"wrote {', '.join(map(str, written))}")
    return "\n".join(lines)
