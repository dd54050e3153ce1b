"""A second, drift-free start for the outlier decision: the chordal initialization.

The GNC stage starts from the initial guess. When that guess has drifted far (odometry chained
over thousands of poses, a noisy heading), its robust optimum can settle in a wrong basin: true
loop closures look large there, the kernel lets them go, and the decision rounds
(`egnc.decision`) confirm a folded map (SE-Sync's torus3D: 477 of 4049 true loops rejected).
Graduated non-convexity was meant to make the result independent of the guess; from a drifted
guess it does not.

The chordal initialization (`egnc.chordal`) does not read the guess at all. It is solved over
the edges the GNC stage still trusts (IRLS weight at least `SolverOptions.trust_weight`, the
set the step solver factorizes): a loop the kernel switched off entirely there would bend the
chordal map if false, and it would put its fill-in into both chordal factorizations (city10000
at 50 % false loops: 6.9 s over every edge, against 2.5 s for the whole default solve). A map
that false loops still bend is easy to recognise by the truncated least-squares cost
(`egnc.decision.truncated_cost`), the objective both decisions are judged by: an accepted loop
pays `r^2 / 2`, a rejected one `chi2.ppf(q, d) / 2`. So:

1. Classify every loop, trusted or not, at the chordal poses (`r^2 <= chi2.ppf(q, d)` accepted).
2. If that is the guess's decision already, stop: nothing to compare.
3. Probe: unless the chordal poses' truncated cost is more than `PROBE_GATE` times the
   guess's decision's (a map bent by false loops: 5-100x on the shared files with 10-50 % false
   loops), give the accepted edges `PROBE_ITERATIONS` least-squares iterations from the chordal
   poses. A consistent set converges in a few (the chordal map of a clean graph is within a few
   percent of the optimum's cost). Stop unless the truncated cost is then below the guess's.
4. Decide from there (`decide_outliers`, starting from that classification); the caller keeps
   it only if its truncated cost is lower than the guess's decision.

On a graph with false loops and a good guess, this costs one chordal solve and changes nothing;
on a clean graph with a drifted guess it returns the least-squares optimum with every loop
accepted.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from egnc.decision import Decision, StartContext, truncated_cost
from egnc.gnc import StageReport, classify_inliers
from egnc.least_squares import Problem, solve_least_squares

PROBE_ITERATIONS = 2
"""Least-squares iterations a chordal classification gets to show a lower truncated cost than
the guess's decision (the clean drifted files needed at most 1; BENCHMARKS.md)."""

PROBE_GATE = 2.0
"""The probe runs only when the chordal poses' truncated cost is at most this many times the
guess's decision's: 1.03 at most on the clean drifted files, 5 to 100 with 10-50 % false loops,
where the probe would factorize every false loop's fill-in for nothing."""


def chordal_decision(
    context: StartContext, to_beat: Decision, trusted: np.ndarray
) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision started from the chordal initialization, unless it cannot beat `to_beat` (module docstring).

    Args:
        context: the graph, its factors, options and callbacks (the probe and each round are stages).
        to_beat: the decision started from the initial guess.
        trusted: `(E,)` bool, the edges the chordal initialization uses: those the GNC stage
            had not switched off (IRLS weight at least `SolverOptions.trust_weight`).

    Returns:
        `(decision, reports)`: the chordal start's decision, or None where it stopped early (same
        classification, gate, probe), and the reports of every solve run here (the probe and
        the rounds).
    """
    graph, robust, factors, gnc_options = context.graph, context.robust, context.factors, context.gnc_options
    d, q = graph.tangent_dim, gnc_options.outlier_quantile
    poses = context.chordal_poses(trusted)
    if poses is None:  # a chordal system the backend cannot factorize: no second start
        return None, ()
    r = factors.whitened_norms(factors.residuals(poses))
    inliers = classify_inliers(r, robust, d, gnc_options)
    if (
        np.array_equal(inliers, to_beat.inliers)
        or truncated_cost(r, robust, d, q) > PROBE_GATE * to_beat.truncated_cost
    ):
        return None, ()
    problem = Problem.from_graph(graph.subgraph_edges(inliers), context.linear_solver, factors.subset(inliers))
    probe_options = replace(context.solver_options, max_iterations=PROBE_ITERATIONS)
    probe = solve_least_squares(problem, poses, None, probe_options, context.on_iteration)
    report = StageReport(
        np.nan,
        np.nan,
        np.nan,
        probe.iterations,
        probe.cost,
        probe.time_s,
        probe.status,
        int(inliers.sum()),
        probe.linear.cg_iterations,
        kind="probe",
        start="chordal",
    )
    if context.on_stage is not None:
        context.on_stage(report)
    probe_r = factors.whitened_norms(factors.residuals(probe.poses))
    if truncated_cost(probe_r, robust, d, q) >= to_beat.truncated_cost:
        return None, (report,)
    decision = context.decide(probe.poses, inliers, "chordal")
    return decision, (report, *decision.reports)
