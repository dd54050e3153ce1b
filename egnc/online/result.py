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
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.least_squares import STATUS_MESSAGES
from egnc.online.options import Settings
from egnc.online.report import UpdateLog
from egnc.online.state import MapState
from egnc.robust.decision import decide_outliers, lower_by_more_than_rounding
from egnc.robust.gnc import StageReport, classify_inliers
from egnc.robust.losses import KernelLoss

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
    arguments); `decide`: make the batch decision, else report the current robust estimate."""
    started = time.perf_counter()
    graph = state.graph()
    factors = state.factors()
    robust = state.robust.copy()
    online_stage = _online_stage(settings, state, log)
    stages: tuple[StageReport, ...] = (online_stage,)
    poses = state.T
    robust_r = state.r.copy()
    weights = KernelLoss(settings.kernel, state.mu, robust).weight(robust_r)
    status = online_stage.status
    settled, start, note = True, "online", ""
    disputed: np.ndarray | None = None
    sorted_graph, order, new_row = _sorted_graph(state)
    decided = decide and robust.any()
    if decided:
        kept = _decision(settings, graph, factors, poses, robust, sorted_graph, new_row, online_stage.status)
        poses, inliers, settled, start, status = kept.poses, kept.inliers, kept.settled, kept.start, kept.status
        stages, disputed, note = stages + kept.stages, kept.disputed, kept.note
    r = factors.whitened_norms(factors.residuals(poses))
    if not decided:
        inliers = classify_inliers(r, robust, settings.d, settings.gnc_options)
    initial_r = factors.whitened_norms(factors.residuals(state.T_initial))
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
    )
    return Result(
        graph=sorted_graph.with_poses(result_poses),
        method=settings.method,
        linear_solver=settings.linear_solver,
        residual_norms=r,
        weights=weights,
        mu=np.where(state.robust, state.mu, np.nan),
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
    fixed[new_row[state.gauge]] = new_row[state.gauge] != 0
    graph = PoseGraph(
        dim=state.dim,
        vertex_ids=state.vertex_ids[order],
        poses=from_matrices(state.dim, state.T_initial)[order],
        edges=new_row[state.edges],
        measurements=state.measurements,
        information=state.information,
        fixed=fixed,
    )
    return graph, order, new_row


def _decision(
    settings: Settings,
    graph: PoseGraph,
    factors: BetweenFactors,
    poses: np.ndarray,
    robust: np.ndarray,
    sorted_graph: PoseGraph,
    new_row: np.ndarray,
    status: int,
) -> _Decided:
    """The decision from the online estimate `poses` of `graph` (row order), or the batch
    solve's of `sorted_graph` where its truncated cost is lower by more than rounding.
    `status`: the online stage's, kept when the decision solves nothing."""
    decision = decide_outliers(
        graph, poses, robust, settings.options, settings.gnc_options, settings.linear_solver, factors, start="online"
    )
    if decision.reports:
        status = decision.reports[-1].status
    batch = _batch_solve(settings, sorted_graph, robust)
    stages = decision.reports + batch.stages
    if not lower_by_more_than_rounding(batch.truncated_cost, decision.truncated_cost):
        disputed = robust & ~decision.inliers & batch.inliers
        return _Decided(decision.poses, decision.inliers, decision.settled, "online", status, stages, disputed, "")
    note = (
        f"; decision from the batch solve of the whole graph (truncated cost {batch.truncated_cost:.6g},"
        f" against {decision.truncated_cost:.6g} from the online estimate)"
    )
    disputed = robust & ~batch.inliers & decision.inliers
    poses = to_matrices(settings.dim, batch.graph.poses)[new_row]
    return _Decided(poses, batch.inliers, batch.settled, batch.start, batch.status, stages, disputed, note)


def _batch_solve(settings: Settings, graph: PoseGraph, robust: np.ndarray) -> Result:
    """`egnc.solve` of `graph` (vertex-sorted) from its odometry composed from the gauge, or
    from the poses as placed at arrival where odometry does not reach every pose."""

    def batch(init: str) -> Result:
        return solve(
            graph,
            settings.method,
            known_inliers=~robust,
            linear_solver=settings.linear_solver,
            options=settings.options,
            gnc_options=settings.gnc_options,
            init=init,
        )

    try:
        return batch("odometry")
    except GraphError:  # a pose no odometry reaches
        return batch("file")
