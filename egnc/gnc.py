"""The graduated non-convexity driver: run a schedule's stages, each a warm-started IRLS solve.

Stage k minimizes the loss the schedule chose from stage k-1's residuals (`egnc.schedules`) with
the sparse GN/LM solver (`egnc.least_squares`), starting from stage k-1's poses. After the last
stage, loop closures (robust edges) with `r^2 > chi2.ppf(outlier_quantile, d)` are classified as
outliers (DESIGN.md section 4); known inliers never are.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.schedules import Schedule, Stage, exceeds


@dataclass(frozen=True)
class GncOptions:
    """Options of the graduated solve.

    Attributes:
        c: shape of the SIG kernel (egnc, risam; riSAM uses 3) and of Geman-McClure (gm).
        threshold: egnc's strong-outlier test, `"squared"` (`r^2` against the chi-square
            quantile) or `"distance"` (`r` against it, as the authors' C++ reference).
        outlier_quantile: a loop closure is rejected when `r^2 > chi2.ppf(outlier_quantile, d)`.
        max_stages: stop graduating after this many stages (reported in the status message).
        refine: graduated methods only (egnc, risam, gnc-gm, gnc-tls): after classification,
            re-solve plain least squares on the accepted edges only
            (warm-started), so the trajectory is the one the accepted measurements imply rather
            than the slightly biased Geman-McClure optimum. Skipped when nothing was rejected
            or when dropping the rejected edges would disconnect the graph.
    """

    c: float = 3.0
    threshold: str = "squared"
    outlier_quantile: float = 0.95
    max_stages: int = 100
    refine: bool = True

    def __post_init__(self) -> None:
        if self.threshold not in ("squared", "distance"):
            raise EgncError(f"unknown threshold convention {self.threshold!r}: choose 'squared' or 'distance'")
        if not 0.0 < self.outlier_quantile < 1.0:
            raise EgncError(f"outlier_quantile must be in (0, 1), got {self.outlier_quantile}")
        if self.c <= 0:
            raise EgncError(f"the kernel shape c must be positive, got {self.c}")
        if self.max_stages < 1:
            raise EgncError(f"max_stages must be at least 1, got {self.max_stages}")


@dataclass(frozen=True, eq=False)
class StageReport:
    """Summary of one stage.

    Attributes:
        mu_min, mu_mean, mu_max: statistics of the robust edges' `mu` (nan where the kernel has none).
        iterations: accepted solver steps.
        cost: the stage's own (robust or weighted) cost at its end.
        time_s: wall time of the stage in seconds.
        status: solver termination code (see `egnc.least_squares.STATUS_MESSAGES`).
    """

    mu_min: float
    mu_mean: float
    mu_max: float
    iterations: int
    cost: float
    time_s: float
    status: int


@dataclass(frozen=True, eq=False)
class GncOutcome:
    """What the driver hands back to `egnc.solve`.

    Attributes:
        poses: `(N, n, n)` final pose matrices.
        residual_norms: `(E,)` whitened residual norms at `poses`.
        weights: `(E,)` final IRLS weights of the last stage's loss at `poses`.
        mu: `(E,)` last stage's `mu` (nan for known inliers and kernels without `mu`).
        stages: per-stage reports.
        status, message: termination of the last stage, or why graduation stopped early.
        timings: solver seconds per phase, summed over stages.
    """

    poses: np.ndarray
    residual_norms: np.ndarray
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
    problem: Problem,
    initial_poses: np.ndarray,
    schedule: Schedule,
    robust: np.ndarray,
    solver_options: SolverOptions,
    max_stages: int,
) -> GncOutcome:
    """Run `schedule`'s stages on `problem` from `initial_poses` `(N, n, n)`.

    Args:
        problem: factors, pattern and linear solver, shared by every stage.
        initial_poses: `(N, n, n)` starting poses.
        schedule: decides each stage's loss.
        robust: `(E,)` bool, edges the schedule's kernel applies to (for the `mu` statistics).
        solver_options: options of each stage's GN/LM solve.
        max_stages: upper bound on the number of stages.
    """
    factors = problem.factors
    poses = initial_poses
    r = factors.whitened_norms(factors.residuals(poses))
    stage: Stage | None = schedule.first_stage(r)
    reports: list[StageReport] = []
    timings: dict[str, float] = {}
    last = stage
    status, message = 0, ""
    while stage is not None:
        if len(reports) == max_stages:
            status, message = 0, f"stopped after max_stages = {max_stages} stages"
            break
        started = time.perf_counter()
        solution = solve_least_squares(problem, poses, stage.loss, solver_options)
        poses, r = solution.poses, solution.residual_norms
        reports.append(
            StageReport(
                *_mu_stats(stage, robust),
                iterations=solution.iterations,
                cost=solution.cost,
                time_s=time.perf_counter() - started,
                status=solution.status,
            )
        )
        for phase, seconds in solution.timings.items():
            timings[phase] = timings.get(phase, 0.0) + seconds
        status, message = solution.status, solution.message
        last = stage
        stage = schedule.next_stage(r, solution.converged)
    assert last is not None
    return GncOutcome(
        poses=poses,
        residual_norms=r,
        weights=last.loss.weight(r),
        mu=last.mu,
        stages=tuple(reports),
        status=status,
        message=message,
        timings=timings,
    )


def classify_inliers(r: np.ndarray, robust: np.ndarray, d: int, quantile: float) -> np.ndarray:
    """`(E,)` bool inlier flags: robust edges with `r^2 > chi2.ppf(quantile, d)` are outliers."""
    return ~(robust & exceeds(r, quantile, d, "squared"))
