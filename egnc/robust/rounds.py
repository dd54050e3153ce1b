"""The rounds of the outlier decision: refine on the accepted edges, re-test, re-admit, repeat.

Each round (`decide_outliers`) solves least squares on the accepted edges (warm-started), rejects
the accepted loop closures whose `r^2` exceeds `chi2.ppf(q, d)` there, re-admits rejected ones
the map agrees with (`egnc.robust.readmission`), and repeats until the classification holds (or
`MAX_ROUNDS`, or a round that reaches the iteration limit).

Hysteresis: a loop re-admitted is rejected by the outlier test of a later round only when its
`r^2` exceeds `chi2.ppf(q_readmit, d)`, the quantile of the test that admitted it. For a linear
model a loop's residual in a map that includes it is no larger (in `r^2`) than its innovation
statistic against the map without it, so the two tests then agree; held to `q` instead, a true
loop between the two quantiles was rejected on one map and re-admitted on the next, and the
rounds alternated until `MAX_ROUNDS` (grids of 2000 to 100 000 poses). Should a classification
still come back, the rounds stop there and keep the one of lowest truncated cost
(`truncated_cost`) among those of the cycle, with its least-squares map.

One analysis: on a system of at least `SHARED_ANALYSIS_MIN_UNKNOWNS` unknowns every round solves
one least-squares problem (`RoundProblem`) over its accepted edges and every rejected loop that
re-admission could take back at the rounds' start (`statistic_floor` within the threshold), weighted 0
while rejected. The loops later rounds take back come from that set, so the rounds share one
pattern and one symbolic analysis instead of one per round; a round that accepts a loop outside
it builds the problem again over both. On a smaller system each round's problem holds its
accepted edges only: its analysis takes milliseconds, while the extra loops' fill-in slows every
factorization of the rounds.

Loose rounds: a round's least squares stops once a step lowers its cost by at most
`ROUND_TOLERANCE` of it. Near the optimum Gauss-Newton converges quadratically, so the step that
would follow changes the cost by about the square of that share, far less than moves a
residual across a threshold, and the map is good enough to decide on. Only a round whose
classification holds is solved on to the caller's tolerance (`SolverOptions.rel_cost_tol`); its
classification is then tested again at that map (keeping the loops re-admitted at the loose
one), and a change there starts another round. So every round but the last saves the
iterations that only confirm convergence (on a 100 000-pose grid with 10 % false loops,
2 + 2 + 4 iterations instead of 4 + 4 + 3; at 30 %, 2 + 4 instead of 4 + 4).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from egnc.graph import PoseGraph
from egnc.graph.connectivity import connected_components
from egnc.linalg.linear_solvers import Factorization
from egnc.nonlinear.least_squares import (
    NUMERICAL_FAILURE,
    IterationCallback,
    Problem,
    SolverOptions,
    SolverResult,
    solve_least_squares,
)
from egnc.nonlinear.marginals import ReachEstimate
from egnc.robust.costs import readmit_quantile, truncated_cost
from egnc.robust.factor_set import Factors, FactorSet, edge_factors, factor_dims, factor_problem
from egnc.robust.gnc import (
    GncOptions,
    StageCallback,
    StageKind,
    StageReport,
    StageStart,
    announce_stage,
    classify_inliers,
)
from egnc.robust.kernels import chi2_quantile
from egnc.robust.losses import FixedWeightLoss
from egnc.robust.readmission import readmitted, readmitted_priors, statistic_floor

MAX_ROUNDS = 5
"""Refine-and-decide rounds before the classification is taken as it stands."""

SHARED_ANALYSIS_MIN_UNKNOWNS = 50_000
"""Systems of at least this many unknowns share one round problem over a superset of the accepted
edges (module docstring, "One analysis"); smaller ones solve each round over its accepted edges
alone, where an analysis costs less than the fill-in the extra loops add to every factorization."""


ROUND_TOLERANCE = 1e-5
"""Relative cost decrease (`SolverOptions.rel_cost_tol`) at which a round's least squares stops
before its classification is known to hold (module docstring, "Loose rounds")."""

REUSED_DAMPING = 1e-6
"""Re-admission takes the information's factorization from the round's last least-squares step
(`round_information`) when that step's LM damping, relative to the diagonal, is at most this."""


def round_information(problem: Problem, refined: SolverResult) -> Factorization | None:
    """The factorization of `problem`'s information that the last step of `refined` solved with,
    where it can stand for the information at the solution; else None (factorize it afresh).

    A solve that stopped on its cost test (status 1) took that step from the linearization just
    before the solution and moved the poses by no more than the tolerance allows; its
    factorization is of `H + lambda diag(H)` there, solved directly (no CG), with `lambda` at most
    `REUSED_DAMPING`. Valid until `problem`'s backend factorizes again.
    """
    if refined.status != 1 or refined.step_damping > REUSED_DAMPING:
        return None
    return problem.step_solver.last_direct_factorization()


@dataclass(frozen=True, eq=False)
class RoundProblem:
    """The least-squares problem of the decision rounds, over a superset of their accepted edges.

    A round weights its accepted edges 1 and the others 0, so the rounds share one pattern and
    its symbolic analysis while their accepted sets stay inside it.

    Attributes:
        edges: `(E,)` bool, the graph's edges in `problem`.
        problem: least squares over those edges.
    """

    edges: np.ndarray
    problem: Problem

    @cached_property
    def reach_estimate(self) -> ReachEstimate | None:
        """`ReachEstimate.of(problem)`: whether exporting the information's factor can pay for
        re-admission's queries (`egnc.nonlinear.marginals`), computed once for every round on this problem."""
        return ReachEstimate.of(self.problem)

    @classmethod
    def over(cls, graph: PoseGraph, factors: Factors, edges: np.ndarray, linear_solver: str) -> RoundProblem:
        """The problem over the factors `edges` `(F,)` of `graph` (whose factors are `factors`)."""
        edges = edges.copy()
        return cls(edges, factor_problem(graph, factors, linear_solver, edges))

    def serves(self, inliers: np.ndarray, exactly: bool) -> bool:
        """Whether a round that accepts `inliers` `(E,)` is solved on this problem: its edges hold
        them, or are exactly them (`exactly`)."""
        return np.array_equal(inliers, self.edges) if exactly else not np.any(inliers & ~self.edges)

    def weights(self, inliers: np.ndarray) -> np.ndarray:
        """`(F_problem,)` weight of each of the problem's factors: 1 where `inliers` `(F,)`, else 0."""
        return inliers[self.edges].astype(np.float64)

    def solve(
        self, poses: np.ndarray, inliers: np.ndarray, options: SolverOptions, on_iteration: IterationCallback | None
    ) -> SolverResult:
        """Least squares of the `inliers` `(E,)` edges from `poses` `(N, n, n)`, each step direct."""
        # The direct path, zeros included (priors are always trusted; where they are candidates the
        # weights cover them too, `Problem.weighted_priors`).
        every_edge = np.ones(len(self.problem.factors.edges), dtype=bool)
        loss = FixedWeightLoss(self.weights(inliers))
        return solve_least_squares(self.problem, poses, loss, options, on_iteration, trusted=every_edge)


@dataclass(frozen=True, eq=False)
class Decision:
    """Outcome of `decide_outliers`.

    Attributes:
        poses: `(N, n, n)` least-squares poses of the accepted edges (the input poses when no
            round ran).
        inliers: `(E,)` bool, the accepted edges.
        reports: one `StageReport` per round.
        settled: whether the last round left the classification unchanged, or the rounds came
            back to a classification they had solved and kept the cycle's lowest truncated cost
            (false when the rounds ran out, a round hit its iteration limit, or no round could run).
        truncated_cost: `truncated_cost` at `poses`, by which two decisions are compared.
    """

    poses: np.ndarray
    inliers: np.ndarray
    reports: tuple[StageReport, ...]
    settled: bool
    truncated_cost: float


def least_squares_report(
    solved: SolverResult, started: float, active_edges: int, kind: StageKind, start: StageStart
) -> StageReport:
    """The `StageReport` of a least-squares solve (no `mu`) over `active_edges` edges, begun at `started`.

    `started` is a `time.perf_counter()` reading in seconds.
    """
    return StageReport(
        np.nan,
        np.nan,
        np.nan,
        solved.iterations,
        solved.cost,
        time.perf_counter() - started,
        solved.status,
        active_edges,
        solved.linear.cg_iterations,
        kind=kind,
        start=start,
    )


def _stopped_loosely(solved: SolverResult, tolerance: float) -> bool:
    """Whether `solved` stopped on its cost test (status 1) after a relative decrease above `tolerance`."""
    history = solved.cost_history
    return solved.status == 1 and len(history) > 1 and history[-2] - history[-1] > tolerance * history[-2]


def _continued(first: SolverResult, then: SolverResult) -> SolverResult:
    """The solve `then`, which went on from where `first` stopped, with the iterations, linear
    solves, cost history and time of both."""
    return replace(
        then,
        cost_history=np.concatenate([first.cost_history, then.cost_history[1:]]),
        iterations=first.iterations + then.iterations,
        linear_solves=first.linear_solves + then.linear_solves,
        time_s=first.time_s + then.time_s,
    )


class _Rounds:
    """What the rounds of one `decide_outliers` call share: the round problem, the loops ever
    re-admitted, and the tests' quantiles (module docstring)."""

    def __init__(
        self,
        graph: PoseGraph,
        robust: np.ndarray,
        solver_options: SolverOptions,
        gnc_options: GncOptions,
        linear_solver: str,
        factors: Factors,
        on_iteration: IterationCallback | None,
        poses: np.ndarray,
        inliers: np.ndarray,
    ) -> None:
        self.graph, self.robust, self.factors, self.linear_solver = graph, robust, factors, linear_solver
        self.solver_options, self.gnc_options, self.on_iteration = solver_options, gnc_options, on_iteration
        d = graph.tangent_dim
        self.dims = factor_dims(graph, factors)
        self.readmit_at = readmit_quantile(gnc_options, robust)
        self.strict = replace(gnc_options, outlier_quantile=self.readmit_at)
        self.ever_readmitted = np.zeros(len(robust), dtype=bool)
        # The rounds' problem (module docstring, "One analysis"): on a large system, the accepted
        # edges and every rejected loop that re-admission could take back at these poses.
        self.shared = d * graph.num_poses >= SHARED_ANALYSIS_MIN_UNKNOWNS
        self.members = inliers.copy()
        if self.shared:
            outside = np.flatnonzero(robust & ~inliers)
            if isinstance(factors, FactorSet):  # a rejected prior stays in the problem (weight 0)
                self.members[outside[outside >= factors.num_edges]] = True
                outside = outside[outside < factors.num_edges]
            loops = edge_factors(factors).subset(outside)
            self.members[outside] = statistic_floor(loops, poses) <= chi2_quantile(self.readmit_at, d)
        self.system: RoundProblem | None = None
        self.loose = replace(solver_options, rel_cost_tol=max(solver_options.rel_cost_tol, ROUND_TOLERANCE))

    def residuals(self, poses: np.ndarray) -> np.ndarray:
        """`(E,)` whitened residual norms at `poses` `(N, n, n)`."""
        return self.factors.whitened_norms(self.factors.residuals(poses))

    def problem_for(self, accepted: np.ndarray) -> RoundProblem:
        """The problem a round that accepts `accepted` `(E,)` solves on: the last one where it serves."""
        self.members = self.members | accepted if self.shared else accepted
        if self.system is None or not self.system.serves(accepted, exactly=not self.shared):
            self.system = None  # freed before the next is built
            self.system = RoundProblem.over(self.graph, self.factors, self.members, self.linear_solver)
        return self.system

    def tightened(self, refined: SolverResult, accepted: np.ndarray) -> SolverResult:
        """`refined`, the round of `accepted` `(E,)`, continued to `solver_options`' tolerance
        where it stopped at `ROUND_TOLERANCE`."""
        solver_options, on_iteration = self.solver_options, self.on_iteration
        if not _stopped_loosely(refined, solver_options.rel_cost_tol):
            return refined
        offset = refined.iterations
        progress = None if on_iteration is None else lambda k, cost: on_iteration(offset + k, cost)
        # The round's iteration limit holds for both solves together; LM goes on from the
        # damping it had reached.
        options = replace(solver_options, max_iterations=solver_options.max_iterations - refined.iterations)
        if refined.next_damping > 0:
            options = replace(options, initial_damping=refined.next_damping)
        continued = self.problem_for(accepted).solve(refined.poses, accepted, options, progress)
        return _continued(refined, continued)

    def classified(self, r: np.ndarray, back: np.ndarray, inliers: np.ndarray) -> np.ndarray:
        """The next round's accepted edges after the round of `inliers` `(E,)`: the outlier test at
        residuals `r` `(E,)`, and `back`."""
        robust, d = self.robust, self.dims
        decided = classify_inliers(r, robust, d, self.gnc_options)
        if not self.gnc_options.readmit:
            return decided
        # A loop the innovation test admitted is held to that test's quantile from then on
        # (module docstring, "Hysteresis").
        decided |= self.ever_readmitted & classify_inliers(r, robust, d, self.strict)
        return (decided & inliers) | back

    def run(self, poses: np.ndarray, inliers: np.ndarray) -> tuple[SolverResult, np.ndarray, np.ndarray]:
        """One round from `poses` `(N, n, n)` on the accepted edges `inliers` `(E,)`: its solve, the
        residuals `(E,)` at its solution and the next round's accepted edges `(E,)`."""
        round_system = self.problem_for(inliers)
        problem = round_system.problem
        refined = round_system.solve(poses, inliers, self.loose, self.on_iteration)
        r = self.residuals(refined.poses)
        back = np.zeros(len(inliers), dtype=bool)
        if self.gnc_options.readmit:
            information = round_information(problem, refined)
            weights = round_system.weights(inliers)
            estimate = round_system.reach_estimate
            factors = self.factors
            rejected, r_edges = ~inliers, r
            if isinstance(factors, FactorSet):
                rejected, r_edges = factors.edges_of(rejected), factors.edges_of(r)
                back[factors.num_edges :] = readmitted_priors(factors, ~inliers, r, self.readmit_at)
            back[: len(rejected)] = readmitted(
                problem,
                refined.poses,
                edge_factors(factors),
                rejected,
                r_edges,
                self.readmit_at,
                information,
                weights,
                estimate,
            )
            problem.step_solver.discard_factorization()  # not held while a new round problem is built
            self.ever_readmitted |= back
        decided = self.classified(r, back, inliers)
        if np.array_equal(decided, inliers):  # it holds: the round is solved to the full tolerance and checked again
            refined = self.tightened(refined, inliers)
            r = self.residuals(refined.poses)
            decided = self.classified(r, back, inliers)
        return refined, r, decided


def decide_outliers(
    graph: PoseGraph,
    poses: np.ndarray,
    robust: np.ndarray,
    solver_options: SolverOptions,
    gnc_options: GncOptions,
    linear_solver: str,
    factors: Factors,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
    inliers: np.ndarray | None = None,
    start: StageStart = "guess",
) -> Decision:
    """Refine on the accepted edges and re-decide until the classification holds.

    Args:
        graph: the pose graph.
        poses: `(N, n, n)` starting poses (the last GNC stage's solution).
        robust: `(F,)` bool, the factors that may be rejected (loop closures; priors too where
            `factors` is a `FactorSet`, `egnc.robust.factor_set`).
        solver_options: options of each least-squares refinement.
        gnc_options: `outlier_quantile` and `readmit`.
        linear_solver: resolved backend name.
        factors: the graph's factors, built once per solve.
        on_stage, on_iteration: progress callbacks; each round is reported as a stage.
        inliers: `(E,)` bool, the first classification; None classifies at `poses`.
        start: the start the rounds belong to, stamped on their reports (`StageReport.start`).

    Returns:
        The `Decision`. No round runs when the accepted edges would split the graph into more
        pieces than all edges do.
    """
    d, q = factor_dims(graph, factors), gnc_options.outlier_quantile
    r = factors.whitened_norms(factors.residuals(poses))
    if inliers is None:
        inliers = classify_inliers(r, robust, d, gnc_options)
    reports: list[StageReport] = []
    settled = False
    components = connected_components(graph.num_poses, graph.edges)[0]  # isolated vertices count too
    rounds = _Rounds(graph, robust, solver_options, gnc_options, linear_solver, factors, on_iteration, poses, inliers)
    solved: dict[bytes, int] = {}  # classification -> its round in `history`
    history: list[tuple[np.ndarray, SolverResult, float]] = []  # inliers, solve, truncated cost
    for _ in range(MAX_ROUNDS):
        if connected_components(graph.num_poses, graph.edges[inliers[: graph.num_edges]])[0] != components:
            break
        started = time.perf_counter()
        refined, r, decided = rounds.run(poses, inliers)
        poses = refined.poses
        solved[np.packbits(inliers).tobytes()] = len(history)
        history.append((inliers, refined, truncated_cost(r, robust, d, q)))
        reports.append(least_squares_report(refined, started, int(inliers.sum()), "decision", start))
        announce_stage(on_stage, reports[-1], poses)
        if np.array_equal(decided, inliers) or refined.status in (0, NUMERICAL_FAILURE):  # settled, or stuck
            settled = refined.status not in (0, NUMERICAL_FAILURE)
            break
        first = solved.get(np.packbits(decided).tobytes())
        if first is not None:  # a cycle: keep its classification of lowest truncated cost
            inliers, refined, _ = min(history[first:], key=lambda solved_round: solved_round[2])
            refined = rounds.tightened(refined, inliers)
            poses = refined.poses
            r = rounds.residuals(poses)
            settled = True
            break
        inliers = decided
    return Decision(
        poses=poses,
        inliers=inliers,
        reports=tuple(reports),
        settled=settled,
        truncated_cost=truncated_cost(r, robust, d, q),
    )
