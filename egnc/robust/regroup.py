"""Another start for the outlier decision: rejected loop closures that come in runs go back in together.

A robot that revisits a place closes loops on several consecutive keyframes, so true loop
closures come in runs: loops `(a, b)` and `(a', b')` with `|a - a'|` and `|b - b'|` both a few
poses. False loops drawn at random do not. When the GNC stage starts from a guess that has
drifted far, it can switch off a whole run of true loops where the drift is largest; the map then
tears there, both sides fit their own loops, and each loop of the run, tested alone against the
torn map, fails: no round of `egnc.robust.decision` brings one back, since it would need the others
(a 100 000-pose grid with 30 % false loops: 830 true loops rejected, 721 of them in runs).

Loops are linked into a run when both their ends are within `RUN_WINDOW` poses and they agree
with each other through the map between their ends (`consistent_pairs`: a chi-square test of
the cycle the two loops close, at `GncOptions.readmit_quantile`). This start puts every run of at
least `MIN_RUN` rejected loops back at once, solves the chordal
initialization (`egnc.nonlinear.chordal`) over the accepted edges and those runs, which closes the tear
without reading the torn map, classifies every loop there and decides from that classification
(`egnc.robust.decision.decide_outliers`). The caller keeps the result only where its truncated cost is
lower. It costs one chordal solve and the decision rounds, and runs only where rejected runs
exist; a run of false loops (riSAM's "group" variant) bends the chordal map and loses the
comparison.

The same runs give the GNC stage a start of its own (`runs_start`, the `"runs"` of `GncOptions.starts`).
From a guess that has drifted far the stage settles where the drift puts it, and tears the map
there (above); the starts after it repair the decision at the price of their own rounds (a
100 000-pose grid at 30 %: 47.6 s against 3.1 s clean, the regrouped start deciding). Before
the stage, the loops of the initial guess are linked into runs the same way: the test reads the
guess only between poses a few rows apart, which drift leaves intact, and random false loops
rarely join a run of `MIN_RUN` (none of 24 000 on that grid). The chordal initialization of the
known inliers and the loops in runs is then a drift-free map; the GNC stage starts there where its
truncated cost is lower than the guess's (the guess of a graph without drift stays). False loops
that agree with each other (riSAM's "group" variant) do form runs and bend that map; the decision
from it then rejects whole runs it had assumed true (`RunsStart.contradicted`), and the caller
decides from the guess as well.

References:
    Y. Latif, C. Cadena, J. Neira, "Robust loop closing over time for pose graph SLAM", IJRR 2013
    (loop closures clustered by the time of their poses, judged as groups).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.graph.connectivity import connected_components
from egnc.nonlinear.factors import BetweenFactors, group_of
from egnc.robust.decision import Decision, StartContext, readmit_quantile
from egnc.robust.factor_set import edge_factors
from egnc.robust.gnc import StageReport, classify_inliers
from egnc.robust.kernels import chi2_quantile

RUN_WINDOW = 10
"""Two loops belong to one run when both their ends are at most this many poses (rows) apart."""

MIN_RUN = 3
"""Fewest loops of a run that goes back in (random false loops of a 100 000-pose grid at 30 %
form pairs by chance, 26 of them, and no run of three)."""


def neighbouring_pairs(edges: np.ndarray, window: int = RUN_WINDOW) -> np.ndarray:
    """`(P, 2)` index pairs of loops `(K, 2)` (pose rows) whose ends are both at most `window` poses apart.

    Orientation is ignored: `(a, b)` and `(b', a')` are compared end to end.
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
    return np.concatenate(links) if links else np.zeros((0, 2), dtype=np.int64)


def consistent_pairs(loops: BetweenFactors, poses: np.ndarray, pairs: np.ndarray, threshold: float) -> np.ndarray:
    """`(P,)` bool: the two loops of each pair agree with each other through the map near their ends.

    With both loops oriented from their lower pose row, `(i1, j1)` and `(i2, j2)`, the cycle
    `Z1^-1 (X_i1^-1 X_i2) Z2 (X_j2^-1 X_j1)` is the identity when both measure the truth; it reads
    the map only between poses a few rows apart, which a tear elsewhere leaves intact. Its log is
    tested against `threshold` (a chi-square quantile) with the loops' covariances added (the
    short stretches of map between the ends are taken as exact, and the covariances untransported).

    Args:
        loops: the `K` loop closures.
        poses: `(N, n, n)` the map.
        pairs: `(P, 2)` indices into `loops`.
        threshold: chi-square quantile for `d` degrees of freedom.
    """
    group = group_of(loops.dim)
    flip = loops.edges[:, 0] > loops.edges[:, 1]
    i = np.where(flip, loops.edges[:, 1], loops.edges[:, 0])
    j = np.where(flip, loops.edges[:, 0], loops.edges[:, 1])
    Z_inv = np.where(flip[:, None, None], group.inverse(loops.Z_inv), loops.Z_inv)  # oriented i -> j
    Z = group.inverse(Z_inv)  # once per loop: a loop is in many pairs
    first, second = pairs[:, 0], pairs[:, 1]
    cycle = (
        Z_inv[first]
        @ group.between(poses[i[first]], poses[i[second]])
        @ Z[second]
        @ group.between(poses[j[second]], poses[j[first]])
    )
    e = group.log(cycle)
    own = np.linalg.inv(loops.information)
    covariance = own[first] + own[second]
    statistics = np.einsum("pi,pi->p", e, np.linalg.solve(covariance, e[:, :, None])[:, :, 0])
    return statistics <= threshold


def loop_runs(loops: BetweenFactors, poses: np.ndarray, threshold: float, window: int = RUN_WINDOW) -> np.ndarray:
    """`(K,)` int run label of each loop: components of neighbouring loops that agree with each other.

    `neighbouring_pairs` proposes the links and `consistent_pairs` keeps those whose cycle through
    the map `poses` passes `threshold`: random false loops that happen to lie side by side do not
    agree (on parking-garage with 50 % false loops, 2674 of them fell into runs by position alone).
    """
    pairs = neighbouring_pairs(loops.edges, window)
    pairs = pairs[consistent_pairs(loops, poses, pairs, threshold)] if len(pairs) else pairs
    return connected_components(len(loops.edges), pairs)[1]


def _loops(context: StartContext, chosen: np.ndarray) -> np.ndarray:
    """The edge indices of the loop closures among the `chosen` `(F,)` factors (priors have no runs)."""
    return np.flatnonzero(chosen[: context.graph.num_edges])


def _runs_at(context: StartContext, loops: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`(labels, in_run)`, both `(K,)`, of the loop closures `loops` (edge indices) at `poses` `(N, n, n)`.

    `labels` are their runs (`loop_runs` at re-admission's quantile, `egnc.robust.decision.readmit_quantile`);
    `in_run` is true where a loop's run has at least `MIN_RUN` loops.
    """
    quantile = readmit_quantile(context.gnc_options, context.robust)
    labels = loop_runs(
        edge_factors(context.factors).subset(loops), poses, chi2_quantile(quantile, context.graph.tangent_dim)
    )
    return labels, np.bincount(labels, minlength=1)[labels] >= MIN_RUN


def regrouped_decision(context: StartContext, to_beat: Decision) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision with `to_beat`'s rejected runs of loops put back together (module docstring).

    Args:
        context: the graph, its factors, options and callbacks (each round is a stage).
        to_beat: the best decision of the other starts.

    Returns:
        `(decision, reports)`: the decision, or None where no run of `MIN_RUN` rejected loops
        exists or the chordal system cannot be factorized, and the reports of its rounds.
    """
    robust, factors, gnc_options = context.robust, context.factors, context.gnc_options
    rejected = _loops(context, robust & ~to_beat.inliers)
    in_run = _runs_at(context, rejected, to_beat.poses)[1]
    if not in_run.any():
        return None, ()
    regrouped = to_beat.inliers.copy()
    regrouped[rejected[in_run]] = True
    poses = context.chordal_poses(regrouped)
    if poses is None:  # a chordal system the backend cannot factorize: no regrouped start
        return None, ()
    r = factors.whitened_norms(factors.residuals(poses))
    decision = context.decide(poses, classify_inliers(r, robust, context.dims, gnc_options), "regrouped")
    return decision, decision.reports


@dataclass(frozen=True, eq=False)
class RunsStart:
    """The GNC stage's start from the loops in runs (`runs_start`).

    Attributes:
        poses: `(N, n, n)` the chordal map of the known inliers and the loops in runs.
        runs: `(F,)` int64 run label of each loop closure in the map, -1 for every other factor.
    """

    poses: np.ndarray
    runs: np.ndarray

    def contradicted(self, inliers: np.ndarray) -> bool:
        """Whether the decision `inliers` `(F,)` bool rejects at least `MIN_RUN` loops of one run.

        The map assumed every run true. A run rejected as a whole was not (a group of false loops
        that agree with each other, riSAM's "group" variant), and the map it bent may have led
        the decision astray; random false loops and honest false alarms do not do this
        (module docstring).
        """
        rejected = self.runs[~inliers & (self.runs >= 0)]
        return bool(len(rejected)) and int(np.bincount(rejected).max()) >= MIN_RUN


def runs_start(context: StartContext, poses: np.ndarray) -> RunsStart | None:
    """The GNC stage's start: the chordal map of the known inliers and the loops in runs (module docstring).

    Args:
        context: the graph, its factors and options.
        poses: `(N, n, n)` the initial guess, where the runs are found.

    Returns:
        The chordal map of the edges that are not robust and the loop closures in runs of at least
        `MIN_RUN` at `poses` (in the priors' frame where the graph has priors), with the runs;
        None where no such run exists, the backend cannot factorize its chordal system, or its
        truncated cost is not lower than that of `poses`.
    """
    robust = context.robust
    loops = _loops(context, robust)
    labels, in_run = _runs_at(context, loops, poses)
    if not in_run.any():
        return None
    keep = ~robust
    keep[loops[in_run]] = True
    keep[context.graph.num_edges :] = True  # every prior frames the map: the trimmed fit passes over wrong ones
    start = context.chordal_poses(keep)
    if start is None:  # a chordal system the backend cannot factorize
        return None
    if context.cost_at(start) >= context.cost_at(poses):
        return None
    runs = np.full(len(robust), -1, dtype=np.int64)
    runs[loops[in_run]] = labels[in_run]
    return RunsStart(start, runs)
