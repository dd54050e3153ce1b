"""The online solver's state as an `egnc.api.Result`, with the batch decision made on it.

The decision (`egnc.robust.decision.decide_outliers`: least squares on the accepted loops,
re-test, re-admission) is made from the online estimate, and again by `egnc.solve` on the whole
graph from its odometry; the batch one is kept only where its truncated cost is lower by more
than rounding (`lower_by_more_than_rounding`), as `egnc.solve` chooses between its starts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from egnc.api import Result, decided_fields, solve
from egnc.errors import GraphError
from egnc.graph import PoseGraph
from egnc.nonlinear.factors import from_matrices, to_matrices
from egnc.nonlinear.least_squares import STATUS_MESSAGES
from egnc.nonlinear.prior_factors import prior_cost
from egnc.online.options import Settings
from egnc.online.report import UpdateLog
from egnc.online.state import MapState
from egnc.robust.decision import decide_outliers, lower_by_more_than_rounding
from egnc.robust.factor_set import Factors, FactorSet, factor_dims
from egnc.robust.gnc import StageReport, classify_inliers
from egnc.robust.losses import KernelLoss
from egnc.robust.result import PriorDecision

__all__ = ["online_result"]


@dataclass(frozen=True, eq=False)
class _Decided:
    """The decision kept (fields as in `egnc.api.Result`); `poses` `(N, n, n)` in row order."""

    poses: np.ndarray
    inliers: np.ndarray
    settled: bool
    start: str
    status: int
    stages: tuple[StageReport, ...]
    disputed: np.ndarray
    note: str


def online_result(settings: Settings, state: MapState, log: UpdateLog, decide: bool) -> Result:
    """`state` as a `Result`, poses sorted by vertex id (`OnlineSolver.result`, which checks its
    arguments); `decide`: make the batch decision, else report the current robust estimate.

    Candidate priors join the edges in the decision's per-factor arrays (`egnc.robust.factor_set`),
    as in `egnc.solve`, and the result reports them apart (`Result.rejected_priors`)."""
    started = time.perf_counter()
    graph = state.graph()
    E = len(state.edges)
    # Priors that may be rejected join the edges in every per-factor array; known ones stay quadratic.
    factors: Factors = FactorSet.from_graph(graph, state.factors()) if state.robust[E:].any() else state.factors()
    F = len(state.r) if isinstance(factors, FactorSet) else E
    robust = state.robust[:F].copy()
    online_stage = _online_stage(settings, state, log)
    stages: tuple[StageReport, ...] = (online_stage,)
    poses = state.T
    robust_r = state.r[:E].copy()
    weights = KernelLoss(settings.kernel, state.mu, state.robust).weight(state.r)[:E]
    status = online_stage.status
    settled, start, note = True, "online", ""
    disputed: np.ndarray | None = None
    sorted_graph, order, new_row = _sorted_graph(state)
    decided = decide and robust.any()
    if decided:
        kept = _decision(settings, graph, factors, poses, robust, sorted_graph, new_row, online_stage.status)
        poses, inliers, settled, start, status = kept.poses, kept.inliers, kept.settled, kept.start, kept.status
        stages, disputed, note = stages + kept.stages, kept.disputed[:E], kept.note
    r = factors.whitened_norms(factors.residuals(poses))
    if not decided:
        inliers = classify_inliers(r, robust, factor_dims(graph, factors), settings.gnc_options)
    initial_r = factors.whitened_norms(factors.residuals(state.T_initial))[:E]
    priors = PriorDecision.of(factors, r, inliers, robust, settings.gnc_options.outlier_quantile)
    r, inliers, robust = r[:E], inliers[:E], robust[:E]
    result_poses = from_matrices(settings.dim, poses)[order]
    fields = decided_fields(
        sorted_graph,
        result_poses,
        initial_r,
        r,
        inliers,
        robust,
        stages,
        settings.gnc_options,
        start=start,
        settled=settled,
        disputed=disputed,
        priors=priors,
    )
    return Result(
        graph=sorted_graph.with_poses(result_poses),
        method=settings.method,
        linear_solver=settings.linear_solver,
        residual_norms=r,
        weights=weights,
        mu=np.where(state.robust, state.mu, np.nan)[:E],
        known_inliers=~robust,
        inliers=inliers,
        stages=stages,
        status=status,
        message=STATUS_MESSAGES.get(status, "no solve needed") + note,
        time_s=online_stage.time_s + time.perf_counter() - started,
        timings={},
        robust_residual_norms=robust_r,
        init="online",
        **fields,
        **({} if priors is None else priors.result_fields()),
    )


def _online_stage(settings: Settings, state: MapState, log: UpdateLog) -> StageReport:
    """One summary of all updates: the loops' `mu`, iterations, time, the last solve's status."""
    robust = state.robust
    mu_loops = state.mu[robust]
    return StageReport(
        float(mu_loops.min()) if len(mu_loops) else np.nan,
        float(mu_loops.mean()) if len(mu_loops) else np.nan,
        float(mu_loops.max()) if len(mu_loops) else np.nan,
        iterations=int(sum(log.update_iterations)),
        cost=float(np.sum(KernelLoss(settings.kernel, state.mu, robust).cost(state.r))),
        time_s=1e-3 * float(sum(log.update_ms)),
        status=log.last_status if log.last_status >= 0 else 1,
        active_edges=len(state.edges),
    )


def _sorted_graph(state: MapState) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """The graph with rows sorted by vertex id, as every `PoseGraph` egnc reads (edges keep
    insertion order), poses as placed at arrival; with `order` `(N,)` (sorted position -> row)
    and `new_row` `(N,)` (row -> sorted position)."""
    order = np.argsort(state.vertex_ids, kind="stable")
    new_row = np.empty_like(order)
    new_row[order] = np.arange(len(order))
    fixed = np.zeros(len(order), dtype=bool)
    # With priors the held pose is named even at row 0 (a graph with priors holds none by itself).
    fixed[new_row[state.gauge]] = state.held >= 0 and (new_row[state.gauge] != 0 or state.num_priors > 0)
    graph = PoseGraph(
        dim=state.dim,
        vertex_ids=state.vertex_ids[order],
        poses=from_matrices(state.dim, state.T_initial)[order],
        edges=new_row[state.edges],
        measurements=state.measurements,
        information=state.information,
        fixed=fixed,
        priors=state.priors.priors(new_row[state.priors.rows]),
    )
    return graph, order, new_row


def _decision(
    settings: Settings,
    graph: PoseGraph,
    factors: Factors,
    poses: np.ndarray,
    robust: np.ndarray,
    sorted_graph: PoseGraph,
    new_row: np.ndarray,
    status: int,
) -> _Decided:
    """The decision from the online estimate `poses` of `graph` (row order), or the batch
    solve's of `sorted_graph` where its truncated cost is lower by more than rounding.
    `robust`: `(F,)` the candidates among `factors`; `status`: the online stage's, kept when
    the decision solves nothing."""
    decision = decide_outliers(
        graph, poses, robust, settings.options, settings.gnc_options, settings.linear_solver, factors, start="online"
    )
    if decision.reports:
        status = decision.reports[-1].status
    known = np.ones(graph.num_edges + graph.num_priors, dtype=bool)  # priors not among `factors` are known
    known[: len(robust)] = ~robust
    batch = _batch_solve(settings, sorted_graph, known if graph.num_priors else ~robust)
    batch_inliers = (
        batch.inliers if batch.prior_inliers is None else np.concatenate((batch.inliers, batch.prior_inliers))
    )
    stages = decision.reports + batch.stages
    online_cost = decision.truncated_cost
    if graph.num_priors and not isinstance(factors, FactorSet):  # the batch's cost counts the known priors
        online_cost += prior_cost(graph.priors, from_matrices(settings.dim, decision.poses))
    if not lower_by_more_than_rounding(batch.truncated_cost, online_cost):
        disputed = robust & ~decision.inliers & batch_inliers
        return _Decided(decision.poses, decision.inliers, decision.settled, "online", status, stages, disputed, "")
    note = (
        f"; decision from the batch solve of the whole graph (truncated cost {batch.truncated_cost:.6g},"
        f" against {online_cost:.6g} from the online estimate)"
    )
    disputed = robust & ~batch_inliers & decision.inliers
    poses = to_matrices(settings.dim, batch.graph.poses)[new_row]
    return _Decided(poses, batch_inliers, batch.settled, batch.start, batch.status, stages, disputed, note)


def _batch_solve(settings: Settings, graph: PoseGraph, known: np.ndarray) -> Result:
    """`egnc.solve` of `graph` (vertex-sorted) with the `known` inliers (`(E,)`, or `(E + K,)`
    edges then priors) from its odometry composed from the gauge, or from the poses as placed
    at arrival where odometry does not reach every pose."""

    def batch(init: str) -> Result:
        return solve(
            graph,
            settings.method,
            known_inliers=known,
            linear_solver=settings.linear_solver,
            options=settings.options,
            gnc_options=settings.gnc_options,
            init=init,
        )

    try:
        return batch("odometry")
    except GraphError:  # a pose no odometry reaches
        return batch("file")
