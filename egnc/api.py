"""`egnc.solve`: one call from a pose graph (or a g2o file) to an optimized graph and its report.

The solve reads and checks its input, builds the initial guess, runs the GNC stage and decides
which loop closures are false through the starts of `GncOptions.starts`
(`egnc.robust.pipeline`), and returns a `Result` (`egnc.robust.result`).
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from egnc.errors import EgncError, GraphError, OptionError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_callable, check_choice, check_instance, check_vertex_ids
from egnc.graph.health import check_representable
from egnc.io import read_g2o
from egnc.linalg.linear_solvers import resolve_name
from egnc.nonlinear.chordal import chordal_initialization
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.initialize import initialize_poses
from egnc.nonlinear.least_squares import STATUS_MESSAGES, IterationCallback, Problem, SolverOptions
from egnc.nonlinear.marginals import pose_covariances
from egnc.nonlinear.prior_alignment import align_to_priors
from egnc.robust.decision import StartContext
from egnc.robust.factor_set import FactorSet
from egnc.robust.gnc import (
    GncOptions,
    GncOutcome,
    KnownInliers,
    StageCallback,
    StageReport,
    StageStart,
    classify_inliers,
    known_inlier_mask,
    run_gnc,
    stage_tolerance,
)
from egnc.robust.pipeline import Graduate, Search, search_decisions
from egnc.robust.result import PriorDecision, Result, decided_fields, nothing_to_optimize
from egnc.robust.schedules import GRADUATED_METHODS, METHODS, make_schedule

__all__ = [
    "INITIALIZATIONS",
    "METHODS",
    "Result",
    "StageReport",
    "decided_fields",  # egnc.robust.result's, named here as before it moved
    "marginal_covariances",
    "solve",
]

INITIALIZATIONS = ("file", "odometry", "chordal")
"""Initial guesses `egnc.solve(init=...)` and `egnc-solve --init` accept (see `initial_guess`)."""


def initial_guess(graph: PoseGraph, init: str, known_inliers: np.ndarray, linear_solver: str) -> np.ndarray:
    """`(N, P)` starting poses of a solve.

    Args:
        graph: the pose graph.
        init: `"file"`: the graph's poses (from the file; missing ones composed along a spanning
            tree when it was read). `"odometry"`: the known-inlier edges composed from the gauge
            pose(s), ignoring the file's other poses. `"chordal"`: `egnc.nonlinear.chordal`, rotations by the
            chordal relaxation then translations, over every edge: independent of odometry drift,
            but it trusts every loop closure, so false loops distort it (BENCHMARKS.md). With
            priors and no FIX line, both are moved rigidly onto the priors (a trimmed fit that
            wrong fixes do not drag, `egnc.nonlinear.prior_alignment`): a map in their frame.
        known_inliers: `(E,)` bool, the edges `"odometry"` composes.
        linear_solver: resolved backend, for `"chordal"`.
    """
    if init == "file":
        return graph.poses
    if init == "chordal":
        return _in_priors_frame(graph, chordal_initialization(graph, linear_solver=linear_solver))
    if init == "odometry":
        gauge = graph.fixed if graph.fixed.any() else np.arange(graph.num_poses) == 0
        try:
            chained = initialize_poses(
                graph.dim, graph.edges[known_inliers], graph.measurements[known_inliers], poses=graph.poses, known=gauge
            )
        except GraphError as error:
            raise GraphError(f"init 'odometry': {error}; use init 'file' or 'chordal'") from None
        return _in_priors_frame(graph, chained)
    raise EgncError(f"unknown init {init!r}: choose one of {', '.join(INITIALIZATIONS)}")


def _in_priors_frame(graph: PoseGraph, poses: np.ndarray) -> np.ndarray:
    """`(N, P)` `poses` moved onto the graph's priors (`egnc.nonlinear.prior_alignment`) where
    they set the frame: the graph has priors and no pose held by a FIX line."""
    if not graph.num_priors or graph.fixed.any():
        return poses
    return align_to_priors(graph, poses)


def solve(
    graph: PoseGraph | str | Path,
    method: str = "egnc",
    *,
    known_inliers: KnownInliers = "odometry",
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
        known_inliers: factors that stay quadratic, by kind: `"odometry"` (edges between
            consecutive ids, default), `"loops"` (the other edges), `"priors"`, several joined
            (`("odometry", "priors")` or `"odometry,priors"`), or `"none"`; or a bool mask,
            `(E,)` over the edges or `(E + K,)` over the edges then the priors. Priors not
            named are candidates for rejection like loop closures (`Result.rejected_priors`),
            each tested at its own dimension (a position prior's 2 or 3).
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
    options, gnc_options = _checked_arguments(method, init, options, gnc_options, on_stage, on_iteration)
    if not isinstance(graph, PoseGraph):
        check_instance("graph", graph, (str, os.PathLike), "a PoseGraph or a g2o file path")
        graph = read_g2o(graph)
    known = known_inlier_mask(graph, known_inliers)
    backend = resolve_name(linear_solver)
    between = BetweenFactors.from_graph(graph)
    check_representable(graph)
    known_edges = known[: graph.num_edges]
    if graph.fixed.all():
        return nothing_to_optimize(graph, method, known_edges, backend, between, init, started, gnc_options)
    graph = graph.with_poses(initial_guess(graph, init, known_edges, backend))
    # Priors that may be rejected join the edges in every per-factor array (egnc.robust.factor_set).
    factors = FactorSet.from_graph(graph, between) if len(known) > graph.num_edges else between
    context = StartContext(graph, ~known, factors, options, gnc_options, backend, on_stage, on_iteration)
    graduate = _graduation(context, method)
    initial = to_matrices(graph.dim, graph.poses)
    search: Search | None = None
    if method in GRADUATED_METHODS and gnc_options.refine:  # decide: the guess's GNC stage, then every start
        search = search_decisions(context, initial, graduate, gnc_options.starts)
    outcome = graduate(initial, "guess") if search is None else search.first
    assert outcome is not None
    return _result(context, method, init, outcome, _kept(search, outcome), started)


def _result(context: StartContext, method: str, init: str, outcome: GncOutcome, kept: _Kept, started: float) -> Result:
    """The `Result` of a solve on `context.graph` (at its initial guess) from its first GNC stage
    `outcome` and what it `kept`; `started` is the solve's `time.perf_counter()` reading."""
    graph, factors, robust, gnc_options = context.graph, context.factors, context.robust, context.gnc_options
    initial_r = factors.whitened_norms(factors.residuals(to_matrices(graph.dim, graph.poses)))
    robust_r = factors.whitened_norms(factors.residuals(outcome.poses))
    r = factors.whitened_norms(factors.residuals(kept.poses))
    inliers = kept.inliers
    if inliers is None:  # nothing decided: the outlier test at the solution
        inliers = classify_inliers(r, robust, context.dims, gnc_options)
    if method == "l2":  # plain least squares: nothing is rejected
        inliers = np.ones(len(r), dtype=bool)
    result_poses = from_matrices(graph.dim, kept.poses)
    priors = PriorDecision.of(factors, r, inliers, robust, gnc_options.outlier_quantile)
    E = graph.num_edges
    initial_r, robust_r, r, inliers, robust = initial_r[:E], robust_r[:E], r[:E], inliers[:E], robust[:E]
    weights, mu = outcome.weights[:E], outcome.mu[:E]
    decided = decided_fields(
        graph,
        result_poses,
        initial_r,
        r,
        inliers,
        robust,
        kept.stages,
        gnc_options,
        start=kept.start,
        settled=kept.settled,
        disputed=None if kept.disputed is None else kept.disputed[:E],
        priors=priors,
    )
    return Result(
        graph=graph.with_poses(result_poses),
        method=method,
        linear_solver=context.linear_solver,
        residual_norms=r,
        weights=weights,
        mu=mu,
        known_inliers=~robust,
        inliers=inliers,
        stages=kept.stages,
        status=kept.status,
        message=kept.message,
        time_s=time.perf_counter() - started,
        timings=outcome.timings,
        robust_residual_norms=robust_r,
        init=init,
        **decided,
        **({} if priors is None else priors.result_fields()),
    )


class _Kept(NamedTuple):
    """What a solve keeps from its GNC stage and decision (`_kept`)."""

    poses: np.ndarray
    inliers: np.ndarray | None
    stages: tuple[StageReport, ...]
    status: int
    message: str
    start: str
    settled: bool
    disputed: np.ndarray | None


def _kept(search: Search | None, outcome: GncOutcome) -> _Kept:
    """The poses, classification (None: not decided), stages, termination, start, settledness and
    disputed loops a solve reports, from its `search` of the starts (None without `refine`) and
    its first GNC stage `outcome`."""
    if search is None:
        return _Kept(outcome.poses, None, outcome.stages, outcome.status, outcome.message, "guess", True, None)
    if search.failed:  # nothing to decide on a failed solve
        return _Kept(
            outcome.poses, None, search.stages, outcome.status, outcome.message, search.first_start, True, None
        )
    start = search.kept()
    decision = search.candidates[start]
    status, message = outcome.status, outcome.message
    if decision.reports:
        status, message = decision.reports[-1].status, STATUS_MESSAGES[decision.reports[-1].status]
    message += search.note(start)
    return _Kept(
        decision.poses,
        decision.inliers,
        search.stages,
        status,
        message,
        start,
        decision.settled,
        search.disputed(start),
    )


def _checked_arguments(
    method: str,
    init: str,
    options: SolverOptions | None,
    gnc_options: GncOptions | None,
    on_stage: StageCallback | None,
    on_iteration: IterationCallback | None,
) -> tuple[SolverOptions, GncOptions]:
    """`solve`'s options with their defaults filled in, after checking its arguments' types and values."""
    check_choice("method", method, METHODS)
    check_choice("init", init, INITIALIZATIONS)
    options = SolverOptions() if options is None else options
    gnc_options = GncOptions() if gnc_options is None else gnc_options
    check_instance("options", options, SolverOptions)
    check_instance("gnc_options", gnc_options, GncOptions)
    check_callable("on_stage", on_stage)
    check_callable("on_iteration", on_iteration)
    return options, gnc_options


def _graduation(context: StartContext, method: str) -> Graduate:
    """The GNC stages of `method` on `context`'s graph as a function of the `(N, n, n)` poses they
    start from and the start they belong to; each run gets a schedule of its own."""
    graph, robust, options, gnc_options = context.graph, context.robust, context.solver_options, context.gnc_options
    stage_options = options
    if method in GRADUATED_METHODS and gnc_options.refine:  # the refinement converges tightly; the stages need not
        stage_options = replace(options, rel_cost_tol=max(options.rel_cost_tol, stage_tolerance(method, gnc_options)))

    def graduate(start_poses: np.ndarray, start: StageStart = "guess") -> GncOutcome:
        schedule = make_schedule(method, robust, context.dims, c=gnc_options.c, threshold=gnc_options.threshold)
        return run_gnc(
            graph,
            start_poses,
            schedule,
            robust,
            stage_options,
            gnc_options,
            context.linear_solver,
            context.factors,
            context.on_stage,
            context.on_iteration,
            start=start,
        )

    return graduate


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
    ids = graph.vertex_ids if ids is None else check_vertex_ids("ids", ids).reshape(-1)
    rows = np.searchsorted(graph.vertex_ids, ids)
    rows = np.minimum(rows, graph.num_poses - 1)
    missing = ids[graph.vertex_ids[rows] != ids]
    if len(missing):
        raise GraphError(f"marginal_covariances: no vertex with id {missing[:5].tolist()}")
    if graph.fixed.all():  # no unknowns: every covariance is zero
        return np.zeros((len(rows), graph.tangent_dim, graph.tangent_dim))
    problem = Problem.from_graph(graph.subgraph_edges(result.inliers), result.linear_solver)
    return pose_covariances(problem, to_matrices(graph.dim, graph.poses), rows, graph.vertex_ids)
