"""The graduated non-convexity driver: run a schedule's stages, each an IRLS solve.

Stage k minimizes the loss the schedule chose from stage k-1's residuals (`egnc.robust.schedules`) with
the sparse GN/LM solver (`egnc.nonlinear.least_squares`), starting from the initial guess (GTSAM's
`GncOptimizer` protocol) or, with `warm_start`, from stage k-1's poses. Every edge stays in every
solve: the solver's linear algebra keeps the cost of down-weighted loops low
(`egnc.nonlinear.least_squares`). After the last stage, loop closures
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
import warnings
from collections.abc import Callable, Sequence
from dataclasses import InitVar, dataclass, field, replace
from typing import Literal

import numpy as np

from egnc.errors import OptionError, OptionTypeError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_bool, check_choice, check_float, check_int
from egnc.nonlinear.least_squares import (
    NUMERICAL_FAILURE,
    IterationCallback,
    SolverOptions,
    SolverResult,
    solve_least_squares,
)
from egnc.robust.factor_set import Factors, factor_problem
from egnc.robust.losses import FixedWeightLoss, KernelLoss
from egnc.robust.schedules import FIXED_LAST_STAGE_METHODS, Schedule, Stage, ThresholdConvention, exceeds

StartName = Literal["runs", "chordal", "chordal-all", "regrouped", "elimination", "parts"]
"""A start of the outlier decision other than the initial guess (`egnc.robust.pipeline`)."""

START_NAMES: tuple[StartName, ...] = ("runs", "chordal", "chordal-all", "regrouped", "elimination", "parts")
"""Every start `GncOptions.starts` accepts, in the default order (`egnc.robust.pipeline.STARTS`)."""

DEPRECATED_START_FLAGS: dict[str, StartName] = {
    "runs_start": "runs",
    "chordal_start": "chordal",
    "chordal_all_start": "chordal-all",
    "regroup_start": "regrouped",
    "elimination_start": "elimination",
}
"""The booleans that switched the starts before `GncOptions.starts` (deprecated, kept for one
release) and the start each switches."""

START_OPTIONS = tuple(DEPRECATED_START_FLAGS)
"""Deprecated: the former `GncOptions` booleans of the starts. `GncOptions(starts=())` is the
decision from the GNC stage of the initial guess alone."""


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
            A stage whose loss would equal the previous one's is never run, and graduation also
            stops after two stages in a row that reached `SolverOptions.max_iterations` (the
            result then carries a warning).
        refine: graduated methods only (egnc, risam, gnc-gm, gnc-tls): after classification,
            decide on least-squares maps of the accepted edges (`egnc.robust.decision`): re-solve
            least squares on them (warm-started, with the caller's `SolverOptions`), reject the
            accepted loops that still exceed the threshold, re-admit rejected ones (`readmit`),
            and repeat until the classification holds. Skipped when dropping the rejected
            edges would disconnect the graph.
        readmit: with `refine`, re-admit a rejected loop closure whose innovation statistic
            (its residual against the map of the accepted edges, whitened by its own covariance
            plus the marginal covariance of the relative pose it measures), conditioned on the
            loops re-admitted with it, is below `chi2.ppf(readmit_quantile, d)`. Stricter than
            the test of accepted loops because an excluded loop's residual is not shrunk by its
            own pull; the benchmark chose 0.9999 (BENCHMARKS.md): at 0.99 three true Intel
            loops that only agree with each other stayed out (precision 0.971 at 10%).
        readmit_false_alarms: on a graph of `L` loop closures, re-admission's quantile is
            raised to `1 - readmit_false_alarms / L` where that is above `readmit_quantile`
            (by default on graphs of more than 10 000 loops): the expected number of honest
            loops its test keeps out of one graph stays at most this many, however large the
            graph (`egnc.robust.decision.readmit_quantile`). None: every graph uses `readmit_quantile`.
        warm_start: start each stage from the previous stage's solution (True) or, as GTSAM's
            `GncOptimizer` does, from the initial guess (False). From a drifted odometry guess
            the first, least-squares stage bends the map to fit every false loop; warm-started
            stages inherit that basin (manhattanOlson3500 at 10% false loops: ATE 19 m warm,
            0.0 m restarted; see BENCHMARKS.md). With restarts a stage's poses reach the result
            only through the next stage's loss, and egnc's and riSAM's last stage puts every
            loop at `mu = 1` whatever came before: only that stage is solved (the same poses
            and decision as solving every stage, bit for bit; docs/method.md).
        starts: with `refine`, the starts that try to beat the decision from the initial guess,
            in the order they run (`egnc.robust.pipeline`; `START_NAMES`, all by default). Each
            proposes a classification from poses of its own; the decision of lowest truncated
            least-squares cost is kept (`Result.start` names it). `"runs"`, which must come first,
            starts the GNC stage from the chordal map of the loops that come in runs where that
            fits better than the guess; `"chordal"` decides from the chordal initialization of the
            trusted edges; `"chordal-all"` runs the GNC stage again from the chordal
            initialization of every edge; `"regrouped"` puts rejected runs of loops back together;
            `"elimination"` eliminates loops backwards from least squares over every edge;
            `"parts"`, where the known inliers fall into parts (two robots), decides from each
            group of agreeing loops between them (`egnc.robust.parts`). `()` decides from the initial guess alone.
        every_stage: solve every stage of the schedule even when, under restarts, only the last
            one decides the result: to watch the graduation stage by stage (same result, more time).
        stage_rel_cost_tol: graduated methods with `refine`: each GNC stage stops when its
            relative cost decrease falls below `max(this, SolverOptions.rel_cost_tol)`, and the
            decision rounds then solve least squares to the caller's tolerance (without
            `refine` the stages do). None (default): chosen by the stage protocol
            (`stage_tolerance`).

    Deprecated keyword arguments (one release): `runs_start`, `chordal_start`,
    `chordal_all_start`, `regroup_start`, `elimination_start`. Each adds its start to `starts`
    (True) or removes it (False), with a `DeprecationWarning`.

    Every field is checked at construction (bools must be bools, `max_stages` an int, the
    numbers finite, `starts` known names); a wrong type or value raises `OptionError` naming the
    field.
    """

    c: float = 3.0
    threshold: ThresholdConvention = "squared"
    outlier_threshold: ThresholdConvention = "squared"
    outlier_quantile: float = 0.99
    max_stages: int = 100
    refine: bool = True
    readmit: bool = True
    readmit_quantile: float = 0.9999
    readmit_false_alarms: float | None = 1.0
    warm_start: bool = False
    starts: tuple[StartName, ...] = START_NAMES
    every_stage: bool = False
    stage_rel_cost_tol: float | None = None
    runs_start: InitVar[bool | None] = None
    chordal_start: InitVar[bool | None] = None
    chordal_all_start: InitVar[bool | None] = None
    regroup_start: InitVar[bool | None] = None
    elimination_start: InitVar[bool | None] = None

    def __post_init__(
        self,
        runs_start: bool | None,
        chordal_start: bool | None,
        chordal_all_start: bool | None,
        regroup_start: bool | None,
        elimination_start: bool | None,
    ) -> None:
        """Check every field's type and range (`egnc.graph.checks`), storing plain Python values."""
        flags = dict(
            zip(
                DEPRECATED_START_FLAGS, (runs_start, chordal_start, chordal_all_start, regroup_start, elimination_start)
            )
        )
        checked: dict[str, object] = {
            "c": check_float("GncOptions.c", self.c, 0.0, open_low=True),
            "max_stages": check_int("GncOptions.max_stages", self.max_stages, 1),
        }
        if self.stage_rel_cost_tol is not None:
            checked["stage_rel_cost_tol"] = check_float("GncOptions.stage_rel_cost_tol", self.stage_rel_cost_tol, 0.0)
        if self.readmit_false_alarms is not None:
            checked["readmit_false_alarms"] = check_float(
                "GncOptions.readmit_false_alarms", self.readmit_false_alarms, 0.0, open_low=True
            )
        for name in ("threshold", "outlier_threshold"):
            checked[name] = check_choice(f"GncOptions.{name}", getattr(self, name), ("squared", "distance"))
        for name in ("outlier_quantile", "readmit_quantile"):
            value = getattr(self, name)
            checked[name] = check_float(f"GncOptions.{name}", value, 0.0, 1.0, open_low=True, open_high=True)
        for name in ("refine", "readmit", "warm_start", "every_stage"):
            checked[name] = check_bool(f"GncOptions.{name}", getattr(self, name))
        checked["starts"] = _with_flags(check_starts(self.starts), flags)
        for name, value in checked.items():
            object.__setattr__(self, name, value)


def check_starts(starts: object) -> tuple[StartName, ...]:
    """`starts` as a tuple of known start names, `"runs"` first if given.

    Raises:
        OptionError: not a sequence of strings, an unknown or repeated name, or `"runs"` not first.
    """
    known = ", ".join(repr(name) for name in START_NAMES)
    if isinstance(starts, str) or not isinstance(starts, (tuple, list)):
        raise OptionTypeError(f"GncOptions.starts must be a tuple of start names ({known}), got {starts!r:.60}")
    for name in starts:
        if name not in START_NAMES:
            raise OptionError(f"GncOptions.starts has an unknown start {name!r:.40}; known starts: {known}")
    if len(set(starts)) != len(starts):
        raise OptionError(f"GncOptions.starts names a start twice: {tuple(starts)!r}")
    if "runs" in starts and starts[0] != "runs":
        raise OptionError("GncOptions.starts must list 'runs' first (it chooses where the GNC stage starts)")
    return tuple(starts)


def _with_flags(starts: tuple[StartName, ...], flags: dict[str, bool | None]) -> tuple[StartName, ...]:
    """`starts` switched by the deprecated booleans `flags` (None: not given): False removes a
    start, True adds a missing one where `START_NAMES` puts it."""
    given = {flag: value for flag, value in flags.items() if value is not None}
    if not given:
        return starts
    switched = dict.fromkeys(starts, True)
    for flag, value in given.items():
        switched[DEPRECATED_START_FLAGS[flag]] = check_bool(f"GncOptions.{flag}", value)
    chosen = [name for name in starts if switched[name]]
    added = [name for name in START_NAMES if switched.get(name) and name not in starts]
    # an added start goes where the default order puts it: "runs" first, the others after those given
    result = (*[name for name in added if name == "runs"], *chosen, *[name for name in added if name != "runs"])
    warnings.warn(
        f"GncOptions({', '.join(given)}) is deprecated and will be removed: use starts={result!r}",
        DeprecationWarning,
        stacklevel=4,
    )
    return result


RESTARTED_STAGE_TOL = 1e-4
"""`stage_tolerance` where the stages restart from the initial guess towards a fixed last stage:
only that stage is solved, and it only has to separate the loops for the decision rounds."""

CHAINED_STAGE_TOL = 1e-6
"""`stage_tolerance` where each stage's solution shapes the next (warm starts, carried weights)."""


def stage_tolerance(method: str, options: GncOptions) -> float:
    """The relative cost tolerance of `method`'s graduated stages: `options.stage_rel_cost_tol`, or
    when None `RESTARTED_STAGE_TOL` for egnc and riSAM with restarted stages (the default) and
    `CHAINED_STAGE_TOL` otherwise (`warm_start`, GNC-GM and GNC-TLS, which carry weights)."""
    if options.stage_rel_cost_tol is not None:
        return options.stage_rel_cost_tol
    if method in FIXED_LAST_STAGE_METHODS and not options.warm_start:
        return RESTARTED_STAGE_TOL
    return CHAINED_STAGE_TOL


StageKind = Literal["gnc", "decision", "probe", "elimination"]
StageStart = Literal["guess", "runs", "chordal", "chordal-all", "regrouped", "elimination", "parts", "online"]


@dataclass(frozen=True, eq=False)
class StageReport:
    """Summary of one stage.

    Attributes:
        mu_min, mu_mean, mu_max: statistics of the robust edges' `mu` (nan where the kernel has none).
        iterations: accepted solver steps.
        cost: the stage's own (robust or weighted) cost at its end.
        time_s: wall time of the stage in seconds.
        status: solver termination code (see `egnc.nonlinear.least_squares.STATUS_MESSAGES`).
        active_edges: edges in the stage's solve (the accepted ones in a refinement round).
        cg_iterations: conjugate-gradient iterations of the stage's steps (`egnc.linalg.step_solver`;
            0 when every step was solved directly).
        kind: `"gnc"` (a graduated stage), `"decision"` (a least-squares round of
            `egnc.robust.decision`), `"probe"` (the few iterations `egnc.robust.starts` gives the chordal
            start; it stops at its iteration limit by design) or `"elimination"` (a least-squares
            solve of `egnc.robust.elimination`'s backward elimination).
        start: the start the stage belongs to: `"guess"`, `"runs"` (the GNC stage from the
            chordal map of the loops in runs, `egnc.robust.regroup.runs_start`), `"chordal"` or
            `"chordal-all"` (`egnc.robust.starts`), `"regrouped"` (`egnc.robust.regroup`), `"elimination"`
            (`egnc.robust.elimination`) or `"online"` (the estimate of `egnc.online.OnlineSolver`);
            only the stages of the start that was kept (`Result.start`) shape the result.
        poses: `(N, n, n)` pose matrices at the stage's end, in the report an `on_stage` callback
            receives (`announce_stage`; e.g. to record each stage, `egnc.rerun`); None in
            `Result.stages`, which holds no poses.
    """

    mu_min: float
    mu_mean: float
    mu_max: float
    iterations: int
    cost: float
    time_s: float
    status: int
    active_edges: int
    cg_iterations: int = 0
    kind: StageKind = "gnc"
    start: StageStart = "guess"
    poses: np.ndarray | None = field(default=None, repr=False)


StageCallback = Callable[[StageReport], None]
"""Receives each stage's report as soon as the stage ends."""


def announce_stage(on_stage: StageCallback | None, report: StageReport, poses: np.ndarray) -> None:
    """Call `on_stage`, if any, with `report` carrying the stage's final `poses` `(N, n, n)`."""
    if on_stage is not None:
        on_stage(replace(report, poses=poses))


def iteration_limited(stages: Sequence[StageReport], start: str) -> list[int]:
    """1-based numbers of the stages of `start` at their iteration limit (the probe stops there by design)."""
    return [
        k
        for k, stage in enumerate(stages, start=1)
        if stage.status == 0 and stage.start == start and stage.kind != "probe"
    ]


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


KNOWN_INLIER_KINDS = ("odometry", "loops", "priors")
"""The kinds of factor `known_inliers` names: edges between consecutive ids, the other edges
(loop closures), and the priors (`egnc.graph.priors`)."""

KnownInliers = str | Sequence[str] | np.ndarray
"""Which factors stay quadratic: kinds (`KNOWN_INLIER_KINDS`, or `"none"`) or a bool mask."""


def known_inlier_mask(graph: PoseGraph, known_inliers: KnownInliers) -> np.ndarray:
    """`(E,)` bool of edges kept quadratic, or `(E + K,)` edges then priors when the graph has
    priors that may be rejected (`egnc.robust.factor_set`).

    Args:
        graph: the pose graph.
        known_inliers: kinds of factor held quadratic, one of `KNOWN_INLIER_KINDS` or several
            (a tuple, or one string joined by commas: `"odometry,priors"`), or `"none"`; or a
            bool mask, `(E,)` over the edges (priors are then candidates) or `(E + K,)` over the
            edges then the priors. Priors not named are candidates, like loop closures.

    Raises:
        OptionError: an unknown kind, or a mask of the wrong type or shape.
    """
    if isinstance(known_inliers, str) or (
        isinstance(known_inliers, (tuple, list)) and all(isinstance(kind, str) for kind in known_inliers)
    ):
        kinds = known_inlier_kinds(known_inliers)  # type: ignore[arg-type]
        edges = np.zeros(graph.num_edges, dtype=bool)
        if "odometry" in kinds:
            edges |= graph.is_odometry
        if "loops" in kinds:
            edges |= ~graph.is_odometry
        if not graph.num_priors or "priors" in kinds:
            return edges
        return np.concatenate((edges, np.zeros(graph.num_priors, dtype=bool)))
    try:
        mask = np.asarray(known_inliers)
    except ValueError:  # ragged nesting
        mask = np.asarray(None)
    sizes = (graph.num_edges,) if not graph.num_priors else (graph.num_edges, graph.num_edges + graph.num_priors)
    if mask.dtype != bool or mask.ndim != 1 or len(mask) not in sizes:
        shapes = " or ".join(f"({size},)" for size in sizes)
        raise OptionError(f"known_inliers mask must be bool of shape {shapes}, got {mask.dtype} {mask.shape}")
    if graph.num_priors and len(mask) == graph.num_edges:
        return np.concatenate((mask, np.zeros(graph.num_priors, dtype=bool)))
    if graph.num_priors and mask[graph.num_edges :].all():  # every prior known: the edges' arrays alone
        return mask[: graph.num_edges].copy()
    return mask


def known_inlier_kinds(known_inliers: str | Sequence[str]) -> set[str]:
    """The kinds named by `known_inliers` (`known_inlier_mask`), checked (`OptionError`)."""
    names = known_inliers.split(",") if isinstance(known_inliers, str) else list(known_inliers)
    kinds = {name.strip() for name in names}
    if kinds == {"none"}:
        return set()
    unknown = sorted(kinds - set(KNOWN_INLIER_KINDS))
    if unknown:
        raise OptionError(
            f"unknown known_inliers {unknown[0]!r}: choose kinds among {', '.join(KNOWN_INLIER_KINDS)},"
            " 'none', or a bool mask"
        )
    return kinds


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
    factors: Factors,
    on_stage: StageCallback | None = None,
    on_iteration: IterationCallback | None = None,
    start: StageStart = "guess",
) -> GncOutcome:
    """Run `schedule`'s stages on `graph` from `initial_poses` `(N, n, n)`.

    Args:
        graph: the pose graph.
        initial_poses: `(N, n, n)` starting poses.
        schedule: decides each stage's loss.
        robust: `(F,)` bool, factors the schedule's kernel applies to.
        solver_options: options of each stage's GN/LM solve.
        gnc_options: stage limit and stage protocol (`warm_start`).
        linear_solver: resolved backend name, `"cholmod"`, `"rslab"` or `"scipy"`.
        factors: the graph's factors, built once per solve: the edges', or the edges' then the
            priors' where priors are candidates (`egnc.robust.factor_set`).
        on_stage: called with each `StageReport` as soon as its stage ends (progress display).
        on_iteration: called with `(iterations, cost)` after each accepted step of a stage.
        start: the start the stages' reports belong to (`StageReport.start`).
    """
    problem = factor_problem(graph, factors, linear_solver)
    poses = initial_poses
    r = factors.whitened_norms(factors.residuals(poses))
    last = schedule.first_stage(r)
    if not (gnc_options.warm_start or gnc_options.every_stage):
        # Restarted stages reach the result only through the next stage's loss: when the last
        # loss is fixed in advance (egnc, riSAM: mu = 1 on every loop), the earlier stages cannot
        # change the poses or the decision, and solving them only costs time.
        last = schedule.fixed_last_stage() or last
    stage: Stage | None = last
    reports: list[StageReport] = []
    timings: dict[str, float] = {}
    status, message = 0, ""
    while stage is not None:
        if stage is not last and _same_loss(stage, last):
            break
        if len(reports) == gnc_options.max_stages:
            status, message = 0, f"stopped after max_stages = {gnc_options.max_stages} stages"
            break
        started = time.perf_counter()
        from_poses = poses if gnc_options.warm_start else initial_poses
        solution = solve_least_squares(problem, from_poses, stage.loss, solver_options, on_iteration)
        poses = solution.poses
        r = factors.whitened_norms(factors.residuals(poses))
        reports.append(_stage_report(stage, robust, solution, started, graph.num_edges, start))
        announce_stage(on_stage, reports[-1], poses)
        for phase, seconds in solution.timings.items():
            timings[phase] = timings.get(phase, 0.0) + seconds
        status, message = solution.status, solution.message
        last = stage
        if solution.status == NUMERICAL_FAILURE:
            break
        if solution.status == 0 and len(reports) > 1 and reports[-2].status == 0:
            # Two stages in a row that could not converge from the same guess predict the rest (a
            # corrupted odometry edge ran 100 stages of 100 iterations). One alone does not: a slow
            # least-squares stage 0 is often followed by robust stages that converge quickly.
            break
        stage = schedule.next_stage(r, solution.converged)
    return GncOutcome(
        poses=poses,
        weights=last.loss.weight(r),
        mu=last.mu,
        stages=tuple(reports),
        status=status,
        message=message,
        timings=timings,
    )


def _stage_report(
    stage: Stage, robust: np.ndarray, solution: SolverResult, started: float, active_edges: int, start: StageStart
) -> StageReport:
    """The `StageReport` of `stage`, solved as `solution` over `active_edges` edges from the
    `time.perf_counter()` reading `started`; `robust` `(E,)` picks the edges of its `mu` statistics."""
    return StageReport(
        *_mu_stats(stage, robust),
        iterations=solution.iterations,
        cost=solution.cost,
        time_s=time.perf_counter() - started,
        status=solution.status,
        active_edges=active_edges,
        cg_iterations=solution.linear.cg_iterations,
        start=start,
    )


def _same_loss(stage: Stage, previous: Stage) -> bool:
    """Whether `stage` would minimize exactly what `previous` did (same kernel or weights, same `mu`)."""
    a, b = stage.loss, previous.loss
    if isinstance(a, KernelLoss) and isinstance(b, KernelLoss):
        return a.kernel is b.kernel and np.array_equal(a.mu, b.mu) and np.array_equal(a.robust, b.robust)
    if isinstance(a, FixedWeightLoss) and isinstance(b, FixedWeightLoss):
        return np.array_equal(a.weights, b.weights)
    return False


def classify_inliers(r: np.ndarray, robust: np.ndarray, d: int | np.ndarray, options: GncOptions) -> np.ndarray:
    """`(E,)` bool inlier flags: robust edges above the chi-square `outlier_quantile` are outliers
    (`d`: the dimension, or `(E,)` per factor, `egnc.robust.factor_set`).

    With `options.outlier_threshold == "squared"` (default) the test is `r^2 > chi2.ppf(q, d)`
    (DESIGN.md section 4); with `"distance"` it is `r > chi2.ppf(q, d)`, as in the authors' C++
    reference.
    """
    return ~(robust & exceeds(r, options.outlier_quantile, d, options.outlier_threshold))
