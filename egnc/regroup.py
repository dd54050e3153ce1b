"""Another start for the outlier decision: rejected loop closures that come in runs go back in together.

A robot that revisits a place closes loops on several consecutive keyframes, so true loop
closures come in runs: loops `(a, b)` and `(a', b')` with `|a - a'|` and `|b - b'|` both a few
poses. False loops drawn at random do not. When the GNC stage starts from a guess that has
drifted far, it can switch off a whole run of true loops where the drift is largest; the map then
tears there, both sides fit their own loops, and each loop of the run, tested alone against the
torn map, fails: no round of `egnc.decision` brings one back, since it would need the others
(a 100 000-pose grid with 30 % false loops: 830 true loops rejected, 721 of them in runs).

This start puts every run of at least `MIN_RUN` rejected loops back at once, solves the chordal
initialization (`egnc.chordal`) over the accepted edges and those runs, which closes the tear
without reading the torn map, classifies every loop there and decides from that classification
(`egnc.decision.decide_outliers`). The caller keeps the result only where its truncated cost is
lower. It costs one chordal solve and the decision rounds, and runs only where rejected runs
exist; a run of false loops (riSAM's "group" variant) bends the chordal map and loses the
comparison.

References:
    Y. Latif, C. Cadena, J. Neira, "Robust loop closing over time for pose graph SLAM", IJRR 2013
    (loop closures clustered by the time of their poses, judged as groups).
"""

from __future__ import annotations

import numpy as np

from egnc.chordal import chordal_initialization
from egnc.connectivity import connected_components
from egnc.decision import Decision, decide_outliers
from egnc.errors import SolverError
from egnc.factors import BetweenFactors, to_matrices
from egnc.gnc import GncOptions, StageCallback, StageReport, classify_inliers
from egnc.graph import PoseGraph
from egnc.least_squares import IterationCallback, SolverOptions

RUN_WINDOW = 10
"""Two loops belong to one run when both their ends are at most this many poses (rows) apart."""

MIN_RUN = 3
"""Fewest loops of a run that goes back in (random false loops of a 100 000-pose grid at 30 %
form pairs by chance, 26 of them, and no run of three)."""


def loop_runs(edges: np.ndarray, window: int = RUN_WINDOW) -> np.ndarray:
    """`(K,)` int label of the run of each loop `(K, 2)` (pose rows): loops linked by ends at most `window` apart.

    Runs are the connected components of "both ends within `window` poses", orientation ignored.
    """
    ends = np.sort(np.asarray(edges, dtype=np.int64), axis=1)
    order = np.lexsort((ends[:, 1], ends[:, 0]))
    a, b = ends[order, 0], ends[order, 1]
    links = []
    for shift in range(1, len(a)):  # loops `shift` apart in the order by first end
        near = a[shift:] - a[:-shift] <= window
        if not near.any():
            break
        linked = np.flatnonzero(near & (np.abs(b[shift:] - b[:-shift]) <= window))
        links.append(np.stack([order[linked], order[linked + shift]], axis=1))
    pairs = np.concatenate(links) if links else np.zeros((0, 2), dtype=np.int64)
    return connected_components(len(ends), pairs)[1]


def regrouped_decision(
    graph: PoseGraph,
    robust: np.ndarray,
    factors: BetweenFactors,
    to_beat: Decision,
    solver_options: SolverOptions,
    gnc_options: GncOptions,
    linear_solver: str,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision with `to_beat`'s rejected runs of loops put back together (module docstring).

    Args:
        graph: the pose graph.
        robust: `(E,)` bool, the loop closures that may be rejected.
        factors: the graph's factors.
        to_beat: the best decision of the other starts.
        solver_options: options of the decision rounds.
        gnc_options: outlier test and readmission options.
        linear_solver: resolved backend name.
        on_stage, on_iteration: progress callbacks (each round is a stage).

    Returns:
        `(decision, reports)`: the decision, or None where no run of `MIN_RUN` rejected loops
        exists or the chordal system cannot be factorized, and the reports of its rounds.
    """
    rejected = np.flatnonzero(robust & ~to_beat.inliers)
    labels = loop_runs(graph.edges[rejected])
    in_run = np.bincount(labels, minlength=1)[labels] >= MIN_RUN
    if not in_run.any():
        return None, ()
    regrouped = to_beat.inliers.copy()
    regrouped[rejected[in_run]] = True
    try:
        poses = to_matrices(
            graph.dim, chordal_initialization(graph.subgraph_edges(regrouped), linear_solver=linear_solver)
        )
    except SolverError:  # a chordal system the backend cannot factorize: no regrouped start
        return None, ()
    r = factors.whitened_norms(factors.residuals(poses))
    inliers = classify_inliers(r, robust, graph.tangent_dim, gnc_options)
    decision = decide_outliers(
        graph,
        poses,
        robust,
        solver_options,
        gnc_options,
        linear_solver,
        factors,
        on_stage,
        on_iteration,
        inliers,
        start="regrouped",
    )
    return decision, decision.reports
