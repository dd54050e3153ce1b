"""The final outlier decision of the graduated methods: refine, re-test, re-admit.

GNC ends at a robust (Geman-McClure) optimum, where a loop closure's residual says how well it
fits a map from which the kernel had already down-weighted it. Deciding there rejects honest
loops: with few loops, or loops that support each other, the robust optimum lets them go and
bends the odometry back, and their residuals grow past any threshold (MIT, smallGrid3D).
So the decision is made on least-squares maps instead, in rounds (`egnc.robust.rounds`):

1. Solve least squares on the accepted edges (warm-started; the map the accepted measurements
   imply).
2. An accepted loop closure whose squared whitened residual `r^2` exceeds `chi2.ppf(q, d)` is
   rejected: it disagrees with the map even though it helped shape it.
3. Rejected loop closures are re-admitted where the map built without them predicts their
   measurements within the combined uncertainty of both (`egnc.robust.readmission`).
4. Repeat until the classification holds (or `MAX_ROUNDS`, or a round that reaches the
   iteration limit).

Decisions reached from different starts (`egnc.robust.pipeline`) are compared by their
truncated cost (`egnc.robust.costs`). This module holds what every start works on
(`StartContext`) and names the decision's public pieces in one place:

- `egnc.robust.costs`: `truncated_cost`, `lower_by_more_than_rounding`, `readmit_quantile`;
- `egnc.robust.rounds`: `decide_outliers`, `Decision`, `RoundProblem`, the rounds' constants;
- `egnc.robust.readmission`: `readmitted`, `sequentially_consistent`, `map_credit`,
  `credited_covariance`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.nonlinear.chordal import chordal_initialization
from egnc.nonlinear.factors import to_matrices
from egnc.nonlinear.least_squares import IterationCallback, SolverOptions
from egnc.nonlinear.prior_alignment import align_to_priors
from egnc.robust.costs import lower_by_more_than_rounding, readmit_quantile, truncated_cost
from egnc.robust.factor_set import Factors, FactorSet, factor_dims
from egnc.robust.gnc import GncOptions, StageCallback, StageStart
from egnc.robust.readmission import (
    READMIT_BATCH,
    SCOUT_LOOPS,
    credited_covariance,
    map_credit,
    readmitted,
    sequentially_consistent,
)
from egnc.robust.rounds import (
    MAX_ROUNDS,
    REUSED_DAMPING,
    ROUND_TOLERANCE,
    SHARED_ANALYSIS_MIN_UNKNOWNS,
    Decision,
    RoundProblem,
    decide_outliers,
    least_squares_report,
    round_information,
)

__all__ = [
    "MAX_ROUNDS",
    "READMIT_BATCH",
    "REUSED_DAMPING",
    "ROUND_TOLERANCE",
    "SCOUT_LOOPS",
    "SHARED_ANALYSIS_MIN_UNKNOWNS",
    "Decision",
    "RoundProblem",
    "StartContext",
    "credited_covariance",
    "decide_outliers",
    "least_squares_report",
    "lower_by_more_than_rounding",
    "map_credit",
    "readmit_quantile",
    "readmitted",
    "round_information",
    "sequentially_consistent",
    "truncated_cost",
]


@dataclass(frozen=True, eq=False)
class StartContext:
    """What every further start of the batch decision works on (`egnc.robust.starts`, `egnc.robust.regroup`,
    `egnc.robust.elimination`): each tries to beat the best decision so far from poses of its own.

    Attributes:
        graph: the pose graph.
        robust: `(F,)` bool, the factors that may be rejected: loop closures, and priors where
            `factors` is a `FactorSet` (`(E + K,)`, edges then priors).
        factors: the graph's factors (`egnc.robust.factor_set`).
        solver_options: options of each least-squares solve.
        gnc_options: outlier test and readmission options.
        linear_solver: resolved backend name.
        on_stage, on_iteration: progress callbacks (each solve a start runs is a stage).
    """

    graph: PoseGraph
    robust: np.ndarray
    factors: Factors
    solver_options: SolverOptions
    gnc_options: GncOptions
    linear_solver: str
    on_stage: StageCallback | None = None
    on_iteration: IterationCallback | None = None

    def chordal_poses(self, keep: np.ndarray) -> np.ndarray | None:
        """`(N, n, n)` chordal initialization over the factors `keep`, or None when the backend
        cannot factorize its system.

        `keep`: `(E,)` bool over the edges, or `(F,)` over the factors (`robust`'s shape). The
        relaxation is solved over the kept edges; where the graph has priors, the map is then
        moved onto the kept priors (all of them for an `(E,)` mask) by the trimmed rigid fit of
        `egnc.nonlinear.prior_alignment`, so that it starts in the fixes' frame as the guess does.
        """
        graph = self.graph
        try:
            chordal = chordal_initialization(
                graph.subgraph_edges(keep[: graph.num_edges]), linear_solver=self.linear_solver
            )
        except SolverError:
            return None
        if graph.num_priors:
            kept = keep[graph.num_edges :] if len(keep) > graph.num_edges else np.ones(graph.num_priors, dtype=bool)
            if kept.any():
                chordal = align_to_priors(replace(graph, priors=graph.priors.subset(kept)), chordal)
        return to_matrices(graph.dim, chordal)

    def cost_at(self, poses: np.ndarray) -> float:
        """`truncated_cost` of the graph at `poses` `(N, n, n)`, at the outlier test's quantile."""
        r = self.factors.whitened_norms(self.factors.residuals(poses))
        return truncated_cost(r, self.robust, self.dims, self.gnc_options.outlier_quantile)

    @property
    def dims(self) -> int | np.ndarray:
        """The chi-square tests' dimension: `d`, or `(E + K,)` per factor (`egnc.robust.factor_set`)."""
        return factor_dims(self.graph, self.factors)

    @property
    def with_priors(self) -> bool:
        """Whether priors are candidates: the per-factor arrays are `(E + K,)`, edges then priors."""
        return isinstance(self.factors, FactorSet)

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
