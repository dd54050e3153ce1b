"""A second, drift-free start for the outlier decision: the chordal initialization.

The GNC stage starts from the initial guess. When that guess has drifted far (odometry chained
over thousands of poses, a noisy heading), its robust optimum can settle in a wrong basin: true
loop closures look large there, the kernel lets them go, and the decision rounds
(`egnc.robust.decision`) confirm a folded map (SE-Sync's torus3D: 477 of 4049 true loops rejected).
Graduated non-convexity was meant to make the result independent of the guess; from a drifted
guess it does not.

The chordal initialization (`egnc.nonlinear.chordal`) does not read the guess at all. It is solved over
the edges the GNC stage still trusts (IRLS weight at least `SolverOptions.trust_weight`, the
set the step solver factorizes): a loop the kernel switched off entirely there would bend the
chordal map if false, and it would put its fill-in into both chordal factorizations (city10000
at 50 % false loops: 6.9 s over every edge, against 2.5 s for the whole default solve). A map
that false loops still bend is easy to recognise by the truncated least-squares cost
(`egnc.robust.decision.truncated_cost`), the objective both decisions are judged by: an accepted loop
pays `r^2 / 2`, a rejected one `chi2.ppf(q, d) / 2`. So:

1. Classify every loop, trusted or not, at the chordal poses (`r^2 <= chi2.ppf(q, d)` accepted),
   and add the loops the guess's decision accepts: this start is there to win back loops the
   guess's basin rejected, and its rounds re-test every accepted loop anyway. (Classified alone,
   the chordal poses dropped the loops the guess's decision had re-admitted above the
   threshold; the probe then looked cheaper than that decision, and the rounds from it
   re-admitted them and ended above it: BENCHMARKS.md, "The chordal start tries to win back
   loops only".)
2. If that accepts no loop the guess's decision rejects, stop: nothing to win back.
3. Probe: unless the chordal poses' truncated cost is more than `PROBE_GATE` times the
   guess's decision's (a map bent by false loops: 5-100x on the shared files with 10-50 % false
   loops), give the accepted edges `PROBE_ITERATIONS` least-squares iterations from the chordal
   poses. A consistent set converges in a few (the chordal map of a clean graph is within a few
   percent of the optimum's cost). Stop unless the truncated cost is then below the guess's.
4. Decide from there (`decide_outliers`, starting from that classification); the caller keeps
   it only if its truncated cost is lower than the guess's decision.

On a graph with false loops and a good guess, this costs one chordal solve and changes nothing;
on a clean graph with a drifted guess it returns the least-squares optimum with every loop
accepted. Where the GNC stage began at the runs start's chordal map (`egnc.robust.regroup`: the known
inliers and the loops in runs, a map the decision did not contradict), that map is the one
classified in step 1: it reads no guess either, and it spares a second chordal solve (on the
shared files every decision stayed the same but one, which rejects one false loop more;
BENCHMARKS.md, issue 18, twenty-seventh session).

Both chordal maps above are solved over the edges the GNC stage trusted, so a true loop that the
stage switched off from a drifted guess stays out of them, and where such loops are many the
decision cannot bring them back (SE-Sync's manhattan, a clean file whose guess is odometry
chained over 3500 poses: 44 of 1954 loops rejected, truncated cost 1820). `all_edges_decision`
is the start for that case: the chordal initialization of *every* edge, and the GNC stage run
again from there (the same schedule as from the guess), then the decision. On that file it
rejected 22 loops with truncated cost 1725 (GTSAM's GNC-TLS decision: 37 and 1685); since
re-admission credits the map with up to a loop's own uncertainty, the guess's decision rejects 8
there and wins. It runs only:

1. where the best decision so far rejects a loop (otherwise nothing is left to win back);
2. where it rejects at most `ALL_EDGES_SHARE` of the loop closures: the chordal system of every
   edge carries each rejected loop's fill-in, and many random long loops make it unaffordable
   (a 100 000-pose grid with 30 % false loops: 462 s and 9.7 GiB, against 3 s clean);
3. where the chordal map of every edge has a lower truncated cost than the initial guess: false
   loops bend that map. With 10-50 % false loops (every shared file, seed 1) its truncated cost
   was above the guess's on 34 of 36 files, while on every clean shared file, drifted or not, it
   was below (BENCHMARKS.md); all 36 already fail the second condition.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from egnc.nonlinear.factors import to_matrices
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, SolverResult, solve_least_squares
from egnc.robust.decision import Decision, StartContext, truncated_cost
from egnc.robust.factor_set import factor_problem
from egnc.robust.gnc import GncOutcome, StageReport, StageStart, announce_stage, classify_inliers

PROBE_ITERATIONS = 2
"""Least-squares iterations a chordal classification gets to show a lower truncated cost than
the guess's decision (the clean drifted files needed at most 1; BENCHMARKS.md)."""

PROBE_GATE = 2.0
"""The probe runs only when the chordal poses' truncated cost is at most this many times the
guess's decision's: 1.03 at most on the clean drifted files, 5 to 100 with 10-50 % false loops,
where the probe would factorize every false loop's fill-in for nothing."""

ALL_EDGES_SHARE = 0.05
"""`all_edges_decision` runs only where the best decision so far rejects at most this share of
the loop closures (each rejected loop's fill-in enters its chordal system; module docstring)."""


def chordal_decision(
    context: StartContext, to_beat: Decision, trusted: np.ndarray, chordal_map: np.ndarray | None = None
) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision started from the chordal initialization, unless it cannot beat `to_beat` (module docstring).

    Args:
        context: the graph, its factors, options and callbacks (the probe and each round are stages).
        to_beat: the decision started from the initial guess.
        trusted: `(F,)` bool, the factors the chordal initialization uses: those the GNC stage
            had not switched off (IRLS weight at least `SolverOptions.trust_weight`); its edges
            give the relaxation, its priors the frame (`StartContext.chordal_poses`).
        chordal_map: `(N, n, n)` a chordal map already solved (the runs start's), used instead
            of solving one over `trusted`.

    Returns:
        `(decision, reports)`: the chordal start's decision, or None where it stopped early (no
        loop to win back, gate, probe), and the reports of every solve run here (the probe and
        the rounds).
    """
    robust, factors, gnc_options = context.robust, context.factors, context.gnc_options
    d, q = context.dims, gnc_options.outlier_quantile
    poses = context.chordal_poses(trusted) if chordal_map is None else chordal_map
    if poses is None:  # a chordal system the backend cannot factorize: no second start
        return None, ()
    r = factors.whitened_norms(factors.residuals(poses))
    inliers = classify_inliers(r, robust, d, gnc_options) | to_beat.inliers
    if (
        np.array_equal(inliers, to_beat.inliers)
        or truncated_cost(r, robust, d, q) > PROBE_GATE * to_beat.truncated_cost
    ):
        return None, ()
    probe = _probe(context, inliers, poses)
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
    announce_stage(context.on_stage, report, probe.poses)
    if context.cost_at(probe.poses) >= to_beat.truncated_cost:
        return None, (report,)
    decision = context.decide(probe.poses, inliers, "chordal")
    return decision, (report, *decision.reports)


def _probe(context: StartContext, inliers: np.ndarray, poses: np.ndarray) -> SolverResult:
    """At most `PROBE_ITERATIONS` least-squares steps on the `inliers` `(F,)` factors from `poses` `(N, n, n)`.

    Its problem (pattern and factorization: 200 MiB on a 100 000-pose grid) is freed on return,
    before the decision rounds build their own.
    """
    problem = factor_problem(context.graph, context.factors, context.linear_solver, inliers)
    probe_options = replace(context.solver_options, max_iterations=PROBE_ITERATIONS)
    return solve_least_squares(problem, poses, None, probe_options, context.on_iteration)


def all_edges_decision(
    context: StartContext, to_beat: Decision, graduate: Callable[[np.ndarray, StageStart], GncOutcome]
) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The decision after the GNC stage run again from the chordal map of every edge (module docstring).

    Args:
        context: the graph at its initial guess, its factors, options and callbacks.
        to_beat: the best decision of the other starts so far.
        graduate: runs the GNC stage from `(N, n, n)` poses (the schedule the guess was solved
            with), its reports labelled with the given start.

    Returns:
        `(decision, reports)`: the decision, or None where the start did not run (nothing
        rejected, too much rejected, no chordal map, a chordal map no better than the guess, a
        failed GNC stage), and the reports of the GNC stage and the rounds.
    """
    graph, robust = context.graph, context.robust
    rejected = int(np.count_nonzero(robust & ~to_beat.inliers))
    if not rejected or rejected > ALL_EDGES_SHARE * np.count_nonzero(robust):
        return None, ()
    poses = context.chordal_poses(np.ones(graph.num_edges, dtype=bool))
    if poses is None:  # a chordal system the backend cannot factorize
        return None, ()
    if context.cost_at(poses) >= context.cost_at(to_matrices(graph.dim, graph.poses)):
        return None, ()
    return graduated_decision(context, poses, "chordal-all", graduate)


def graduated_decision(
    context: StartContext,
    poses: np.ndarray,
    start: StageStart,
    graduate: Callable[[np.ndarray, StageStart], GncOutcome],
) -> tuple[Decision | None, tuple[StageReport, ...]]:
    """The GNC stage from `poses` `(N, n, n)` and the decision from its classification, labelled `start`.

    Returns:
        `(decision, reports)`: the decision, or None where the GNC stage failed numerically,
        and the reports of the GNC stage and the rounds.
    """
    outcome = graduate(poses, start)
    if outcome.status == NUMERICAL_FAILURE:
        return None, outcome.stages
    r = context.factors.whitened_norms(context.factors.residuals(outcome.poses))
    inliers = classify_inliers(r, context.robust, context.dims, context.gnc_options)
    decision = context.decide(outcome.poses, inliers, start)
    return decision, (*outcome.stages, *decision.reports)
