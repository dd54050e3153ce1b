"""`egnc.solve`: one call from a pose graph (or a g2o file) to an optimized graph and its report."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.errors import EgncError
from egnc.factors import from_matrices, to_matrices
from egnc.graph import PoseGraph
from egnc.io import read_g2o
from egnc.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.linear_solvers import resolve_name

METHODS = ("l2",)
"""Names accepted by `solve(method=...)`."""


@dataclass(frozen=True, eq=False)
class StageReport:
    """Summary of one solve stage (one GNC stage, or the single stage of a non-graduated method).

    Attributes:
        mu_min, mu_mean, mu_max: statistics of the loop closures' kernel parameter in the stage
            (0 for least squares).
        iterations: accepted solver steps.
        cost: cost at the end of the stage.
        time_s: wall time of the stage in seconds.
        status: solver termination code of the stage (see `egnc.least_squares.STATUS_MESSAGES`).
    """

    mu_min: float
    mu_mean: float
    mu_max: float
    iterations: int
    cost: float
    time_s: float
    status: int


@dataclass(frozen=True, eq=False)
class Result:
    """Outcome of `egnc.solve`.

    Attributes:
        graph: the input graph with optimized poses.
        method: the method used.
        linear_solver: the linear backend used, `"cholmod"` or `"scipy"`.
        residual_norms: `(E,)` whitened residual norms `r` at the solution (never kernel-scaled).
        initial_cost: least-squares cost `0.5 sum r^2` at the initial guess.
        cost: least-squares cost `0.5 sum r^2` at the solution.
        iterations: accepted solver steps over all stages.
        stages: per-stage reports.
        status: termination code of the last stage (1, 2, 3 mean converged).
        message: termination reason of the last stage.
        time_s: wall time in seconds, from graph to result.
        timings: seconds per solver phase, summed over stages.
    """

    graph: PoseGraph
    method: str
    linear_solver: str
    residual_norms: np.ndarray
    initial_cost: float
    cost: float
    iterations: int
    stages: tuple[StageReport, ...]
    status: int
    message: str
    time_s: float
    timings: dict[str, float]

    @property
    def converged(self) -> bool:
        """Whether the last stage stopped on a convergence criterion."""
        return self.status in (1, 2, 3)


def solve(
    graph: PoseGraph | str | Path,
    method: str = "l2",
    *,
    linear_solver: str = "auto",
    options: SolverOptions | None = None,
) -> Result:
    """Optimize a pose graph.

    Args:
        graph: a `PoseGraph`, or the path of a g2o file to read.
        method: one of `METHODS`.
        linear_solver: `"auto"` (CHOLMOD when scikit-sparse is importable, else SciPy),
            `"cholmod"` or `"scipy"`.
        options: solver options (GN or LM, tolerances, iteration limit).

    Returns:
        The `Result`, whose `graph` holds the optimized poses.
    """
    started = time.perf_counter()
    if method not in METHODS:
        raise EgncError(f"unknown method {method!r}: choose one of {', '.join(METHODS)}")
    if not isinstance(graph, PoseGraph):
        graph = read_g2o(graph)
    options = options or SolverOptions()
    backend = resolve_name(linear_solver)
    problem = Problem.from_graph(graph, backend)
    solution = solve_least_squares(problem, to_matrices(graph.dim, graph.poses), None, options)
    stage = StageReport(0.0, 0.0, 0.0, solution.iterations, solution.cost, solution.time_s, solution.status)
    return Result(
        graph=graph.with_poses(from_matrices(graph.dim, solution.poses)),
        method=method,
        linear_solver=backend,
        residual_norms=solution.residual_norms,
        initial_cost=float(solution.cost_history[0]),
        cost=solution.cost,
        iterations=solution.iterations,
        stages=(stage,),
        status=solution.status,
        message=solution.message,
        time_s=time.perf_counter() - started,
        timings=solution.timings,
    )
