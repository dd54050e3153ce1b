"""`egnc.solve`: one call from a pose graph (or a g2o file) to an optimized graph and its report."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TypedDict

import numpy as np

from egnc.errors import EgncError, GraphError, OptionError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_callable, check_choice, check_instance
from egnc.graph.health import check_representable
from egnc.io import read_g2o
from egnc.linalg.linear_solvers import resolve_name
from egnc.nonlinear.chordal import chordal_initialization
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.initialize import initialize_poses
from egnc.nonlinear.least_squares import (
    NOTHING_TO_OPTIMIZE,
    NUMERICAL_FAILURE,
    STATUS_MESSAGES,
    IterationCallback,
    Problem,
    SolverOptions,
)
from egnc.nonlinear.marginals import pose_covariances
from egnc.nonlinear.prior_factors import prior_cost
from egnc.robust.decision import Decision, StartContext, lower_by_more_than_rounding, truncated_cost
from egnc.robust.diagnostics import solve_warnings
from egnc.robust.elimination import elimination_decision
from egnc.robust.gnc import (
    GncOptions,
    GncOutcome,
    StageCallback,
    StageReport,
    StageStart,
    classify_inliers,
    iteration_limited,
    known_inlier_mask,
    run_gnc,
    stage_tolerance,
)
from egnc.robust.regroup import regrouped_decision, runs_start
from egnc.robust.schedules import GRADUATED_METHODS, METHODS, make_schedule
from egnc.robust.starts import all_edges_decision, chordal_decision, graduated_decision

__all__ = ["INITIALIZATIONS", "METHODS", "Result", "StageReport", "marginal_covariances", "solve"]

INITIALIZATIONS = ("file", "odometry", "chordal")
"""Initial guesses `egnc.solve(init=...)` and `egnc-solve --init` accept (see `initial_guess`)."""

_START_NAMES = {
    "guess": "initial guess",
    "runs": "GNC stage from the chordal map of the loop closures in runs",
    "chordal": "chordal initialization",
    "chordal-all": "GNC stage run again from the chordal initialization of every edge",
    "regrouped": "rejected runs of loop closures put back together",
    "elimination": "backward elimination over every edge",
}
"""How the message names the start whose decision was kept, and the first start it was compared with."""


@dataclass(frozen=True, eq=False)
class Result:
    """Outcome of `egnc.solve`.

    Attributes:
        graph: the input graph with optimized poses.
        method: the method used.
        linear_solver: the linear backend used, `"cholmod"`, `"rslab"` or `"scipy"`.
        residual_norms: `(E,)` whitened residual norms `r` at the solution (never kernel-scaled);
            for graduated methods the solution is the least-squares optimum of the accepted edges.
        weights: `(E,)` IRLS weight of each edge at the end of the last GNC stage of the first
            start (`stages[0].start`: the initial guess or the runs' map; 1 for known inliers and
            least squares).
        mu: `(E,)` final kernel parameter of each edge (nan for known inliers and for kernels
            without one).
        known_inliers: `(E,)` bool, edges held quadratic (odometry by default).
        inliers: `(E,)` bool, false for the loop closures rejected as outliers: for graduated
            methods the decision of `egnc.robust.decision` (`r^2 > chi2.ppf(q, d)` on the least-squares
            map of the accepted edges, q = `GncOptions.outlier_quantile`, 0.99 by default); for
            fixed kernels the same test at their solution; all true for `"l2"`.
        initial_cost: least-squares cost `0.5 sum r^2` at the initial guess.
        cost: least-squares cost `0.5 sum r^2` at the solution, over all edges (rejected ones too).
        accepted_cost: the same over the accepted edges only.
        truncated_cost: `egnc.robust.decision.truncated_cost` at the solution: accepted loops pay
            `r^2 / 2`, rejected ones `chi2.ppf(q, d) / 2`; the cost by which two decisions are
            compared.
        iterations: accepted solver steps over all stages.
        stages: per-stage reports; with `GncOptions.refine`, the last one is the least-squares
            refinement on the accepted edges (its `mu` statistics are nan).
        status: termination code of the last solve (1, 2, 3 mean converged; see
            `egnc.nonlinear.least_squares.STATUS_MESSAGES`).
        message: termination reason.
        time_s: wall time in seconds, from graph to result.
        timings: seconds per solver phase, summed over stages.
        robust_residual_norms: `(E,)` `r` where `weights` are taken, before the outlier
            decision (the robust optimum; equal to `residual_norms` for single-stage methods).
            With `residual_norms` it explains a rejection: a loop far off at both is false.
        init: the initial guess used (`INITIALIZATIONS`).
        start: where the decision that was kept started: `"guess"` (the GNC solve from `init`),
            `"runs"` (the GNC solve from the chordal map of the loops in runs, where that fits
            better than `init`; `GncOptions.runs_start`), `"chordal"` (the chordal
            initialization, kept for its lower truncated cost; `GncOptions.chordal_start`),
            `"chordal-all"` (the GNC stage run again from the chordal initialization of every
            edge; `GncOptions.chordal_all_start`), `"regrouped"`
            (rejected runs of loops put back together; `GncOptions.regroup_start`),
            `"elimination"` (backward elimination from least squares over every edge;
            `GncOptions.elimination_start`) or `"online"` (`egnc.online.OnlineSolver`'s estimate).
        warnings: one sentence per thing the user should check before trusting the result
            (a stage stopped at its iteration limit, most loop closures rejected, ...).
        settled: whether the kept decision's rounds reached a classification that no longer
            changed (`egnc.robust.decision.Decision.settled`); True where no decision was made.
    """

    graph: PoseGraph
    method: str
    linear_solver: str
    residual_norms: np.ndarray
    weights: np.ndarray
    mu: np.ndarray
    known_inliers: np.ndarray
    inliers: np.ndarray
    initial_cost: float
    cost: float
    iterations: int
    stages: tuple[StageReport, ...]
    status: int
    message: str
    time_s: float
    timings: dict[str, float]
    robust_residual_norms: np.ndarray
    accepted_cost: float
    truncated_cost: float
    warnings: tuple[str, ...] = ()
    init: str = "file"
    start: str = "guess"
    settled: bool = True

    def __repr__(self) -> str:
        loops = int(np.count_nonzero(~self.known_inliers))
        return (
            f"Result(method={self.method!r}, poses={self.graph.num_poses}, edges={self.graph.num_edges},"
            f" rejected={len(self.rejected_edges)} of {loops} loop closures, cost={self.cost:.6g},"
            f" stages={len(self.stages)}, iterations={self.iterations}, status={self.status}"
            f" ({self.message!r}), time_s={self.time_s:.3g}, warnings={len(self.warnings)})"
        )

    @property
    def converged(self) -> bool:
        """Whether the last solve and every stage of the kept start stopped on a convergence criterion."""
        return self.status in (1, 2, 3) and not iteration_limited(self.stages, self.start)

    @property
    def rejected_edges(self) -> np.ndarray:
        """0-based factor indices (`PoseGraph.edge_factor_index`: every edge and prior line in file
        order; the edge index when the graph has no prior) of the edges rejected as outliers."""
        return self.graph.edge_factor_index[~self.inliers]

    @property
    def rejected_priors(self) -> np.ndarray:
        """0-based factor indices of the priors rejected as outliers: none, priors are held as known inliers."""
        return np.zeros(0, dtype=np.int64)


class ResultCosts(TypedDict):
    """The cost fields of a `Result` (see its docstring)."""

    initial_cost: float
    cost: float
    accepted_cost: float
    truncated_cost: float


def result_costs(
    initial_r: np.ndarray, r: np.ndarray, inliers: np.ndarray, robust: np.ndarray, d: int, quantile: float
) -> ResultCosts:
    """The cost fields of a `Result` from `(E,)` residual norms at the guess and at the solution.

    Args:
        initial_r, r: `(E,)` whitened residual norms at the initial guess and at the solution.
        inliers: `(E,)` bool, the accepted edges.
        robust: `(E,)` bool, the loop closures.
        d: residual dimension.
        quantile: the outlier test's quantile (`GncOptions.outlier_quantile`).
    """
    return ResultCosts(
        initial_cost=float(0.5 * np.sum(initial_r**2)),
        cost=float(0.5 * np.sum(r**2)),
        accepted_cost=float(0.5 * np.sum(r[inliers] ** 2)),
        truncated_cost=truncated_cost(r, robust, d, quantile),
    )


class DecidedFields(ResultCosts):
    """The fields of a `Result` that follow from its decision (see its docstring)."""

    iterations: int
    warnings: tuple[str, ...]
    start: str
    settled: bool


def decided_fields(
    graph: PoseGraph,
    result_poses: np.ndarray,
    initial_r: np.ndarray,
    r: np.ndarray,
    inliers: np.ndarray,
    robust: np.ndarray,
    stages: tuple[StageReport, ...],
    gnc_options: GncOptions,
    *,
    start: str,
    settled: bool,
    disputed: np.ndarray | None,
) -> DecidedFields:
    """Costs, iteration count, warnings, start and settledness of a `Result`.

    Args:
        graph: the graph at its initial guess.
        result_poses: `(N, P)` the result's poses.
        initial_r, r: `(E,)` whitened residual norms at the initial guess and at `result_poses`.
        inliers: `(E,)` bool, the accepted edges.
        robust: `(E,)` bool, the loop closures.
        stages: every stage run (every start's included).
        gnc_options: the outlier test's options.
        start, settled, disputed: the kept decision's start, whether it settled, and the loops the
            other starts' decisions accepted where it rejects (None when only one start decided).
    """
    d = graph.tangent_dim
    initial_fits = classify_inliers(initial_r, robust, d, gnc_options)
    # The priors' cost (held quadratic in this release: never rejected) is part of every cost field.
    priors = (prior_cost(graph.priors, graph.poses), prior_cost(graph.priors, result_poses))
    warnings = solve_warnings(
        graph,
        stages,
        robust,
        inliers,
        initial_r,
        r,
        initial_fits,
        result_poses,
        start=start,
        settled=settled,
        disputed=disputed,
        prior_costs=priors,
    )
    costs = result_costs(initial_r, r, inliers, robust, d, gnc_options.outlier_quantile)
    if graph.num_priors:
        costs = ResultCosts(
            initial_cost=costs["initial_cost"] + priors[0],
            cost=costs["cost"] + priors[1],
            accepted_cost=costs["accepted_cost"] + priors[1],
            truncated_cost=costs["truncated_cost"] + priors[1],
        )
    return DecidedFields(
        **costs,
        iterations=sum(stage.iterations for stage in stages),
        warnings=warnings,
        start=start,
        settled=settled,
    )


def initial_guess(graph: PoseGraph, init: str, known_inliers: np.ndarray, linear_solver: str) -> np.ndarray:
    """`(N, P)` starting poses of a solve.

    Args:
        graph: the pose graph.
        init: `"file"`: the graph's poses (from the file; missing ones composed along a spanning
            tree when it was read). `"odometry"`: the known-inlier edges composed from the gauge
            pose(s), ignoring the file's other poses. `"chordal"`: `egnc.nonlinear.chordal`, rotations by the
            chordal relaxation then translations, over every edge: independent of odometry drift,
            but it trusts every loop closure, so false loops distort it (BENCHMARKS.md).
        known_inliers: `(E,)` bool, the edges `"odometry"` composes.
        linear_solver: resolved backend, for `"chordal"`.
    """
    if init == "file":
        return graph.poses
    if init == "chordal":
        return chordal_initialization(graph, linear_solver=linear_solver)
    if init == "odometry":
        gauge = graph.fixed if graph.fixed.any() else np.arange(graph.num_poses) == 0
        try:
            return initialize_poses(
                graph.dim, graph.edges[known_inliers], graph.measurements[known_inliers], poses=graph.poses, known=gauge
            )
        except GraphError as error:
            raise GraphError(f"init 'odometry': {error}; use init 'file' or 'chordal'") from None
    raise EgncError(f"unknown init {init!r}: choose one of {', '.join(INITIALIZATIONS)}")


def solve(
    graph: PoseGraph | str | Path,
    method: str = "egnc",
    *,
    known_inliers: str | np.ndarray = "odometry",
    init: str = "file",
    linear_solver: str = "auto",
    options: SolverOptions | None = None,
    gnc_options: GncOptions | None = None,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
) -> Result:
    """Optimize a pose graph, rejecting false loop closures with a robust method.

    Args:
        graph: a `PoseGraph`, or the path of a g2o file to read.
        method: one of `METHODS`: `"egnc"` (default), `"risam"`, `"gnc-gm"`, `"gnc-tls"`,
            `"huber"`, `"cauchy"`, `"gm"` or `"l2"` (plain least squares).
        known_inliers: edges that stay quadratic: `"odometry"` (consecutive ids, default),
            `"none"`, or an `(E,)` bool mask.
        init: the initial guess, one of `INITIALIZATIONS` (`initial_guess`): `"file"` (default:
            on every shared dataset, with or without false loops, it did at least as well as the
            others; `"chordal"` reaches better least-squares minima from a drifted guess but is
            distorted by false loops), `"odometry"` or `"chordal"`.
        linear_solver: `"auto"` (the first importable of CHOLMOD (scikit-sparse) and rslab, else
            SciPy), `"cholmod"`, `"rslab"` or `"scipy"`.
        options: options of each stage's GN/LM solve (tolerances, iteration limit).
        gnc_options: kernel shape, threshold convention, outlier quantile, stage limit.
        on_stage: called with each `StageReport` as soon as its stage ends (e.g. to show
            progress); the refinement rounds of graduated methods are stages too.
        on_iteration: called with `(iterations, cost)` after each accepted solver step of the
            running stage (live progress on long solves).

    Returns:
        The `Result`, whose `graph` holds the optimized poses.

    Raises:
        NumericalError: the graph cannot be solved in double precision (`egnc.graph.health`).
        OptionError: an argument has the wrong type or value (e.g. `GncOptions` given as
            `options`); it names the argument.

    A graph whose poses are all fixed has nothing to optimize: it is returned unchanged with
    status 6 (`NOTHING_TO_OPTIMIZE`, not "converged"), every edge accepted, and a warning.
    """
    started = time.perf_counter()
    check_choice("method", method, METHODS)
    check_choice("init", init, INITIALIZATIONS)
    options = SolverOptions() if options is None else options
    gnc_options = GncOptions() if gnc_options is None else gnc_options
    check_instance("options", options, SolverOptions)
    check_instance("gnc_options", gnc_options, GncOptions)
    check_callable("on_stage", on_stage)
    check_callable("on_iteration", on_iteration)
    if not isinstance(graph, PoseGraph):
        check_instance("graph", graph, (str, os.PathLike), "a PoseGraph or a g2o file path")
        graph = read_g2o(graph)
    known = known_inlier_mask(graph, known_inliers)
    robust = ~known
    backend = resolve_name(linear_solver)
    factors = BetweenFactors.from_graph(graph)
    check_representable(graph)
    if graph.fixed.all():
        return _nothing_to_optimize(graph, method, known, backend, factors, init, started, gnc_options)
    graph = graph.with_poses(initial_guess(graph, init, known, backend))
    initial = to_matrices(graph.dim, graph.poses)
    initial_r = factors.whitened_norms(factors.residuals(initial))
    refine = method in GRADUATED_METHODS and gnc_options.refine
    stage_options = options
    if refine:  # the refinement converges tightly; the stages need not
        stage_options = replace(options, rel_cost_tol=max(options.rel_cost_tol, stage_tolerance(method, gnc_options)))

    def graduate(start_poses: np.ndarray, start: StageStart = "guess") -> GncOutcome:
        """The GNC stages of `method` from `(N, n, n)` poses, with a schedule of their own."""
        schedule = make_schedule(method, robust, graph.tangent_dim, c=gnc_options.c, threshold=gnc_options.threshold)
        return run_gnc(
            graph,
            start_poses,
            schedule,
            robust,
            stage_options,
            gnc_options,
            backend,
            factors,
            on_stage,
            on_iteration,
            start=start,
        )

    context = StartContext(graph, robust, factors, options, gnc_options, backend, on_stage, on_iteration)
    runs = runs_start(context, initial) if refine and gnc_options.runs_start else None
    first: StageStart = "guess" if runs is None else "runs"
    outcome = graduate(initial if runs is None else runs.poses, first)
    poses, stages = outcome.poses, outcome.stages
    status, message = outcome.status, outcome.message
    robust_r = factors.whitened_norms(factors.residuals(poses))
    decide = refine and status != NUMERICAL_FAILURE  # nothing to decide on a failed solve
    start: str = first
    settled, message_note = True, ""
    disputed: np.ndarray | None = None
    if decide:
        decision = context.decide(poses, classify_inliers(robust_r, robust, graph.tangent_dim, gnc_options), first)
        stages += decision.reports
        candidates: dict[str, Decision] = {first: decision}
        bent = runs is not None and runs.contradicted(decision.inliers)  # the runs' map may be bent
        if bent:
            other, reports = graduated_decision(context, initial, "guess", graduate)
            stages += reports
            if other is not None:
                candidates["guess"] = other
        if gnc_options.chordal_start:
            trusted = ~robust | (outcome.weights >= options.trust_weight)
            best = min(candidates.values(), key=lambda candidate: candidate.truncated_cost)
            # After a runs start the chordal start classifies at the runs' chordal map (egnc.robust.starts).
            runs_map = runs.poses if runs is not None and not bent else None
            other, reports = chordal_decision(context, best, trusted, runs_map)
            stages += reports
            if other is not None:
                candidates["chordal"] = other
        later_starts = (
            ("chordal-all", gnc_options.chordal_all_start, partial(all_edges_decision, graduate=graduate)),
            ("regrouped", gnc_options.regroup_start, regrouped_decision),
            ("elimination", gnc_options.elimination_start, elimination_decision),
        )
        for name, enabled, decide_from in later_starts:  # each tries to beat the best decision so far
            if enabled:
                best = min(candidates.values(), key=lambda candidate: candidate.truncated_cost)
                other, reports = decide_from(context, best)
                stages += reports
                if other is not None:
                    candidates[name] = other
        for name, candidate in candidates.items():
            if lower_by_more_than_rounding(candidate.truncated_cost, candidates[start].truncated_cost):
                start = name
        decision = candidates[start]
        if start != first:
            message_note = (
                f"; decision from the {_START_NAMES[start]} (truncated cost {decision.truncated_cost:.6g},"
                f" against {candidates[first].truncated_cost:.6g} from the {_START_NAMES[first]})"
            )
        elif first != "guess":
            message_note = f"; decision from the {_START_NAMES[first]}"
        if len(candidates) > 1:
            accepted_elsewhere = np.logical_or.reduce([c.inliers for name, c in candidates.items() if name != start])
            disputed = robust & ~decision.inliers & accepted_elsewhere
        poses, inliers, settled = decision.poses, decision.inliers, decision.settled
        if decision.reports:
            status, message = decision.reports[-1].status, STATUS_MESSAGES[decision.reports[-1].status]
        message += message_note
    r = factors.whitened_norms(factors.residuals(poses))
    if not decide:
        inliers = classify_inliers(r, robust, graph.tangent_dim, gnc_options)
    if method == "l2":  # plain least squares: nothing is rejected
        inliers = np.ones(graph.num_edges, dtype=bool)
    result_poses = from_matrices(graph.dim, poses)
    return Result(
        graph=graph.with_poses(result_poses),
        method=method,
        linear_solver=backend,
        residual_norms=r,
        weights=outcome.weights,
        mu=outcome.mu,
        known_inliers=known,
        inliers=inliers,
        stages=stages,
        status=status,
        message=message,
        time_s=time.perf_counter() - started,
        timings=outcome.timings,
        robust_residual_norms=robust_r,
        init=init,
        **decided_fields(
            graph,
            result_poses,
            initial_r,
            r,
            inliers,
            robust,
            stages,
            gnc_options,
            start=start,
            settled=settled,
            disputed=disputed,
        ),
    )


def _nothing_to_optimize(
    graph: PoseGraph,
    method: str,
    known: np.ndarray,
    backend: str,
    factors: BetweenFactors,
    init: str,
    started: float,
    gnc_options: GncOptions,
) -> Result:
    """The `Result` of a graph whose poses are all fixed: the graph unchanged, no stage run, a warning."""
    r = factors.whitened_norms(factors.residuals(to_matrices(graph.dim, graph.poses)))
    inliers = np.ones(graph.num_edges, dtype=bool)
    return Result(
        graph=graph,
        method=method,
        linear_solver=backend,
        residual_norms=r,
        weights=np.ones(graph.num_edges),
        mu=np.full(graph.num_edges, np.nan),
        known_inliers=known,
        inliers=inliers,
        **result_costs(r, r, inliers, ~known, graph.tangent_dim, gnc_options.outlier_quantile),
        iterations=0,
        stages=(),
        status=NOTHING_TO_OPTIMIZE,
        message=STATUS_MESSAGES[NOTHING_TO_OPTIMIZE],
        time_s=time.perf_counter() - started,
        timings={},
        robust_residual_norms=r,
        warnings=(
            f"all {graph.num_poses} poses are fixed: there is nothing to optimize; the graph is returned "
            "unchanged and no edge is rejected",
        ),
        init=init,
    )


def marginal_covariances(result: Result, ids: np.ndarray | list[int] | None = None) -> np.ndarray:
    """Marginal covariances of chosen poses of a solve, from the information of its accepted edges.

    The Laplace approximation at the solution (as GTSAM's `Marginals`): the inverse of the
    Gauss-Newton information of the accepted edges, relative to the poses held fixed.

    Args:
        result: a finished solve.
        ids: vertex ids (as in the g2o file) of the poses wanted; None means every pose.

    Returns:
        `(K, d, d)` covariances of the right-perturbation tangent of each pose, order `[v, omega]`
        (translation first; GTSAM's `Pose3` uses `[omega, v]`), in metres and radians squared.
        Fixed poses get zeros.

    Raises:
        GraphError: an id is not a vertex of the graph.
        OptionError: `result` is not a `Result`, or `ids` not a 1-D sequence of integers.
    """
    check_instance("result", result, Result)
    graph = result.graph
    if ids is not None:
        try:
            requested = np.asarray(ids)
        except ValueError:  # ragged nesting
            requested = np.asarray(None)
        if requested.dtype.kind not in "iu" or requested.ndim > 1:
            raise OptionError(f"ids must be a vertex id or a 1-D sequence of them (integers), got {ids!r:.60}")
    ids = graph.vertex_ids if ids is None else np.asarray(ids, dtype=np.int64).reshape(-1)
    rows = np.searchsorted(graph.vertex_ids, ids)
    rows = np.minimum(rows, graph.num_poses - 1)
    missing = ids[graph.vertex_ids[rows] != ids]
    if len(missing):
        raise GraphError(f"marginal_covariances: no vertex with id {missing[:5].tolist()}")
    if graph.fixed.all():  # no unknowns: every covariance is zero
        return np.zeros((len(rows), graph.tangent_dim, graph.tangent_dim))
    problem = Problem.from_graph(graph.subgraph_edges(result.inliers), result.linear_solver)
    return pose_covariances(problem, to_matrices(graph.dim, graph.poses), rows)
