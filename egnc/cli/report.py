"""What `egnc-solve` tells the user: the JSON report (fields documented in docs/cli.md) and the summary."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from egnc.api import Result
from egnc.graph.connectivity import describe_ids
from egnc.robust.gnc import iteration_limited


def report_dict(result: Result, warnings: list[str]) -> dict[str, Any]:
    """The JSON report of a solve, strict JSON: non-finite numbers become null and add a warning.

    Args:
        result: the solve.
        warnings: what the reader warned about (`EgncWarning` messages); the result's own
            warnings and those about non-finite numbers are appended.
    """
    graph = result.graph
    report = {
        "method": result.method,
        "init": result.init,
        "linear_solver": result.linear_solver,
        "time_s": result.time_s,
        # Named by the edges they sum over: `Result.cost` includes the rejected loops, the
        # summary's figure leaves them out, and the two differ by far on a graph with outliers.
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
        "rejected": [
            {
                "edge": int(k),
                "i": int(graph.vertex_ids[graph.edges[k, 0]]),
                "j": int(graph.vertex_ids[graph.edges[k, 1]]),
                "r_robust": float(result.robust_residual_norms[k]),
                "r": float(result.residual_norms[k]),
            }
            for k in result.rejected_edges
        ],
        "stages": [
            {
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
            for stage in result.stages
        ],
        "timings_s": result.timings,
    }
    notes = [*warnings, *result.warnings]
    report = _nulls_for_non_finite(report, "", notes)
    report["warnings"] = notes
    return report


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
        f" ({graph.dim}D)",
        f"method {result.method}, linear solver {result.linear_solver}",
        f"least-squares cost {result.accepted_cost:.10g} over the {int(result.inliers.sum())} accepted edges"
        f" ({result.cost:.10g} over all {graph.num_edges} edges, rejected ones included)",
        f"{len(result.stages)} stages, {result.iterations} iterations ({stopped})",
        f"rejected {len(result.rejected_edges)} of {int((~result.known_inliers).sum())} loop closures"
        f" (candidates: edges not known inliers)",
        f"time {result.time_s:.3f} s",
    ]
    if written:
        lines.append(f"wrote {', '.join(map(str, written))}")
    return "\n".join(lines)
