"""The graduated non-convexity driver: run a schedule's stages, each an IRLS solve.

Stage k minimizes the loss the schedule chose from stage k-1's residuals (`egnc.schedules`) with
the sparse GN/LM solver (`egnc.least_squares`), starting from the initial guess (GTSAM's
`GncOptimizer` protocol) or, with `warm_start`, from stage k-1's poses. Loop closures whose weight
became negligible leave the factorization (`prune_weight`). After the last stage, loop closures
(robust edges) with `r^2 > chi2.ppf(outlier_quantile, d)` are classified as outliers (DESIGN.md
section 4; `outlier_threshold="distance"` compares `r` instead); known inliers never are. Graduated
methods then re-solve least squares on the accepted edges (`refine_on_inliers`).

References:
    H. Yang, P. Antonante, V. Tzoumas, L. Carlone, "Graduated Non-Convexity for Robust Spatial
    Perception", RA-L 2020 (the alternation of weight and variable updates).
    GTSAM, `gtsam/nonlinear/GncOptimizer.h` (each stage restarts from the initial values).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from egnc.connectivity import connected_components
from egnc.errors import EgncError
from egnc.factors import BetweenFactors
from egnc.graph import PoseGraph
from egnc.least_squares import IterationCallback, Problem, SolverOptions, solve_least_squares
from egnc.schedules import Schedule, Stage, ThresholdConvention, exceeds


@dataclass(frozen=True)
class GncOptions:
    """Options of the graduated solve.

    Attributes:
        c: shape of the SIG kernel (egnc, risam; riSAM uses 3) and of Geman-McClure (gm).
        threshold: egnc's strong-outlier test: `"squared"` compares `r^2` with
            `chi2.ppf(0.9, d)` (statistically consistent); `"distance"` compares `r`, as the
            authors' C++ reference. Squared flags more strong outliers early, which prunes them
            sooner (manhattanOlson3500 at 30%: 0.37x riSAM's time against 1.24x).
        outlier_threshold: the final outlier report: a loop closure is rejected when `r^2`
            (`"squared"`, the statistically consistent form of DESIGN.md section 4, default) or
            `r` (`"distance"`, the C++ reference's rule) exceeds `chi2.ppf(outlier_quantile, d)`.
            The benchmark decided the default (BENCHMARKS.md): `"distance"` stops reporting 7 of
            Intel's 895 true loops (r = 1.7 to 2.6 at the clean optimum; ATE cost 4.5 mm) but
            keeps a gross outlier of manhattan_noisy.irl (ATE cost 1.9 m) and loses 4 of 49
            noisy-Manhattan successes: a missed outlier costs metres, a dropped marginal inlier
            millimetres.
        outlier_quantile: the chi-square quantile of the outlier report.
        max_stages: stop graduating after this many stages (reported in the status message).
        refine: graduated methods only (egnc, risam, gnc-gm, gnc-tls): after classification,
            re-solve plain least squares on the accepted edges only (warm-started, with the
            caller's `SolverOptions`), so the trajectory is the one the accepted measurements
            imply rather than the slightly biased Geman-McClure optimum. Skipped when dropping
            the rejected edges would disconnect the graph.
        warm_start: start each stage from the previous stage's solution (True) or, as GTSAM's
            `GncOptimizer` does, from the initial guess (False). From a drifted odometry guess
            the first, least-squares stage bends the map to fit every false loop; warm-started
            stages inherit that basin (manhattanOlson3500 at 10% false loops: ATE 19 m warm,
            0.0 m restarted; see BENCHMARKS.md).
        stage_rel_cost_tol: graduated methods: each GNC stage stops when its relative cost
            decrease falls below `max(this, SolverOptions.rel_cost_tol)` (GTSAM's GNC uses
            1e-5); IRLS converges linearly, so a tight tolerance only costs iterations there.
            The refinement then converges to the caller's tolerance.
        prune_weight: robust edges whose IRLS weight for the next stage is below this leave the
            factorization from that stage on (they still count in the residuals the schedule
            and the outlier report see). Off (0) by default: pruning is irreversible, and
            after egnc's first stage it dropped true loops that the distorted least-squares
            stage had left with large residuals (sphere2500 at 30%: precision 0.887 with 1e-4,
            1.0 without); under stage restarts it saved only 14% on manhattanOlson3500 at 50%.
    """

    c: float = 3.0
    threshold: ThresholdConvention = "squared"
    outlier_threshold: ThresholdConvention = "squared"
    outlier_quantile: float = 0.95
    max_stages: int = 100
    refine: bool = True
    warm_start: bool = False
    stage_rel_cost_tol: float = 1e-6
    prune_weight: float = 0.0

    def __post_init__(self) -> None:
        for name in ("threshold", "outlier_threshold"):
            if getattr(self, name) not in ("squared", "distance"):
                raise EgncError(f"unknown {name} {getattr(self, name)!r}: choose 'squared' or 'distance'")
        if not 0.0 < self.outlier_quantile < 1.0:
            raise EgncError(f"outlier_quantile must be in (0, 1), got {self.outlier_quantile}")
        if self.c <= 0:
            raise EgncError(f"the kernel shape c must be positive, got {self.c}")
        if self.max_stages < 1:
            raise EgncError(f"max_stages must be at least 1, got {self.max_stages}")
        if not 0.0 <= self.prune_weight < 1.0:
            raise EgncError(f"prune_weight must be in [0, 1), got {self.prune_weight}")


@dataclass(frozen=True, eq=False)
class StageReport:
    """Summary of one stage.

    Attributes:
        mu_min, mu_mean, mu_max: statistics of the robust edges' `mu` (nan where the kernel has none).
        iterations: accepted solver steps.
        cost: the stage's own (robust or weighted) cost at its end.
        time_s: wall time of the stage in seconds.
        status: solver termination code (see `egnc.least_squares.STATUS_MESSAGES`).
        active_edges: edges in the stage's factorization (the others were pruned).
    """

    mu_min: float
    mu_mean: float
    mu_max: float
    iterations: int
    cost: float
    time_s: float
    status: int
    active_edges: int


StageCallback = Callable[[StageReport], None]
"""Receives each stage's report as soon as the stage ends."""


@dataclass(frozen=True, eq=False)
class GncOutcome:
    """What the driver hands back to `egnc.solve`.

    Attributes:
        poses: `(N, n, n)` final pose matrices.
        weights: `(E,)` final IRLS weights of the last stage's loss at `poses`.
        mu: `(E,)` last stage's `mu` (nan for known inliers and kernels without `mu`).
        stages: per-stage reports.
        status, message: termination of the last stage, or why graduation stopped early.
        timings: solver seconds per phase, summed over stages.
    """

    poses: np.ndarray
    weights: np.ndarray
    mu: np.ndarray
    stages: tuple[StageReport, ...]
    status: int
    message: str
    timings: dict[str, float]


def known_inlier_mask(graph: PoseGraph, known_inliers: str | np.ndarray) -> np.ndarray:
    """`(E,)` bool of edges kept quadratic: `"odometry"`, `"none"`, or an explicit `(E,)` mask."""
    if isinstance(known_inliers, str):
        if known_inliers == "odometry":
            return graph.is_odometry
        if known_inliers == "none":
            return np.zeros(graph.num_edges, dtype=bool)
        raise EgncError(f"unknown known_inliers {known_inliers!r}: choose 'odometry', 'none' or an (E,) bool mask")
    mask = np.asarray(known_inliers)
    if mask.dtype != bool or mask.shape != (graph.num_edges,):
        raise EgncError(f"known_inliers mask must be bool of shape ({graph.num_edges},), got {mask.dtype} {mask.shape}")
    return mask


def _mu_stats(stage: Stage, robust: np.ndarray) -> tuple[float, float, float]:
    mu = stage.mu[robust]
    if len(mu) == 0 or np.all(np.isnan(mu)):
        return (np.nan, np.nan, np.nan)
    return (float(np.nanmin(mu)), float(np.nanmean(mu)), float(np.nanmax(mu)))


def run_gnc(
    graph: PoseGraph,
    initial_poses: np.ndarray,
    schedule: Schedule,
    robust: np.ndarray,
    solver_options: SolverOptions,
    gnc_options: GncOptions,
    linear_solver: str,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
) -> GncOutcome:
    """Run `schedule`'s stages on `graph` from `initial_poses` `(N, n, n)`.

    Between stages, robust edges whose weight in the next stage would fall below
    `gnc_options.prune_weight` leave the factorization (not the residuals the schedule sees):
    false loop closures join distant poses and their fill-in dominates the Cholesky cost.

    Args:
        graph: the pose graph.
        initial_poses: `(N, n, n)` starting poses.
        schedule: decides each stage's loss.
        robust: `(E,)` bool, edges the schedule's kernel applies to.
        solver_options: options of each stage's GN/LM solve.
        gnc_options: stage limit and pruning weight.
        linear_solver: resolved backend name, `"cholmod"` or `"scipy"`.
        on_stage: called with each `StageReport` as soon as its stage ends (progress display).
        on_iteration: called with `(iterations, cost)` after each accepted step of a stage.
    """
    factors = BetweenFactors.from_graph(graph)
    active = np.ones(graph.num_edges, dtype=bool)
    problem = Problem.from_graph(graph, linear_solver)
    poses = initial_poses
    r = factors.whitened_norms(factors.residuals(poses))
    stage: Stage | None = schedule.first_stage(r)
    reports: list[StageReport] = []
    timings: dict[str, float] = {}
    last = stage
    status, message = 0, ""
    while stage is not None:
        if len(reports) == gnc_options.max_stages:
            status, message = 0, f"stopped after max_stages = {gnc_options.max_stages} stages"
            break
        started = time.perf_counter()
        start = poses if gnc_options.warm_start else initial_poses
        solution = solve_least_squares(problem, start, stage.loss.subset(active), solver_options, on_iteration)
        poses = solution.poses
        r = factors.whitened_norms(factors.residuals(poses))
        reports.append(
            StageReport(
                *_mu_stats(stage, robust),
                iterations=solution.iterations,
                cost=solution.cost,
                time_s=time.perf_counter() - started,
                status=solution.status,
                active_edges=int(active.sum()),
            )
        )
        if on_stage is not None:
            on_stage(reports[-1])
        for phase, seconds in solution.timings.items():
            timings[phase] = timings.get(phase, 0.0) + seconds
        status, message = solution.status, solution.message
        last = stage
        stage = schedule.next_stage(r, solution.converged)
        if stage is not None and gnc_options.prune_weight > 0:
            keep = active & ~(robust & (stage.loss.weight(r) < gnc_options.prune_weight))
            if keep.sum() < active.sum() and connected_components(graph.num_poses, graph.edges[keep])[0] == 1:
                active = keep
                problem = Problem.from_graph(graph.subgraph_edges(active), linear_solver)
    assert last is not None
    return GncOutcome(
        poses=poses,
        weights=last.loss.weight(r),
        mu=last.mu,
        stages=tuple(reports),
        status=status,
        message=message,
        timings=timings,
    )


def classify_inliers(r: np.ndarray, robust: np.ndarray, d: int, options: GncOptions) -> np.ndarray:
    """`(E,)` bool inlier flags: robust edges above the chi-square `outlier_quantile` are outliers.

    With `options.outlier_threshold == "squared"` (default) the test is `r^2 > chi2.ppf(q, d)`
    (DESIGN.md section 4); with `"distance"` it is `r > chi2.ppf(q, d)`, as in the authors' C++
    reference.
    """
    return ~(robust & exceeds(r, options.outlier_quantile, d, options.outlier_threshold))


MAX_REFINEMENTS = 3
"""Refine-and-reclassify rounds before the classification is taken as it stands."""


def refine_on_inliers(
    graph: PoseGraph,
    poses: np.ndarray,
    robust: np.ndarray,
    solver_options: SolverOptions,
    gnc_options: GncOptions,
    linear_solver: str,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[StageReport, ...]]:
    """Classify, re-solve least squares on the inliers, and repeat until the classification holds.

    The classification made at the Geman-McClure solution of the last stage is re-checked at the
    least-squares trajectory of the accepted edges: a marginal true loop closure that the robust
    kernel let drift past the threshold is re-admitted if the accepted measurements agree with it.
    At most `MAX_REFINEMENTS` rounds; a round that would disconnect the graph is not run.

    Returns:
        `(poses, inliers, reports)`: refined `(N, n, n)` poses, `(E,)` inlier flags consistent with
        them (unless the round limit was hit), and one `StageReport` per round.
    """
    factors = BetweenFactors.from_graph(graph)
    d = graph.tangent_dim
    inliers = classify_inliers(factors.whitened_norms(factors.residuals(poses)), robust, d, gnc_options)
    reports: list[StageReport] = []
    for _ in range(MAX_REFINEMENTS):
        if connected_components(graph.num_poses, graph.edges[inliers])[0] != 1:
            break
        problem = Problem.from_graph(graph.subgraph_edges(inliers), linear_solver)
        refined = solve_least_squares(problem, poses, None, solver_options, on_iteration)
        poses = refined.poses
        reports.append(
            StageReport(
                np.nan,
                np.nan,
                np.nan,
                refined.iterations,
                refined.cost,
                refined.time_s,
                refined.status,
                int(inliers.sum()),
            )
        )
        if on_stage is not None:
            on_stage(reports[-1])
        r = factors.whitened_norms(factors.residuals(poses))
        reclassified = classify_inliers(r, robust, d, gnc_options)
        if np.array_equal(reclassified, inliers):
            break
        inliers = reclassified
    return poses, inliers, tuple(reports)
