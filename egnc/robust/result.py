"""`Result`: what `egnc.solve` hands back, and the fields that follow from its decision."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from egnc.graph import PoseGraph
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import NOTHING_TO_OPTIMIZE, STATUS_MESSAGES
from egnc.nonlinear.prior_factors import prior_cost
from egnc.robust.costs import truncated_cost
from egnc.robust.diagnostics import solve_warnings
from egnc.robust.factor_set import Factors, FactorSet
from egnc.robust.gnc import GncOptions, StageReport, classify_inliers, iteration_limited
from egnc.robust.parts import part_group_warning

__all__ = [
    "DecidedFields",
    "PriorDecision",
    "Result",
    "ResultCosts",
    "decided_fields",
    "nothing_to_optimize",
    "result_costs",
]


@dataclass(frozen=True, eq=False)
class Result:
    """Outcome of `egnc.solve`.

    Attributes:
        graph: the input graph with optimized poses.
        method: the method used.
        linear_solver: the linear backend used, `"cholmod"`, `"rslab"` or `"scipy"`.
        residual_norms: `(E,)` whitened residual norms `r` at the solution (never kernel-scaled);
            for graduated methods the solution is the least-squares optimum of the accepted edges.
        weights: `(E,)` IRLS weight of each edge at the end of the last GNC stage of the first
            start (`stages[0].start`: the initial guess or the runs' map; 1 for known inliers and
            least squares).
        mu: `(E,)` final kernel parameter of each edge (nan for known inliers and for kernels
            without one).
        known_inliers: `(E,)` bool, edges held quadratic (odometry by default).
        inliers: `(E,)` bool, false for the loop closures rejected as outliers: for graduated
            methods the decision of `egnc.robust.decision` (`r^2 > chi2.ppf(q, d)` on the least-squares
            map of the accepted edges, q = `GncOptions.outlier_quantile`, 0.99 by default); for
            fixed kernels the same test at their solution; all true for `"l2"`.
        initial_cost: least-squares cost `0.5 sum r^2` at the initial guess.
        cost: least-squares cost `0.5 sum r^2` at the solution, over all edges (rejected ones too).
        accepted_cost: the same over the accepted edges only.
        truncated_cost: `egnc.robust.decision.truncated_cost` at the solution: accepted loops pay
            `r^2 / 2`, rejected ones `chi2.ppf(q, d) / 2`; the cost by which two decisions are
            compared.
        iterations: accepted solver steps over all stages.
        stages: per-stage reports; with `GncOptions.refine`, the last one is the least-squares
            refinement on the accepted edges (its `mu` statistics are nan).
        status: termination code of the last solve (1, 2, 3 mean converged; see
            `egnc.nonlinear.least_squares.STATUS_MESSAGES`).
        message: termination reason.
        time_s: wall time in seconds, from graph to result.
        timings: seconds per solver phase, summed over stages.
        robust_residual_norms: `(E,)` `r` where `weights` are taken, before the outlier
            decision (the robust optimum; equal to `residual_norms` for single-stage methods).
            With `residual_norms` it explains a rejection: a loop far off at both is false.
        init: the initial guess used (`egnc.api.INITIALIZATIONS`).
        start: where the decision that was kept started: `"guess"` (the GNC solve from `init`),
            one of `GncOptions.starts` (`egnc.robust.pipeline`: `"runs"`, the GNC solve from the
            chordal map of the loops in runs; `"chordal"`, the chordal initialization;
            `"chordal-all"`, the GNC stage run again from the chordal initialization of every
            edge; `"regrouped"`, rejected runs of loops put back together; `"elimination"`,
            backward elimination from least squares over every edge), or `"online"`
            (`egnc.online.OnlineSolver`'s estimate).
        warnings: one sentence per thing the user should check before trusting the result
            (a stage stopped at its iteration limit, most loop closures rejected, ...).
        settled: whether the kept decision's rounds reached a classification that no longer
            changed (`egnc.robust.decision.Decision.settled`); True where no decision was made.
        prior_residual_norms: `(K,)` whitened residual norms of the priors at the solution,
            where priors were candidates for rejection (`egnc.robust.factor_set`); else None.
        prior_inliers: `(K,)` bool, false for the priors rejected as outliers (tested at their own
            dimension: `r^2 > chi2.ppf(q, d_k)`); None where priors were held quadratic.
        prior_candidates: `(K,)` bool, the priors that could be rejected; None where none could.
    """

    graph: PoseGraph
    method: str
    linear_solver: str
    residual_norms: np.ndarray
    weights: np.ndarray
    mu: np.ndarray
    known_inliers: np.ndarray
    inliers: np.ndarray
    initial_cost: float
    cost: float
    iterations: int
    stages: tuple[StageReport, ...]
    status: int
    message: str
    time_s: float
    timings: dict[str, float]
    robust_residual_norms: np.ndarray
    accepted_cost: float
    truncated_cost: float
    warnings: tuple[str, ...] = ()
    init: str = "file"
    start: str = "guess"
    settled: bool = True
    prior_residual_norms: np.ndarray | None = None
    prior_inliers: np.ndarray | None = None
    prior_candidates: np.ndarray | None = None

    def __repr__(self) -> str:
        loops = int(np.count_nonzero(~self.known_inliers))
        return (
            f"Result(method={self.method!r}, poses={self.graph.num_poses}, edges={self.graph.num_edges},"
            f" rejected={len(self.rejected_edges)} of {loops} loop closures,{self._priors_text()} cost={self.cost:.6g},"
            f" stages={len(self.stages)}, iterations={self.iterations}, status={self.status}"
            f" ({self.message!r}), time_s={self.time_s:.3g}, warnings={len(self.warnings)})"
        )

    def _priors_text(self) -> str:
        """`" rejected_priors=k of K,"` where priors were candidates, else empty (the `repr`)."""
        if self.prior_candidates is None:
            return ""
        return f" rejected_priors={len(self.rejected_priors)} of {int(self.prior_candidates.sum())},"

    @property
    def converged(self) -> bool:
        """Whether the last solve and every stage of the kept start stopped on a convergence criterion."""
        return self.status in (1, 2, 3) and not iteration_limited(self.stages, self.start)

    @property
    def rejected_edges(self) -> np.ndarray:
        """0-based factor indices (`PoseGraph.edge_factor_index`: every edge and prior line in file
        order; the edge index when the graph has no prior) of the edges rejected as outliers."""
        return self.graph.edge_factor_index[~self.inliers]

    @property
    def rejected_priors(self) -> np.ndarray:
        """0-based factor indices (`PoseGraph.prior_factor_index`) of the priors rejected as
        outliers; empty where the priors were known inliers (`egnc.solve(known_inliers=...)`)."""
        if self.prior_inliers is None:
            return np.zeros(0, dtype=np.int64)
        return self.graph.prior_factor_index[~self.prior_inliers]


@dataclass(frozen=True, eq=False)
class PriorDecision:
    """The decision on priors that were candidates for rejection (`egnc.robust.factor_set`).

    Attributes:
        residual_norms: `(K,)` whitened residual norms at the solution.
        inliers: `(K,)` bool, the accepted priors.
        candidates: `(K,)` bool, the priors that could be rejected.
        costs: the priors' shares of `Result.accepted_cost` (accepted priors' `r^2 / 2`) and of
            `Result.truncated_cost` (a rejected prior pays `chi2.ppf(q, d_k) / 2`).
    """

    residual_norms: np.ndarray
    inliers: np.ndarray
    candidates: np.ndarray
    costs: tuple[float, float]

    @classmethod
    def of(
        cls, factors: Factors, r: np.ndarray, inliers: np.ndarray, robust: np.ndarray, quantile: float
    ) -> PriorDecision | None:
        """The priors' part of the `(F,)` per-factor `r`, `inliers` and `robust` (candidates) at
        the outlier test's `quantile`; None where `factors` holds no priors."""
        if not isinstance(factors, FactorSet):
            return None
        r_p, inliers_p, robust_p = factors.priors_of(r), factors.priors_of(inliers), factors.priors_of(robust)
        accepted = 0.5 * float(np.sum(r_p[inliers_p] ** 2))
        truncated = truncated_cost(r_p, robust_p, factors.priors_of(factors.dims), quantile)
        return cls(r_p, inliers_p.copy(), robust_p.copy(), (accepted, truncated))

    def result_fields(self) -> dict[str, np.ndarray]:
        """The `Result` fields of the priors' decision."""
        return {
            "prior_residual_norms": self.residual_norms,
            "prior_inliers": self.inliers,
            "prior_candidates": self.candidates,
        }


class ResultCosts(TypedDict):
    """The cost fields of a `Result` (see its docstring)."""

    initial_cost: float
    cost: float
    accepted_cost: float
    truncated_cost: float


def result_costs(
    initial_r: np.ndarray, r: np.ndarray, inliers: np.ndarray, robust: np.ndarray, d: int, quantile: float
) -> ResultCosts:
    """The cost fields of a `Result` from `(E,)` residual norms at the guess and at the solution.

    Args:
        initial_r, r: `(E,)` whitened residual norms at the initial guess and at the solution.
        inliers: `(E,)` bool, the accepted edges.
        robust: `(E,)` bool, the loop closures.
        d: residual dimension.
        quantile: the outlier test's quantile (`GncOptions.outlier_quantile`).
    """
    return ResultCosts(
        initial_cost=float(0.5 * np.sum(initial_r**2)),
        cost=float(0.5 * np.sum(r**2)),
        accepted_cost=float(0.5 * np.sum(r[inliers] ** 2)),
        truncated_cost=truncated_cost(r, robust, d, quantile),
    )


class DecidedFields(ResultCosts):
    """The fields of a `Result` that follow from its decision (see its docstring)."""

    iterations: int
    warnings: tuple[str, ...]
    start: str
    settled: bool


def decided_fields(
    graph: PoseGraph,
    result_poses: np.ndarray,
    initial_r: np.ndarray,
    r: np.ndarray,
    inliers: np.ndarray,
    robust: np.ndarray,
    stages: tuple[StageReport, ...],
    gnc_options: GncOptions,
    *,
    start: str,
    settled: bool,
    disputed: np.ndarray | None,
    priors: PriorDecision | None = None,
) -> DecidedFields:
    """Costs, iteration count, warnings, start and settledness of a `Result`.

    Args:
        graph: the graph at its initial guess.
        result_poses: `(N, P)` the result's poses.
        initial_r, r: `(E,)` whitened residual norms at the initial guess and at `result_poses`.
        inliers: `(E,)` bool, the accepted edges.
        robust: `(E,)` bool, the loop closures.
        stages: every stage run (every start's included).
        gnc_options: the outlier test's options.
        start, settled, disputed: the kept decision's start, whether it settled, and the loops the
            other starts' decisions accepted where it rejects (None when only one start decided).
        priors: the decision on the priors where they were candidates; None: held quadratic.
    """
    d = graph.tangent_dim
    initial_fits = classify_inliers(initial_r, robust, d, gnc_options)
    # The priors' cost (held quadratic in this release: never rejected) is part of every cost field.
    prior_costs = (prior_cost(graph.priors, graph.poses), prior_cost(graph.priors, result_poses))
    warnings = solve_warnings(
        graph,
        stages,
        robust,
        inliers,
        initial_r,
        r,
        initial_fits,
        result_poses,
        start=start,
        settled=settled,
        disputed=disputed,
        prior_costs=prior_costs,
    )
    quantile = gnc_options.outlier_quantile
    parts = part_group_warning(graph, robust, inliers, to_matrices(graph.dim, result_poses), quantile)
    warnings += () if parts is None else (parts,)
    costs = result_costs(initial_r, r, inliers, robust, d, quantile)
    if graph.num_priors:
        accepted, truncated = (prior_costs[1], prior_costs[1]) if priors is None else priors.costs
        costs = ResultCosts(
            initial_cost=costs["initial_cost"] + prior_costs[0],
            cost=costs["cost"] + prior_costs[1],
            accepted_cost=costs["accepted_cost"] + accepted,
            truncated_cost=costs["truncated_cost"] + truncated,
        )
    return DecidedFields(
        **costs,
        iterations=sum(stage.iterations for stage in stages),
        warnings=warnings,
        start=start,
        settled=settled,
    )


def nothing_to_optimize(
    graph: PoseGraph,
    method: str,
    known: np.ndarray,
    backend: str,
    factors: BetweenFactors,
    init: str,
    started: float,
    gnc_options: GncOptions,
) -> Result:
    """The `Result` of a graph whose poses are all fixed: the graph unchanged, no stage run, a warning."""
    r = factors.whitened_norms(factors.residuals(to_matrices(graph.dim, graph.poses)))
    inliers = np.ones(graph.num_edges, dtype=bool)
    return Result(
        graph=graph,
        method=method,
        linear_solver=backend,
        residual_norms=r,
        weights=np.ones(graph.num_edges),
        mu=np.full(graph.num_edges, np.nan),
        known_inliers=known,
        inliers=inliers,
        **result_costs(r, r, inliers, ~known, graph.tangent_dim, gnc_options.outlier_quantile),
        iterations=0,
        stages=(),
        status=NOTHING_TO_OPTIMIZE,
        message=STATUS_MESSAGES[NOTHING_TO_OPTIMIZE],
        time_s=time.perf_counter() - started,
        timings={},
        robust_residual_norms=r,
        warnings=(
            f"all {graph.num_poses} poses are fixed: there is nothing to optimize; the graph is returned "
            "unchanged and no edge is rejected",
        ),
        init=init,
    )
