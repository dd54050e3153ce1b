"""The final outlier decision of the graduated methods: refine, re-test, re-admit.

GNC ends at a robust (Geman-McClure) optimum, where a loop closure's residual says how well it
fits a map from which the kernel had already down-weighted it. Deciding there rejects honest
loops: with few loops, or loops that support each other, the robust optimum lets them go and
bends the odometry back, and their residuals grow past any threshold (MIT, smallGrid3D).
So the decision is made on least-squares maps instead, in rounds:

1. Solve least squares on the accepted edges (warm-started; the map the accepted measurements
   imply).
2. An accepted loop closure whose squared whitened residual `r^2` exceeds `chi2.ppf(q, d)` is
   rejected: it disagrees with the map even though it helped shape it.
3. Rejected loop closures are re-admitted by their innovation statistic
   `e^T (Omega^-1 + A H^-1 A^T)^-1 e` (`egnc.nonlinear.marginals`; `H` factorized by step 1's last step,
   `round_information`): how well the map built without them
   predicts their measurements, within the combined uncertainty of both (the residual alone,
   `r^2`, ignores how uncertain the relative pose of two far-apart poses is). If the map agrees
   with *all* rejected loops, conditioned one on another, at `chi2.ppf(q_readmit, d)`, all
   come back: nothing in the graph contradicts anything else (MIT, smallGrid3D). Otherwise
   loops are re-admitted one at a time, each given those before it, with the map credited with
   no more uncertainty of a loop's relative pose than the loop's own (`credited_covariance`):
   where the map is much weaker than the loop, agreement within its uncertainty says little,
   and the noisy Manhattan graphs absorbed gross outliers that way (recall 0.89, ATE 8.8 m on
   manhattan_noisy.irl when the full map covariance was credited).
4. Repeat until the classification holds (or `MAX_ROUNDS`, or a round that reaches the
   iteration limit).

Hysteresis: a loop re-admitted in step 3 is rejected in step 2 of a later round only when its
`r^2` exceeds `chi2.ppf(q_readmit, d)`, the quantile of the test that admitted it. For a linear
model a loop's residual in a map that includes it is no larger (in `r^2`) than its innovation
statistic against the map without it, so the two tests then agree; held to `q` instead, a true
loop between the two quantiles was rejected on one map and re-admitted on the next, and the
rounds alternated until `MAX_ROUNDS` (grids of 2000 to 100 000 poses). Should a classification
still come back, the rounds stop there and keep the one of lowest truncated cost
(`truncated_cost`) among those of the cycle, with its least-squares map.

One analysis: on a system of at least `SHARED_ANALYSIS_MIN_UNKNOWNS` unknowns every round solves
one least-squares problem (`RoundProblem`) over its accepted edges and every rejected loop that
step 3 could re-admit at the rounds' start (`_statistic_floor` within the threshold), weighted 0
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

Under the linear-Gaussian model the false-alarm rate per honest loop is below `1 - q` for the
test of step 2 (an included loop's `r^2` is stochastically smaller than chi-square: it pulls the
map towards itself) and `1 - q_readmit` for step 3, where `q_readmit` is raised on graphs of
many loops so that the expected number of honest loops step 3 keeps out of one graph stays
bounded (`readmit_quantile`).

A rejected loop with `r^2 <= chi2.ppf(q_readmit, d)` passes without its covariance: the innovation
statistic is never larger than `r^2`, since its covariance is the loop's own plus the map's (true
loops that the robust optimum let go are mostly of this kind: 363 of a 25 000-pose grid's first
round, which took seven batches of covariance solves). The others are tested in order of
increasing `r^2`, in batches of `READMIT_BATCH`; testing stops at the first batch in which none passes
(the all-agree test starts from the largest residuals and stops at the first batch that fails, or
before it when its largest loop alone rules it out, `_all_agree`),
and before solving a batch of which a bound that needs no covariance says none can pass
(`_statistic_floor`). Where that bound leaves only a few loops of a batch (`SCOUT_LOOPS`), those
are tested alone first and the batch is solved only if one of them passes: a batch admits no
loop unless one passes alone. So a graph with thousands of gross false loops pays for one or two
batches of marginal covariances per round, not thousands, and a round that only confirms the
classification mostly pays for a few columns.

References:
    M. Kaess, F. Dellaert, "Covariance recovery from a square root information matrix for data
    association", RAS 2009 (innovation gating with marginal covariances).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.graph.connectivity import connected_components
from egnc.linalg.linear_solvers import Factorization, NotPositiveDefiniteError
from egnc.nonlinear.chordal import chordal_initialization
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import (
    NUMERICAL_FAILURE,
    IterationCallback,
    Problem,
    SolverOptions,
    SolverResult,
    solve_least_squares,
)
from egnc.nonlinear.marginals import ReachEstimate, covariance_solver, innovations
from egnc.robust.gnc import GncOptions, StageCallback, StageKind, StageReport, StageStart, classify_inliers
from egnc.robust.kernels import chi2_quantile
from egnc.robust.losses import FixedWeightLoss

MAX_ROUNDS = 5
"""Refine-and-decide rounds before the classification is taken as it stands."""

SHARED_ANALYSIS_MIN_UNKNOWNS = 50_000
"""Systems of at least this many unknowns share one round problem over a superset of the accepted
edges (module docstring, "One analysis"); smaller ones solve each round over its accepted edges
alone, where an analysis costs less than the fill-in the extra loops add to every factorization."""

READMIT_BATCH = 64
"""Rejected loops whose innovation statistics are computed together (one multi-column solve)."""

SCOUT_LOOPS = 8
"""A batch in which at most this many loops, but not all, can pass alone by `_statistic_floor` is
first tested on those loops alone: where none passes, neither does the batch, and its solve is
skipped."""

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


def readmit_quantile(gnc_options: GncOptions, robust: np.ndarray) -> float:
    """The chi-square quantile of re-admission's test on a graph whose loop closures are `robust` `(E,)`.

    `gnc_options.readmit_quantile`, raised to `1 - readmit_false_alarms / L` on a graph of `L`
    loop closures where that is higher. An honest loop fails the test with probability
    `1 - quantile` under the linear-Gaussian model, so a fixed quantile keeps out a number of
    honest loops that grows with the graph (5.6 expected among a 100 000-pose grid's 56 000);
    the raised one bounds the expected number per graph (a Bonferroni correction).
    """
    quantile = gnc_options.readmit_quantile
    num_loops = int(np.count_nonzero(robust))
    if gnc_options.readmit_false_alarms is None or not num_loops:
        return quantile
    return max(quantile, 1.0 - gnc_options.readmit_false_alarms / num_loops)


def readmitted(
    problem: Problem,
    poses: np.ndarray,
    factors: BetweenFactors,
    rejected: np.ndarray,
    r: np.ndarray,
    quantile: float,
    information: Factorization | None = None,
    weights: np.ndarray | None = None,
    estimate: ReachEstimate | None = None,
) -> np.ndarray:
    """`(E,)` bool: the `rejected` edges that the map of `problem` agrees with.

    Two cases (module docstring). If the map agrees with *every* rejected loop, taken together,
    all come back: nothing in the graph contradicts anything else (a clean graph whose loops the
    robust kernel let go). Otherwise loops are re-admitted one at a time, each given those before
    it, by the statistic of `credited_covariance`: the map's uncertainty of a loop's relative
    pose counts only up to the loop's own, since agreement within a much weaker map's
    uncertainty says little (a weakly constrained graph absorbs gross outliers).

    Args:
        problem: least squares of the accepted edges, solved at `poses` `(N, n, n)`.
        poses: the solution.
        factors: the whole graph's factors.
        rejected: `(E,)` bool, edges left out of `problem`.
        r: `(E,)` whitened residual norms at `poses`, to order the candidates.
        quantile: chi-square quantile of the test.
        information: a factorization of `problem`'s information at `poses` (`round_information`);
            None factorizes it here.
        weights: `(E_problem,)` weight of each of `problem`'s edges in its information (0: an edge
            of its pattern left out, `RoundProblem`); None: 1.
        estimate: `ReachEstimate.of(problem)` (`RoundProblem.reach_estimate`: it depends on the
            pattern only), or None for none: the factor may then be exported for any large
            system (`egnc.nonlinear.marginals.quadratic_form`).
    """
    threshold = chi2_quantile(quantile, factors.information.shape[-1])
    # The innovation statistic is at most r^2 (its covariance adds the map's to the loop's own):
    # a loop the map already fits within the threshold passes without its covariance.
    fits = rejected & (r * r <= threshold)
    candidates = np.flatnonzero(rejected & ~fits)
    candidates = candidates[np.argsort(r[candidates], kind="stable")]
    passed = fits.copy()
    if not len(candidates):
        return passed
    try:
        covariance_solve = covariance_solver(problem, poses, weights) if information is None else information
        if _all_agree(problem, poses, factors, candidates, (covariance_solve, estimate), threshold):
            return rejected.copy()
        floor = _statistic_floor(factors.subset(np.sort(candidates)), poses)
        floor = floor[np.searchsorted(np.sort(candidates), candidates)]  # in candidate order
        for start in range(0, len(candidates), READMIT_BATCH):
            batch = candidates[start : start + READMIT_BATCH]
            may_pass = floor[start : start + READMIT_BATCH] <= threshold
            if not may_pass.any():
                break  # none passes alone, so none passes: no solve needed
            scout = batch[may_pass]
            if len(scout) <= SCOUT_LOOPS and len(scout) < len(batch):
                if not _any_passes_alone(problem, poses, factors, scout, (covariance_solve, estimate), threshold):
                    break  # the loops that could pass alone do not: none passes
            e, S, own = _batch_innovations(problem, poses, factors, batch, (covariance_solve, estimate))
            ok = sequentially_consistent(e, credited_covariance(S, own), threshold)
            if not ok.any():
                break
            passed[np.sort(batch)[ok]] = True
    except NotPositiveDefiniteError:  # no covariance at a degenerate solution: nothing to test against
        pass
    return passed


def _all_agree(
    problem: Problem,
    poses: np.ndarray,
    factors: BetweenFactors,
    candidates: np.ndarray,
    covariance: tuple[Factorization, ReachEstimate | None],
    threshold: float,
) -> bool:
    """Whether every loop of `candidates` `(K,)` (by increasing `r`) passes, batch by batch.

    Largest residuals first: one batch refutes "all agree" in a graph with gross outliers, and
    most often its largest loop alone does, for `d` columns instead of a batch's: every loop of a
    batch passes only if the batch's joint statistic is at most `len(batch) * threshold`, and a
    joint statistic is at least that of any one of its loops.
    """
    e, S, _ = _batch_innovations(problem, poses, factors, candidates[-1:], covariance)
    if float(e[0] @ np.linalg.solve(S, e[0])) > min(READMIT_BATCH, len(candidates)) * threshold:
        return False
    for stop in range(len(candidates), 0, -READMIT_BATCH):
        batch = candidates[max(0, stop - READMIT_BATCH) : stop]
        e, S, _ = _batch_innovations(problem, poses, factors, batch, covariance)
        if not sequentially_consistent(e, S, threshold).all():
            return False
    return True


def _statistic_floor(loops: BetweenFactors, poses: np.ndarray) -> np.ndarray:
    """`(K,)` lower bounds of the credited innovation statistics of `loops` (`credited_covariance`).

    The credited map covariance `s Sigma_rel` has `trace(s Sigma_rel) <= trace(Omega^-1)`, so
    `lambda_max(Omega^-1 + s Sigma_rel) <= lambda_max(Omega^-1) + trace(Omega^-1)` and
    `e^T (Omega^-1 + s Sigma_rel)^-1 e >= |e|^2 / (lambda_max(Omega^-1) + trace(Omega^-1))`.
    A loop above the threshold by this bound fails alone; a batch of only such loops admits
    none (the first loop `sequentially_consistent` visits is tested alone, and so is every later
    one while none is admitted).
    """
    e = loops.residuals(poses)
    own = np.linalg.inv(loops.information)
    largest = np.linalg.eigvalsh(0.5 * (own + np.swapaxes(own, 1, 2)))[:, -1]
    return np.einsum("ki,ki->k", e, e) / (largest + np.trace(own, axis1=1, axis2=2))


def _batch_innovations(
    problem: Problem,
    poses: np.ndarray,
    factors: BetweenFactors,
    batch: np.ndarray,
    covariance: tuple[Factorization, ReachEstimate | None],
    export: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Innovations `(K, d)`, their covariance `(K d, K d)` and the loops' own covariances `(K, d, d)`,
    in edge order; `covariance`: the information's factorization and `ReachEstimate`; `export`:
    whether the query may export the factor (`egnc.nonlinear.marginals.quadratic_form`)."""
    loops = factors.subset(np.sort(batch))
    e, S = innovations(problem, poses, loops, *covariance, export=export)
    return e, S, np.linalg.inv(loops.information)


def credited_covariance(S: np.ndarray, own: np.ndarray) -> np.ndarray:
    """`(K d, K d)` innovation covariance with each loop's share of the map's covariance capped at its own size.

    `S = blockdiag(own) + M`, with `M` the map's joint covariance of the `K` loops' relative
    poses and `own` `(K, d, d)` the loops' measurement covariances. Each loop's rows and columns
    of `M` are scaled by the square root of its `map_credit`, so that its block is credited with
    no more total variance than the loop's own (a loop the map determines at least as well as it
    measures it keeps its block unchanged). The result is positive definite.
    """
    num_loops, d = own.shape[:2]
    block = np.arange(num_loops)[:, None] * d + np.arange(d)
    own_full = np.zeros_like(S)
    own_full[block[:, :, None], block[:, None, :]] = own
    relative = S - own_full
    root = np.repeat(np.sqrt(map_credit(relative[block[:, :, None], block[:, None, :]], own)), d)
    return own_full + root[:, None] * relative * root[None, :]


def map_credit(relative: np.ndarray, own: np.ndarray) -> np.ndarray:
    """`(K,)` share of the map's covariance of each loop's relative pose that re-admission credits.

    1 where the map determines the relative pose at least as well as the loop measures it, in
    total variance (`trace(relative) <= trace(own)`, metres^2 and radians^2 added, as in the
    tangent: the loop is well determined), else `trace(own) / trace(relative)`, which scales the
    map's covariance down to the loop's own size.

    Args:
        relative: `(K, d, d)` the map's covariance of each loop's relative pose.
        own: `(K, d, d)` each loop's measurement covariance `Omega^-1`.
    """
    own_trace = np.trace(own, axis1=1, axis2=2)
    relative_trace = np.trace(relative, axis1=1, axis2=2)
    credit = np.ones(len(own))
    weak = relative_trace > own_trace  # divided only there: a map share of 0 (fixed poses) overflowed
    credit[weak] = own_trace[weak] / relative_trace[weak]
    return credit


def _any_passes_alone(
    problem: Problem,
    poses: np.ndarray,
    factors: BetweenFactors,
    loops: np.ndarray,
    covariance: tuple[Factorization, ReachEstimate | None],
    threshold: float,
) -> bool:
    """Whether some loop of `loops` `(K,)` has a credited innovation statistic alone within `threshold`.

    A loop's block of `credited_covariance` depends on that loop only, so this is the statistic
    `sequentially_consistent` tests it by while nothing of its batch is admitted, in any batch.
    The query does not export the factor (`egnc.nonlinear.marginals.quadratic_form`; it uses one already
    exported): where the batch is then skipped nothing else would use it, and on the 3D grids the
    copy set the robust solve's peak memory (BENCHMARKS.md, issue 18, twenty-second session).
    """
    e, S, own = _batch_innovations(problem, poses, factors, loops, covariance, export=False)
    return bool(np.any(_block_statistics(e, credited_covariance(S, own)) <= threshold))


def _block_statistics(e: np.ndarray, S: np.ndarray) -> np.ndarray:
    """`(K,)` `e_k^T S_kk^-1 e_k` of residuals `e` `(K, d)` with the diagonal blocks of `S` `(K d, K d)`."""
    num_loops, d = e.shape
    block = np.arange(num_loops)[:, None] * d + np.arange(d)
    S_kk = S[block[:, :, None], block[:, None, :]]
    return np.einsum("ki,ki->k", e, np.linalg.solve(S_kk, e[:, :, None])[:, :, 0])


def sequentially_consistent(e: np.ndarray, S: np.ndarray, threshold: float) -> np.ndarray:
    """`(K,)` bool: loops admitted one at a time while each agrees with the map and those before it.

    Loops are visited by increasing innovation statistic `e_k^T S_kk^-1 e_k`; loop `k` is admitted
    when its innovation conditioned on the loops admitted so far is at most `threshold`. For a
    Gaussian the conditional statistic is the increase of the joint one, `e_T^T S_TT^-1 e_T`, so
    once one loop of a group that supports itself is in, the others are judged given it (they
    add little), while a false loop never hides among true ones: its own increase is tested, not
    a joint statistic diluted over many degrees of freedom.

    Args:
        e: `(K, d)` residuals of the candidate loops.
        S: `(K d, K d)` their joint innovation covariance (`egnc.nonlinear.marginals.innovations`).
        threshold: chi-square quantile for `d` degrees of freedom.
    """
    num_loops, d = e.shape
    block = np.arange(num_loops)[:, None] * d + np.arange(d)
    alone = _block_statistics(e, S)
    admitted = np.zeros(num_loops, dtype=bool)
    joint = 0.0
    for k in np.argsort(alone, kind="stable"):  # at most READMIT_BATCH small dense solves
        trial = admitted.copy()
        trial[k] = True
        rows = block[trial].ravel()
        statistic = float(e[trial].ravel() @ np.linalg.solve(S[np.ix_(rows, rows)], e[trial].ravel()))
        if statistic - joint <= threshold:
            admitted, joint = trial, statistic
    return admitted


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
    def over(cls, graph: PoseGraph, factors: BetweenFactors, edges: np.ndarray, linear_solver: str) -> RoundProblem:
        """The problem over the `edges` `(E,)` of `graph` (whose factors are `factors`)."""
        edges = edges.copy()
        return cls(edges, Problem.from_graph(graph.subgraph_edges(edges), linear_solver, factors.subset(edges)))

    def serves(self, inliers: np.ndarray, exactly: bool) -> bool:
        """Whether a round that accepts `inliers` `(E,)` is solved on this problem: its edges hold
        them, or are exactly them (`exactly`)."""
        return np.array_equal(inliers, self.edges) if exactly else not np.any(inliers & ~self.edges)

    def weights(self, inliers: np.ndarray) -> np.ndarray:
        """`(E_problem,)` weight of each of the problem's edges: 1 where `inliers` `(E,)`, else 0."""
        return inliers[self.edges].astype(np.float64)

    def solve(
        self, poses: np.ndarray, inliers: np.ndarray, options: SolverOptions, on_iteration: IterationCallback | None
    ) -> SolverResult:
        """Least squares of the `inliers` `(E,)` edges from `poses` `(N, n, n)`, each step direct."""
        every_edge = np.ones(len(self.problem.factors.edges), dtype=bool)  # the direct path, zeros included
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


def truncated_cost(r: np.ndarray, robust: np.ndarray, d: int, quantile: float) -> float:
    """Truncated least-squares cost `0.5 (sum_known r^2 + sum_loops min(r^2, chi2.ppf(q, d)))`.

    The cost a classification pays under the outlier test: an accepted loop its squared residual,
    a rejected one the threshold. Two decisions on the same graph are compared by it (the lower
    explains the measurements better); it depends on the poses only.

    Args:
        r: `(E,)` whitened residual norms.
        robust: `(E,)` bool, the loop closures (truncated); the other edges are quadratic.
        d: residual dimension.
        quantile: `q` of the outlier test (`GncOptions.outlier_quantile`).
    """
    r2 = r * r
    return 0.5 * float(np.sum(r2[~robust]) + np.sum(np.minimum(r2[robust], chi2_quantile(quantile, d))))


def lower_by_more_than_rounding(candidate: float, incumbent: float) -> bool:
    """Whether truncated cost `candidate` is below `incumbent` by more than a relative 1e-9: two
    starts that reach the same decision differ by rounding only, and the incumbent stays."""
    return candidate < incumbent * (1 - 1e-9)


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


def decide_outliers(
    graph: PoseGraph,
    poses: np.ndarray,
    robust: np.ndarray,
    solver_options: SolverOptions,
    gnc_options: GncOptions,
    linear_solver: str,
    factors: BetweenFactors,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
    inliers: np.ndarray | None = None,
    start: StageStart = "guess",
) -> Decision:
    """Refine on the accepted edges and re-decide until the classification holds.

    Args:
        graph: the pose graph.
        poses: `(N, n, n)` starting poses (the last GNC stage's solution).
        robust: `(E,)` bool, the loop closures that may be rejected.
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
    d = graph.tangent_dim
    r = factors.whitened_norms(factors.residuals(poses))
    if inliers is None:
        inliers = classify_inliers(r, robust, d, gnc_options)
    reports: list[StageReport] = []
    settled = False
    components = connected_components(graph.num_poses, graph.edges)[0]  # isolated vertices count too
    readmit_at = readmit_quantile(gnc_options, robust)
    strict = replace(gnc_options, outlier_quantile=readmit_at)
    ever_readmitted = np.zeros(graph.num_edges, dtype=bool)
    solved: dict[bytes, int] = {}  # classification -> its round in `rounds`
    rounds: list[tuple[np.ndarray, SolverResult, float]] = []  # inliers, solve, truncated cost
    # The rounds' problem (module docstring, "One analysis"): on a large system, the accepted
    # edges and every rejected loop that re-admission could take back at these poses.
    shared = d * graph.num_poses >= SHARED_ANALYSIS_MIN_UNKNOWNS
    members = inliers.copy()
    if shared:
        outside = np.flatnonzero(robust & ~inliers)
        members[outside] = _statistic_floor(factors.subset(outside), poses) <= chi2_quantile(readmit_at, d)
    system: RoundProblem | None = None
    loose = replace(solver_options, rel_cost_tol=max(solver_options.rel_cost_tol, ROUND_TOLERANCE))

    def round_problem(accepted: np.ndarray) -> RoundProblem:
        """The problem a round that accepts `accepted` `(E,)` solves on: the last one where it serves."""
        nonlocal system, members
        members = members | accepted if shared else accepted
        if system is None or not system.serves(accepted, exactly=not shared):
            system = None  # freed before the next is built
            system = RoundProblem.over(graph, factors, members, linear_solver)
        return system

    def tightened(refined: SolverResult, accepted: np.ndarray) -> SolverResult:
        """`refined`, the round of `accepted` `(E,)`, continued to `solver_options`' tolerance
        where it stopped at `ROUND_TOLERANCE`."""
        if not _stopped_loosely(refined, solver_options.rel_cost_tol):
            return refined
        offset = refined.iterations
        progress = None if on_iteration is None else lambda k, cost: on_iteration(offset + k, cost)
        # The round's iteration limit holds for both solves together; LM goes on from the
        # damping it had reached.
        options = replace(solver_options, max_iterations=solver_options.max_iterations - refined.iterations)
        if refined.next_damping > 0:
            options = replace(options, initial_damping=refined.next_damping)
        continued = round_problem(accepted).solve(refined.poses, accepted, options, progress)
        return _continued(refined, continued)

    def classified(r: np.ndarray, back: np.ndarray) -> np.ndarray:
        """The next round's accepted edges: the outlier test at residuals `r` `(E,)`, and `back`."""
        decided = classify_inliers(r, robust, d, gnc_options)
        if not gnc_options.readmit:
            return decided
        # A loop the innovation test admitted is held to that test's quantile from then on
        # (module docstring, "Hysteresis").
        decided |= ever_readmitted & classify_inliers(r, robust, d, strict)
        return (decided & inliers) | back

    for _ in range(MAX_ROUNDS):
        if connected_components(graph.num_poses, graph.edges[inliers])[0] != components:
            break
        started = time.perf_counter()
        round_system = round_problem(inliers)
        problem = round_system.problem
        refined = round_system.solve(poses, inliers, loose, on_iteration)
        r = factors.whitened_norms(factors.residuals(refined.poses))
        back = np.zeros(graph.num_edges, dtype=bool)
        if gnc_options.readmit:
            information = round_information(problem, refined)
            weights = round_system.weights(inliers)
            estimate = round_system.reach_estimate
            back = readmitted(problem, refined.poses, factors, ~inliers, r, readmit_at, information, weights, estimate)
            problem.step_solver.discard_factorization()  # not held while a new round problem is built
            ever_readmitted |= back
        decided = classified(r, back)
        if np.array_equal(decided, inliers):  # it holds: the round is solved to the full tolerance and checked again
            refined = tightened(refined, inliers)
            r = factors.whitened_norms(factors.residuals(refined.poses))
            decided = classified(r, back)
        poses = refined.poses
        solved[np.packbits(inliers).tobytes()] = len(rounds)
        rounds.append((inliers, refined, truncated_cost(r, robust, d, gnc_options.outlier_quantile)))
        reports.append(least_squares_report(refined, started, int(inliers.sum()), "decision", start))
        if on_stage is not None:
            on_stage(reports[-1])
        if np.array_equal(decided, inliers) or refined.status in (0, NUMERICAL_FAILURE):  # settled, or stuck
            settled = refined.status not in (0, NUMERICAL_FAILURE)
            break
        first = solved.get(np.packbits(decided).tobytes())
        if first is not None:  # a cycle: keep its classification of lowest truncated cost
            inliers, refined, _ = min(rounds[first:], key=lambda solved_round: solved_round[2])
            refined = tightened(refined, inliers)
            poses = refined.poses
            r = factors.whitened_norms(factors.residuals(poses))
            settled = True
            break
        inliers = decided
    return Decision(
        poses=poses,
        inliers=inliers,
        reports=tuple(reports),
        settled=settled,
        truncated_cost=truncated_cost(r, robust, d, gnc_options.outlier_quantile),
    )


@dataclass(frozen=True, eq=False)
class StartContext:
    """What every further start of the batch decision works on (`egnc.robust.starts`, `egnc.robust.regroup`,
    `egnc.robust.elimination`): each tries to beat the best decision so far from poses of its own.

    Attributes:
        graph: the pose graph.
        robust: `(E,)` bool, the loop closures that may be rejected.
        factors: the graph's factors.
        solver_options: options of each least-squares solve.
        gnc_options: outlier test and readmission options.
        linear_solver: resolved backend name.
        on_stage, on_iteration: progress callbacks (each solve a start runs is a stage).
    """

    graph: PoseGraph
    robust: np.ndarray
    factors: BetweenFactors
    solver_options: SolverOptions
    gnc_options: GncOptions
    linear_solver: str
    on_stage: StageCallback | None = None
    on_iteration: IterationCallback | None = None

    def chordal_poses(self, keep: np.ndarray) -> np.ndarray | None:
        """`(N, n, n)` chordal initialization over the edges `keep` `(E,)` bool, or None when the
        backend cannot factorize its system."""
        try:
            chordal = chordal_initialization(self.graph.subgraph_edges(keep), linear_solver=self.linear_solver)
        except SolverError:
            return None
        return to_matrices(self.graph.dim, chordal)

    def cost_at(self, poses: np.ndarray) -> float:
        """`truncated_cost` of the graph at `poses` `(N, n, n)`, at the outlier test's quantile."""
        r = self.factors.whitened_norms(self.factors.residuals(poses))
        return truncated_cost(r, self.robust, self.graph.tangent_dim, self.gnc_options.outlier_quantile)

    def decide(self, poses: np.ndarray, inliers: np.ndarray, start: StageStart) -> Decision:
        """`decide_outliers` from `poses` `(N, n, n)` and the first classification `inliers` `(E,)`."""
        return decide_outliers(
            self.graph,
            poses,
            self.robust,
            self.solver_options,
            self.gnc_options,
            self.linear_solver,
            self.factors,
            self.on_stage,
            self.on_iteration,
            inliers,
            start=start,
        )
