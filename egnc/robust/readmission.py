"""Re-admission: which rejected loop closures the map of the accepted edges agrees with.

Step 3 of each decision round (`egnc.robust.rounds`). Rejected loop closures are re-admitted by
their innovation statistic `e^T (Omega^-1 + A H^-1 A^T)^-1 e` (`egnc.nonlinear.marginals`; `H`
factorized by the round's last least-squares step, `egnc.robust.rounds.round_information`): how
well the map built without them predicts their measurements, within the combined uncertainty of
both (the residual alone, `r^2`, ignores how uncertain the relative pose of two far-apart poses
is). If the map agrees with *all* rejected loops, conditioned one on another, at
`chi2.ppf(q_readmit, d)`, all come back: nothing in the graph contradicts anything else (MIT,
smallGrid3D). Otherwise loops are re-admitted one at a time, each given those before it, with
the map credited with no more uncertainty of a loop's relative pose than the loop's own
(`credited_covariance`): where the map is much weaker than the loop, agreement within its
uncertainty says little, and the noisy Manhattan graphs absorbed gross outliers that way (recall
0.89, ATE 8.8 m on manhattan_noisy.irl when the full map covariance was credited).

A rejected loop with `r^2 <= chi2.ppf(q_readmit, d)` passes without its covariance: the innovation
statistic is never larger than `r^2`, since its covariance is the loop's own plus the map's (true
loops that the robust optimum let go are mostly of this kind: 363 of a 25 000-pose grid's first
round, which took seven batches of covariance solves). The others are tested in order of
increasing `r^2`, in batches of `READMIT_BATCH`; testing stops at the first batch in which none passes
(the all-agree test starts from the largest residuals and stops at the first batch that fails, or
before it when its largest loop alone rules it out, `_all_agree`),
and before solving a batch of which a bound that needs no covariance says none can pass
(`statistic_floor`). Where that bound leaves only a few loops of a batch (`SCOUT_LOOPS`), those
are tested alone first and the batch is solved only if one of them passes: a batch admits no
loop unless one passes alone. So a graph with thousands of gross false loops pays for one or two
batches of marginal covariances per round, not thousands, and a round that only confirms the
classification mostly pays for a few columns.

References:
    M. Kaess, F. Dellaert, "Covariance recovery from a square root information matrix for data
    association", RAS 2009 (innovation gating with marginal covariances).
"""

from __future__ import annotations

import numpy as np

from egnc.linalg.linear_solvers import Factorization, NotPositiveDefiniteError
from egnc.nonlinear.factors import BetweenFactors
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.marginals import ReachEstimate, covariance_solver, innovations
from egnc.robust.factor_set import FactorSet
from egnc.robust.kernels import chi2_quantile

READMIT_BATCH = 64
"""Rejected loops whose innovation statistics are computed together (one multi-column solve)."""

SCOUT_LOOPS = 8
"""A batch in which at most this many loops, but not all, can pass alone by `statistic_floor` is
first tested on those loops alone: where none passes, neither does the batch, and its solve is
skipped."""


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
        floor = statistic_floor(factors.subset(np.sort(candidates)), poses)
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


def readmitted_priors(factors: FactorSet, rejected: np.ndarray, r: np.ndarray, quantile: float) -> np.ndarray:
    """`(K,)` bool: the rejected priors the map of the accepted factors fits, `r^2 <= chi2.ppf(q, d_k)`.

    A prior's innovation statistic is at most its `r^2` (its covariance adds the map's
    uncertainty of the pose to the prior's own), so this admits only what the full test would;
    a prior just outside the threshold, which the map's own uncertainty would excuse, stays out.

    Args:
        factors: the edges' and the priors' factors.
        rejected: `(E + K,)` bool, the factors left out of the round.
        r: `(E + K,)` whitened residual norms at the round's solution.
        quantile: chi-square quantile of the test.
    """
    threshold = chi2_quantile(quantile, factors.priors_of(factors.dims))
    return factors.priors_of(rejected) & (factors.priors_of(r) ** 2 <= threshold)


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


def statistic_floor(loops: BetweenFactors, poses: np.ndarray) -> np.ndarray:
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
