"""Warnings about a finished solve: what a user should check before trusting the result.

Each check is cheap and reads only what the solve already computed. The wording names the
number behind the warning and, where there is one, what to try.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from egnc.graph import PoseGraph
from egnc.metrics import ate
from egnc.robust.gnc import StageReport, iteration_limited
from egnc.robust.kernels import chi2_quantile

MOVED_FRACTION = 0.05
"""A result "far" from a consistent initial guess: ATE above this fraction of the trajectory's extent."""

KNOWN_INLIER_FACTOR = 100.0
"""A known inlier "disagrees" when its `r^2` exceeds this many times `chi2.ppf(0.99, d)` at the result:
the clean shared files stay below 5x, except sphere_a (2000x), whose information matrices are far
too confident; a 1000 m error on one sphere2500 odometry edge spreads over 20 edges above 100x."""


def solve_warnings(
    graph: PoseGraph,
    stages: Sequence[StageReport],
    robust: np.ndarray,
    inliers: np.ndarray,
    initial_r: np.ndarray,
    final_r: np.ndarray,
    initial_fits: np.ndarray,
    result_poses: np.ndarray,
    *,
    start: str = "guess",
    settled: bool = True,
    disputed: np.ndarray | None = None,
    prior_costs: tuple[float, float] = (0.0, 0.0),
) -> tuple[str, ...]:
    """The warnings of one solve, in the order the checks run.

    Args:
        graph: the input graph (its poses are the initial guess).
        stages: per-stage reports, decision rounds and both starts included.
        robust: `(E,)` bool, loop closures that could be rejected.
        inliers: `(E,)` bool, the final classification.
        initial_r, final_r: `(E,)` whitened residual norms at the initial guess and the result.
        initial_fits: `(E,)` bool, edges that pass the outlier test at the initial guess.
        result_poses: `(N, P)` optimized poses in the graph's parametrization.
        start: the start whose decision was kept (only its stages count: `egnc.robust.gnc.iteration_limited`).
        settled: whether the outlier decision reached a classification its own map confirms
            (`egnc.robust.decision.Decision.settled`).
        disputed: `(E,)` bool, loops the kept decision rejects and another start's decision
            accepted (`egnc.robust.starts`, `egnc.robust.elimination`); None when only one start decided.
        prior_costs: the priors' cost `0.5 sum r^2` at the initial guess and at the result.
    """
    warnings = [
        f"stage {k} stopped at its iteration limit ({stages[k - 1].iterations} iterations): the result may not"
        " have converged (raise --max-iters)"
        for k in iteration_limited(stages, start)
    ]
    if not settled:
        warnings.append(
            "the outlier decision did not settle: its last least-squares map still disagrees with the"
            " classification (rounds ran out, or a round hit its iteration limit); treat the rejected set"
            " as provisional"
        )
    if disputed is not None and disputed.any():
        ids = np.flatnonzero(disputed)
        warnings.append(
            f"{len(ids)} rejected loop closures (edges {_listed(ids)}) were accepted by the decision from another"
            " start, whose truncated cost is higher: two explanations of this graph disagree on them; check them,"
            " and the known inliers and the initial guess"
        )
    num_loops = int(np.count_nonzero(robust))
    num_rejected = int(np.count_nonzero(robust & ~inliers))
    if num_rejected > 0.5 * num_loops:
        warnings.append(
            f"{num_rejected} of {num_loops} loop closures were rejected (more than half): either most are false,"
            " or the information matrices are far too confident for this data, or the initial guess is poor"
        )
    initial_cost = 0.5 * float(np.sum(initial_r[inliers] ** 2)) + prior_costs[0]
    final_cost = 0.5 * float(np.sum(final_r[inliers] ** 2)) + prior_costs[1]
    if final_cost > initial_cost:
        priors = " and the priors" if any(prior_costs) else ""
        warnings.append(
            f"the least-squares cost over the accepted edges{priors} rose from {initial_cost:.6g} at the initial guess"
            f" to {final_cost:.6g}: the solve made the guess worse"
        )
    warnings += _known_inliers_disagree(graph, ~robust, final_r)
    if num_loops and np.all(initial_fits[robust]):
        warnings += _moved_far(graph, result_poses)
    return tuple(warnings)


def _known_inliers_disagree(graph: PoseGraph, known: np.ndarray, final_r: np.ndarray) -> list[str]:
    """The warning, if any, about known inliers `known` `(E,)` whose `r^2` at the result exceeds
    `KNOWN_INLIER_FACTOR` times `chi2.ppf(0.99, d)`."""
    bound = KNOWN_INLIER_FACTOR * chi2_quantile(0.99, graph.tangent_dim)
    if not np.any(final_r[known] ** 2 > bound):
        return []
    worst = np.flatnonzero(known)[np.argmax(final_r[known])]
    i, j = graph.vertex_ids[graph.edges[worst]]
    return [
        f"{int(np.count_nonzero(final_r[known] ** 2 > bound))} known-inlier edges (odometry) disagree with the"
        f" map: edge {worst} ({i} -> {j}) has r^2 = {final_r[worst] ** 2:.3g}, over {bound:.3g}; a corrupted"
        " measurement, or information matrices far too confident"
    ]


def _moved_far(graph: PoseGraph, result_poses: np.ndarray) -> list[str]:
    """The warning, if any, that the result `(N, P)` moved more than `MOVED_FRACTION` of the
    trajectory's extent from the initial guess (asked where every loop fits that guess)."""
    extent = _extent(graph.poses, graph.dim)
    moved = ate(result_poses, graph.poses, graph.dim)
    if not (extent > 0 and moved > MOVED_FRACTION * extent):
        return []
    return [
        f"every loop closure fits the initial guess, yet the result moved {moved:.3g} m (ATE) from it,"
        f" {100 * moved / extent:.1f}% of the trajectory's extent"
    ]


def _listed(ids: np.ndarray, most: int = 5) -> str:
    """`ids` as `"3, 7, 9"`, the first `most` of them and a count of the rest."""
    shown = ", ".join(str(int(k)) for k in ids[:most])
    return shown if len(ids) <= most else f"{shown} and {len(ids) - most} more"


def _extent(poses: np.ndarray, dim: int) -> float:
    """Diagonal of the bounding box of the positions in `poses` `(N, P)`, in metres."""
    positions = poses[:, :dim]
    return float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
