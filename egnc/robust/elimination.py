"""A third start for the outlier decision: least squares over every edge, then backward elimination.

Where the map is weakly constrained (long odometry chains, few loop closures: MIT's 808 poses and
20 loops), a false loop closure hides in its residual. Least squares over every edge bends the
map to fit it (a false MIT loop ends at `r^2 = 0.08`), so every loop passes the chi-square test;
the robust stage from a poor guess instead lets honest loops go that the guess does not fit
(13 of MIT's 20 with 2 false loops added), and the decision rounds cannot bring them back,
because the map without them is too weak to vouch for them (`egnc.robust.decision`). Neither the guess
nor the chordal start (`egnc.robust.starts`) reaches the map of the honest loops.

What sees such a loop is its deletion statistic: the innovation of its measurement against the
map of every other edge. At a least-squares solution that includes the loop it is
`e^T (Omega^-1 - C)^-1 e`, with `e` its residual and `C = A H^-1 A^T` the covariance of the
residual the map predicts (`egnc.nonlinear.marginals.relative_covariances`; in regression terms the
externally studentized residual). It is never smaller than `r^2`, it is chi-square with `d`
degrees of freedom for an honest loop of a linear model, and it is large for a loop that the
map can only fit because the loop bends it (MIT: 208 and 146 for the two false loops).

From the chordal initialization of every edge (`egnc.nonlinear.chordal`), the start:

1. solves least squares over the accepted edges (every edge at first);
2. computes the deletion statistic of every accepted loop and, if the largest exceeds
   `chi2.ppf(q, d)`, rejects that loop alone and returns to 1: one false loop inflates the
   statistics of the honest loops it bends, so they are judged again without it;
3. decides from that classification (`egnc.robust.decision.decide_outliers`, with re-admission).

The caller keeps the result only where its truncated cost is lower than the other starts'.

The start runs only where it can change something and its worst case is small:

- the best decision so far rejected a loop that re-admission could neither take nor refute
  (`undecided`): it agrees with the map only within the map's own large uncertainty of its
  relative pose. MIT's 13 wrongly rejected loops are all of this kind; a stiff map's false
  loops are refuted outright (csail, kitti_00, intel, smallGrid3D with 10-30 % false loops:
  none undecided).
- each step costs a least-squares solve and `2 d` covariance columns per accepted loop. Every
  rejected loop adds `chi2.ppf(q, d) / 2` to the truncated cost, so past `2 c / chi2.ppf(q, d)`
  steps it cannot beat a decision of truncated cost `c`; that bound times the number of loop
  closures must stay within `STEP_BUDGET`. Graphs with many loops are stiff enough that false
  loops show in their residuals, and the other starts decide.

References:
    R. D. Cook, "Detection of influential observation in linear regression", Technometrics 1977.
    Y. Latif, C. Cadena, J. Neira, "Robust loop closing over time for pose graph SLAM", IJRR 2013
    (loop closures that only a weak map lets pass).
"""

from __future__ import annotations

import time

import numpy as np

from egnc.graph import PoseGraph
from egnc.linalg.linear_solvers import NotPositiveDefiniteError
from egnc.nonlinear.factors import BetweenFactors
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, Problem, solve_least_squares
from egnc.nonlinear.marginals import relative_covariances
from egnc.robust.decision import Decision, StartContext, least_squares_report, map_credit, readmit_quantile
from egnc.robust.factor_set import edge_factors
from egnc.robust.gnc import GncOptions, StageReport, announce_stage
from egnc.robust.kernels import chi2_quantile

STEP_BUDGET = 4096
"""Largest (loop closures x possible elimination steps) for which the start runs: each step
computes the covariance of every accepted loop (MIT with 50 % false loops: 40 x 34)."""


def deletion_statistics(problem: Problem, poses: np.ndarray, loops: BetweenFactors) -> np.ndarray:
    """`(K,)` innovation statistic of each of `loops` against the map of the other edges of `problem`.

    `loops` must be edges of `problem`, solved at `poses` `(N, n, n)`. A loop that the rest of the
    graph does not constrain at all (a bridge: leverage 1, `Omega^-1 - C` singular) cannot be
    contradicted and gets 0.

    Raises:
        NotPositiveDefiniteError: the information of `problem` cannot be factorized.
    """
    # In whitened coordinates (`Omega = W W^T`): `e_w = W^T e`, leverage `h = W^T C W`, and the
    # statistic is `e_w^T (I - h)^-1 e_w`; a bridge has a leverage eigenvalue of 1.
    W = np.linalg.cholesky(loops.information)
    e_w = np.einsum("kji,kj->ki", W, loops.residuals(poses))
    leverage = np.swapaxes(W, 1, 2) @ relative_covariances(problem, poses, loops) @ W
    deleted = np.eye(e_w.shape[1]) - 0.5 * (leverage + np.swapaxes(leverage, 1, 2))
    testable = np.linalg.eigvalsh(deleted)[:, 0] > 1e-9
    statistics = np.zeros(len(e_w))
    statistics[testable] = np.einsum(
        "ki,ki->k", e_w[testable], np.linalg.solve(deleted[testable], e_w[testable][:, :, None])[:, :, 0]
    )
    return statistics


def undecided(
    graph: PoseGraph,
    robust: np.ndarray,
    factors: BetweenFactors,
    decision: Decision,
    gnc_options: GncOptions,
    linear_solver: str,
) -> np.ndarray:
    """`(R,)` bool for the loops `decision` rejected (edge order): re-admission could neither take nor refute it.

    Such a loop agrees with the decision's map (innovation statistic at most
    `chi2.ppf(readmit_quantile, d)`) only because the map does not determine its relative pose:
    with the map credited no more uncertainty of it than the loop's own
    (`egnc.robust.decision.map_credit`), the statistic exceeds that threshold. The map is too weak to
    judge it.
    """
    rejected = np.flatnonzero(robust & ~decision.inliers)
    if not len(rejected):
        return np.zeros(0, dtype=bool)
    loops = factors.subset(rejected)
    try:
        problem = Problem.from_graph(
            graph.subgraph_edges(decision.inliers), linear_solver, factors.subset(decision.inliers)
        )
        relative = relative_covariances(problem, decision.poses, loops)
    except NotPositiveDefiniteError:  # no covariance at a degenerate solution: nothing to judge by
        return np.zeros(len(rejected), dtype=bool)
    e = loops.residuals(decision.poses)
    own = np.linalg.inv(loops.information)
    threshold = chi2_quantile(readmit_quantile(gnc_options, robust), graph.tangent_dim)
    credit = map_credit(relative, own)[:, None, None]
    full, capped = (
        np.einsum("ki,ki->k", e, np.linalg.solve(S, e[:, :, None])[:, :, 0])
        for S in (own + relative, own + credit * relative)
    )
    return (full <= threshold) & (capped > threshold)


def elimination_decision(context: StartContext, to_beat: Decision) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision started by backward elimination over every edge, unless it cannot beat `to_beat` (module docstring).

    Args:
        context: the graph, its factors, options and callbacks (each elimination step and each
            round is a stage).
        to_beat: the best decision of the other starts.

    Returns:
        `(decision, reports)`: the decision, or None where the start did not run or stopped
        early (nothing undecided, over budget, no chordal map, a failed solve, past the step
        bound), and the reports of every solve run here.
    """
    graph, robust, gnc_options = context.graph, context.robust, context.gnc_options
    factors = edge_factors(context.factors)  # a start of loop closures alone (egnc.robust.pipeline)
    d, q = graph.tangent_dim, gnc_options.outlier_quantile
    threshold = chi2_quantile(q, d)
    max_steps = int(2.0 * to_beat.truncated_cost / threshold)
    if int(np.count_nonzero(robust)) * max(max_steps, 1) > STEP_BUDGET:
        return None, ()
    if not undecided(graph, robust, factors, to_beat, gnc_options, context.linear_solver).any():
        return None, ()
    accepted = np.ones(graph.num_edges, dtype=bool)
    poses = context.chordal_poses(accepted)
    if poses is None:  # a chordal system the backend cannot factorize: no elimination start
        return None, ()
    reports: list[StageReport] = []
    for _ in range(max_steps + 1):
        started = time.perf_counter()
        problem = Problem.from_graph(graph.subgraph_edges(accepted), context.linear_solver, factors.subset(accepted))
        solved = solve_least_squares(problem, poses, None, context.solver_options, context.on_iteration)
        poses = solved.poses
        reports.append(least_squares_report(solved, started, int(accepted.sum()), "elimination", "elimination"))
        announce_stage(context.on_stage, reports[-1], poses)
        if solved.status == NUMERICAL_FAILURE:
            return None, tuple(reports)
        loops = np.flatnonzero(accepted & robust)
        try:
            statistics = deletion_statistics(problem, poses, factors.subset(loops))
        except NotPositiveDefiniteError:  # no covariance at a degenerate solution
            return None, tuple(reports)
        if not len(loops) or statistics.max() <= threshold:
            break
        accepted[loops[np.argmax(statistics)]] = False
    else:
        return None, tuple(reports)  # past the step bound: it cannot beat `to_beat`
    decision = context.decide(poses, accepted, "elimination")
    return decision, (*reports, *decision.reports)
