"""Benchmark grid: datasets x outlier percentages x seeds x methods, each run isolated and timed.

Protocol (DESIGN.md section 5, experiment 1). For every dataset, the outlier-free reference is the
plain least-squares optimum of the clean graph (`egnc.solve(graph, "l2")`), computed once. For
every (dataset, percent, seed) the graph is corrupted in memory with
`egnc.datasets.add_false_loops` against that reference, and every method solves the same
corrupted graph with the odometry as known inliers. Each run is scored against the labels and the
reference: outlier precision and recall (outliers are the positive class), success (both 1), ATE
and RPE (`egnc.metrics`), plus stages, iterations, solver time and status.

Experiment 2 (`run_irl`): an IRL log with ground-truth labels (e.g. the noisy Manhattan case) is
solved as is, with its ODOMETRY entries as known inliers; the reference is the least-squares
optimum of the graph without the labelled outliers.

Methods: every name in `egnc.schedules.METHODS`, optionally with `GncOptions` overrides in
brackets (`egnc[threshold=distance]`, `risam[c=2,refine=false]`), plus the GTSAM baselines
`gtsam-gnc-gm`, `gtsam-gnc-tls` (`GncLMOptimizer`) and `gtsam-lm` (least squares) when `gtsam` is
importable. GTSAM runs follow `benchmarks/gtsam_baseline.py`: the graph goes through a temporary
g2o file and `gtsam.readG2o`, a prior with sigma 1e-3 holds the lowest id at its initial value,
the known inliers are the odometry factors and that prior, GNC uses GTSAM's default parameters
(inner LM included) and LM the reference protocol's tolerances (1e-12, 1000 iterations). Their
outliers are decided by the same rule as egnc's, on the final residuals: a loop closure is an
outlier when `r^2 > chi2.ppf(0.95, d)`, so both libraries are scored by one yardstick (GTSAM's
own per-edge weights are not used). Times: `Result.time_s` for egnc (graph in, result out) and
`optimize()` alone for GTSAM (file reading and graph building excluded).

Isolation: every run, and every reference solve, happens in a child process forked from the
benchmark (fork: the graph is inherited, not copied through a pipe), which is killed at the time
limit; a run that does not answer in time is reported as "timeout" and one that fails as
"error: <message>". The parent never solves anything itself, so no thread pool of a numerical
library is ever live in it at a fork. The reference solve gets `max(time_limit_s, 60)` seconds.
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import io
import math
import multiprocessing
import os
import re
import tempfile
import time
import types
import typing
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.api import solve
from egnc.datasets import add_false_loops
from egnc.errors import EgncError
from egnc.factors import BetweenFactors, from_matrices, to_matrices
from egnc.gnc import GncOptions, classify_inliers
from egnc.graph import PoseGraph
from egnc.io import read_g2o, read_irl, write_g2o
from egnc.io.atomic import atomic_text_file
from egnc.metrics import ate, precision_recall, rpe, success
from egnc.schedules import METHODS

__all__ = [
    "CSV_COLUMNS",
    "GTSAM_METHODS",
    "BenchCase",
    "MethodSpec",
    "RunRecord",
    "SummaryRow",
    "describe_run",
    "format_markdown",
    "gtsam_available",
    "parse_method",
    "parse_methods",
    "resolve_dataset",
    "run_case",
    "run_grid",
    "run_irl",
    "summarize",
    "write_outputs",
]

GTSAM_METHODS = ("gtsam-gnc-gm", "gtsam-gnc-tls", "gtsam-lm")
"""Baselines run with GTSAM's Python wheel (the optional `bench` extra) when it is importable."""

GTSAM_PRIOR_SIGMA = 1e-3
"""Isotropic sigma of the prior that fixes GTSAM's gauge (benchmarks/gtsam_baseline.py)."""

REFERENCE_MIN_TIME_S = 60.0
"""The reference least-squares solve of a dataset gets at least this many seconds."""

Progress = Callable[[str], None]


# --- methods ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MethodSpec:
    """One method of the grid.

    Attributes:
        label: the spec as given, e.g. `"egnc[threshold=distance]"`; names the method in the results.
        method: an `egnc.schedules.METHODS` name or one of `GTSAM_METHODS`.
        overrides: `GncOptions` fields to change, as `(name, value)` pairs (egnc methods only).
    """

    label: str
    method: str
    overrides: tuple[tuple[str, object], ...] = ()

    @property
    def is_gtsam(self) -> bool:
        """Whether GTSAM runs this method."""
        return self.method in GTSAM_METHODS

    def gnc_options(self) -> GncOptions:
        """The `GncOptions` with this spec's overrides."""
        overrides: dict[str, typing.Any] = dict(self.overrides)  # each value has its field's type (parse_method)
        return GncOptions(**overrides)


_SPEC = re.compile(r"^\s*([A-Za-z0-9_-]+)\s*(?:\[(.*)\])?\s*$", re.DOTALL)


def parse_method(spec: str) -> MethodSpec:
    """Parse `name` or `name[field=value,...]` into a `MethodSpec`.

    Values are converted to the type of the `GncOptions` field (`none` for an optional field,
    `true`/`false` for a flag) and the options are validated at once.

    Raises:
        EgncError: unknown method or option, a value of the wrong type, or options GncOptions rejects.
    """
    match = _SPEC.match(spec)
    if not match:
        raise EgncError(f"method {spec!r}: expected NAME or NAME[option=value,...]")
    name, body = match.group(1), match.group(2)
    if name not in METHODS and name not in GTSAM_METHODS:
        raise EgncError(f"unknown method {name!r}: choose one of {', '.join(METHODS + GTSAM_METHODS)}")
    overrides: dict[str, object] = {}
    if body is not None and body.strip():
        if name in GTSAM_METHODS:
            raise EgncError(f"method {spec!r}: GTSAM baselines take no options")
        hints = typing.get_type_hints(GncOptions)
        fields = [f.name for f in dataclasses.fields(GncOptions)]
        for item in body.split(","):
            key, equals, value = (part.strip() for part in item.partition("="))
            if not equals or not key or not value:
                raise EgncError(f"method {spec!r}: option {item.strip()!r} is not of the form name=value")
            if key not in hints:
                raise EgncError(f"method {spec!r}: unknown option {key!r}; GncOptions has {', '.join(fields)}")
            if key in overrides:
                raise EgncError(f"method {spec!r}: option {key!r} given twice")
            overrides[key] = _convert(value, hints[key], f"method {spec!r}: option {key}")
    parsed = MethodSpec(label=spec.strip(), method=name, overrides=tuple(overrides.items()))
    if not parsed.is_gtsam:
        try:
            parsed.gnc_options()
        except EgncError as error:
            raise EgncError(f"method {spec!r}: {error}") from None
    return parsed


def parse_methods(text: str) -> tuple[MethodSpec, ...]:
    """Parse a comma-separated list of specs; commas inside brackets belong to the options."""
    specs, depth, start = [], 0, 0
    for position, char in enumerate(text + ","):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            if text[start:position].strip():
                specs.append(parse_method(text[start:position]))
            start = position + 1
    if depth != 0:
        raise EgncError(f"methods {text!r}: unbalanced brackets")
    if not specs:
        raise EgncError("no method given")
    labels = [spec.label for spec in specs]
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        raise EgncError(f"method {repeated[0]!r} is listed twice")
    return tuple(specs)


def _convert(text: str, kind: object, what: str) -> object:
    """Convert an option value to the annotated type (`float`, `int`, `bool`, `str`, `X | None`)."""
    union = isinstance(kind, types.UnionType) or typing.get_origin(kind) is typing.Union
    options = typing.get_args(kind) if union else (kind,)
    if type(None) in options and text.lower() == "none":
        return None
    if typing.get_origin(kind) is typing.Literal:
        if text in typing.get_args(kind):
            return text
        raise EgncError(f"{what}: {text!r} is not one of {', '.join(map(str, typing.get_args(kind)))}")
    for option in options:
        if option is bool:
            if text.lower() in ("true", "yes", "1"):
                return True
            if text.lower() in ("false", "no", "0"):
                return False
        elif option is int:
            try:
                return int(text)
            except ValueError:
                pass
        elif option is float:
            try:
                return float(text)
            except ValueError:
                pass
        elif option is str:
            return text
    names = " or ".join("none" if option is type(None) else getattr(option, "__name__", "value") for option in options)
    raise EgncError(f"{what}: {text!r} is not a valid {names}")


# --- cases and runs -----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BenchCase:
    """One graph to solve with every method.

    Attributes:
        dataset: name shown in the results (the file's stem).
        percent: outlier percentage among loop closures (requested; for IRL logs the actual share).
        seed: seed of the corruption (None for IRL logs).
        graph: the graph to solve.
        is_outlier: `(E,)` bool ground truth.
        known_inliers: `(E,)` bool edges every method keeps quadratic (the odometry).
        reference: `(N, P)` outlier-free optimum the trajectory errors are measured against.
    """

    dataset: str
    percent: float
    seed: int | None
    graph: PoseGraph
    is_outlier: np.ndarray
    known_inliers: np.ndarray
    reference: np.ndarray


@dataclass(frozen=True)
class RunRecord:
    """The outcome of one method on one case (one row of `results.csv`).

    Attributes:
        dataset, percent, seed: the case.
        method: the method's label.
        status: "ok", "timeout" or "error: <message>"; the metrics are nan unless "ok".
        precision, recall: outlier detection, outliers positive (`egnc.metrics.precision_recall`).
        success: precision and recall both 1.
        ate: absolute trajectory error against the reference, metres.
        rpe: translational relative pose error (consecutive poses), metres.
        rpe_rotation: rotational relative pose error, radians.
        rpe_percent: translational RPE / mean reference step length * 100.
        stages: `len(Result.stages)` of egnc methods (a final least-squares refinement counts as
            one); -1 for GTSAM, which does not report them.
        iterations: solver iterations over all stages (-1 when not reported).
        time_s: solver time in seconds (see the module docstring).
        wall_s: parent-side seconds for the run, child process included.
        loops: loop closures in the graph (candidates for rejection).
        outliers: true outliers among them.
        rejected: loop closures the method rejected.
    """

    dataset: str
    percent: float
    seed: int | None
    method: str
    status: str
    precision: float = math.nan
    recall: float = math.nan
    success: bool = False
    ate: float = math.nan
    rpe: float = math.nan
    rpe_rotation: float = math.nan
    rpe_percent: float = math.nan
    stages: int = -1
    iterations: int = -1
    time_s: float = math.nan
    wall_s: float = math.nan
    loops: int = 0
    outliers: int = 0
    rejected: int = 0

    @property
    def ok(self) -> bool:
        """Whether the run finished."""
        return self.status == "ok"


CSV_COLUMNS = tuple(field.name for field in dataclasses.fields(RunRecord))
"""Columns of `results.csv`, in order."""


def run_case(
    case: BenchCase, spec: MethodSpec, *, time_limit_s: float = 300.0, linear_solver: str = "auto"
) -> RunRecord:
    """Solve one case with one method in a child process killed after `time_limit_s` seconds."""
    started = time.perf_counter()
    status, payload = _in_child(_solve_and_score, (case, spec, linear_solver), time_limit_s)
    wall_s = time.perf_counter() - started
    loops = int(np.count_nonzero(~case.known_inliers))
    common: dict[str, typing.Any] = dict(
        dataset=case.dataset,
        percent=case.percent,
        seed=case.seed,
        method=spec.label,
        wall_s=wall_s,
        loops=loops,
        outliers=int(np.count_nonzero(case.is_outlier)),
    )
    if status != "ok":
        return RunRecord(status=status, **common)
    assert payload is not None  # an "ok" status carries the child's value
    return RunRecord(status="ok", **payload, **common)


def _solve_and_score(case: BenchCase, spec: MethodSpec, linear_solver: str) -> dict:
    """Child-process body of `run_case`: solve, then score against labels and reference."""
    if spec.is_gtsam:
        poses, time_s, iterations = _gtsam_solve(case.graph, case.known_inliers, spec.method)
        # GTSAM's outliers by egnc's rule: r^2 > chi2.ppf(0.95, d) on the loop closures at its poses.
        factors = BetweenFactors.from_graph(case.graph)
        r = factors.whitened_norms(factors.residuals(to_matrices(case.graph.dim, poses)))
        predicted = ~classify_inliers(r, ~case.known_inliers, case.graph.tangent_dim, GncOptions())
        stages = -1
    else:
        result = solve(
            case.graph,
            spec.method,
            known_inliers=case.known_inliers,
            linear_solver=linear_solver,
            gnc_options=spec.gnc_options(),
        )
        poses, time_s, iterations = result.graph.poses, result.time_s, result.iterations
        predicted, stages = ~result.inliers, len(result.stages)
    precision, recall = precision_recall(predicted, case.is_outlier)
    relative = rpe(poses, case.reference, case.graph.dim)
    return dict(
        precision=precision,
        recall=recall,
        success=success(precision, recall),
        ate=ate(poses, case.reference, case.graph.dim),
        rpe=relative.translation,
        rpe_rotation=relative.rotation,
        rpe_percent=relative.percent,
        stages=stages,
        iterations=iterations,
        time_s=time_s,
        rejected=int(np.count_nonzero(predicted)),
    )


def _reference(graph: PoseGraph, linear_solver: str) -> np.ndarray:
    """Child-process body: the least-squares optimum `(N, P)` of a (clean) graph."""
    return solve(graph, "l2", linear_solver=linear_solver).graph.poses


_T = typing.TypeVar("_T")


def _in_child(target: Callable[..., _T], args: tuple, time_limit_s: float) -> tuple[str, _T | None]:
    """Run `target(*args)` in a forked child; `("ok", value)`, `("timeout", None)` or `("error: ...", None)`."""
    context = multiprocessing.get_context("fork")
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_child_main, args=(sender, target, args), daemon=True)
    process.start()
    sender.close()  # so a child that dies without answering shows up as EOF
    status, value = "interrupted", None  # what the cleanup sees if the wait itself is interrupted
    try:
        if receiver.poll(time_limit_s):
            status, value = receiver.recv()
        else:
            status, value = "timeout", None
    except EOFError:
        process.join(5.0)
        status, value = f"error: child process died (exit code {process.exitcode})", None
    finally:
        if process.is_alive() and status != "ok":
            process.kill()
        process.join()
        receiver.close()
    return status, value


def _child_main(connection, target: Callable, args: tuple) -> None:
    """Body of the child: send `("ok", result)` or a one-line error, never raise across the fork."""
    try:
        connection.send(("ok", target(*args)))
    except BaseException as error:  # reported to the parent, whatever it was
        message = " ".join(str(error).split())  # one line
        if not isinstance(error, EgncError):
            message = f"{type(error).__name__}: {message}" if message else type(error).__name__
        connection.send((f"error: {message}", None))
    finally:
        connection.close()


# --- GTSAM baselines ----------------------------------------------------------------------------


def gtsam_available() -> bool:
    """Whether `gtsam` can be imported (checked without importing it)."""
    return importlib.util.find_spec("gtsam") is not None


def add_gtsam_reference_prior(factors: typing.Any, initial: typing.Any, key: int, is_3d: bool) -> None:
    """Append the reference protocol's gauge to a GTSAM graph: a prior, sigma 1e-3 on every
    component, holding pose `key` at its initial value (needs the `bench` extra's gtsam)."""
    import gtsam

    noise = gtsam.noiseModel.Isotropic.Sigma(6 if is_3d else 3, GTSAM_PRIOR_SIGMA)
    if is_3d:
        factors.add(gtsam.PriorFactorPose3(key, initial.atPose3(key), noise))
    else:
        factors.add(gtsam.PriorFactorPose2(key, initial.atPose2(key), noise))


def _gtsam_solve(graph: PoseGraph, known_inliers: np.ndarray, method: str) -> tuple[np.ndarray, float, int]:
    """Solve with GTSAM (child process only): `(poses (N, P), optimize() seconds, iterations or -1)`."""
    import gtsam  # the optional `bench` extra; imported only here, in the child

    is_3d = graph.dim == 3
    # readG2o stops at a FIX line, so the file holds no gauge: the prior below is the gauge.
    plain = PoseGraph(graph.dim, graph.vertex_ids, graph.poses, graph.edges, graph.measurements, graph.information)
    with tempfile.TemporaryDirectory(prefix="egnc-bench-") as folder:
        path = Path(folder) / "graph.g2o"
        write_g2o(plain, path)
        factors, initial = gtsam.readG2o(str(path), is_3d)
    if factors.size() != graph.num_edges:
        raise EgncError(f"gtsam.readG2o read {factors.size()} of {graph.num_edges} edges")
    fixed = np.flatnonzero(graph.fixed)
    add_gtsam_reference_prior(factors, initial, int(graph.vertex_ids[fixed[0] if len(fixed) else 0]), is_3d)
    optimizer: typing.Any  # LevenbergMarquardtOptimizer or GncLMOptimizer; only the first has iterations()
    if method == "gtsam-lm":
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-12)
        params.setAbsoluteErrorTol(1e-12)
        params.setMaxIterations(1000)
        optimizer = gtsam.LevenbergMarquardtOptimizer(factors, initial, params)
    else:
        gnc_params = gtsam.GncLMParams(gtsam.LevenbergMarquardtParams())
        gnc_params.setLossType(gtsam.GncLossType.GM if method == "gtsam-gnc-gm" else gtsam.GncLossType.TLS)
        gnc_params.setKnownInliers([int(k) for k in np.flatnonzero(known_inliers)] + [graph.num_edges])
        optimizer = gtsam.GncLMOptimizer(factors, initial, gnc_params)
    started = time.perf_counter()
    values = optimizer.optimize()
    time_s = time.perf_counter() - started
    iterations = optimizer.iterations() if method == "gtsam-lm" else -1
    keys = np.array(sorted(values.keys()), dtype=np.int64)
    if not np.array_equal(keys, graph.vertex_ids):
        raise EgncError("GTSAM's result does not hold the graph's poses")
    if is_3d:
        flat = gtsam.utilities.extractPose3(values)  # rows: R (row-major), then t
        T = np.zeros((len(flat), 4, 4))
        T[:, :3, :3] = flat[:, :9].reshape(-1, 3, 3)
        T[:, :3, 3] = flat[:, 9:]
        T[:, 3, 3] = 1.0
        poses = from_matrices(3, T)
    else:
        poses = np.asarray(gtsam.utilities.extractPose2(values), dtype=np.float64)
    return poses, time_s, int(iterations)


# --- grids --------------------------------------------------------------------------------------


def resolve_dataset(name: str | os.PathLike, data_dir: str | os.PathLike) -> Path:
    """An existing file path as is, else `data_dir/name` or `data_dir/name.g2o`."""
    path = Path(name)
    if path.is_file():
        return path
    for candidate in (Path(data_dir) / path, Path(data_dir) / f"{path}.g2o"):
        if candidate.is_file():
            return candidate
    raise EgncError(f"dataset {str(name)!r} not found: no such file, nor {Path(data_dir) / path}[.g2o]")


def run_grid(
    datasets: Sequence[str | os.PathLike],
    percents: Sequence[float],
    seeds: Sequence[int],
    methods: Sequence[str | MethodSpec],
    *,
    data_dir: str | os.PathLike = "../shared/datasets",
    variant: str = "random",
    time_limit_s: float = 300.0,
    linear_solver: str = "auto",
    progress: Progress | None = None,
) -> list[RunRecord]:
    """Run every method on every (dataset, percent, seed) corruption (see the module docstring).

    Args:
        datasets: g2o paths or names resolved in `data_dir` (`csail` -> `data_dir/csail.g2o`).
        percents: outlier percentages among loop closures, each in [0, 100).
        seeds: corruption seeds.
        methods: specs (`"egnc"`, `"egnc[threshold=distance]"`, `"gtsam-gnc-tls"`, ...) or `MethodSpec`s;
            GTSAM methods are skipped (with a progress note) when gtsam is not importable.
        data_dir: where dataset names are looked up.
        variant: false-loop variant of `add_false_loops` ("random", "group", "mixed", "close").
        time_limit_s: per-run limit in seconds.
        linear_solver: egnc's linear backend for every solve, reference included.
        progress: called with one line of text after every run (and for notes).

    Returns:
        One `RunRecord` per (dataset, percent, seed, method), in that nesting order.
    """
    specs = _specs(methods, progress)
    paths = [resolve_dataset(name, data_dir) for name in datasets]
    total = len(paths) * len(percents) * len(seeds) * len(specs)
    counter = _Counter(total, progress)
    records: list[RunRecord] = []
    for path in paths:
        for percent, seed, case in _corruptions(path, percents, seeds, variant, time_limit_s, linear_solver):
            for spec in specs:
                if isinstance(case, str):  # the case could not be built: every method says why
                    record = RunRecord(path.stem, float(percent), int(seed), spec.label, case)
                else:
                    record = run_case(case, spec, time_limit_s=time_limit_s, linear_solver=linear_solver)
                records.append(counter.report(record))
    return records


def _corruptions(
    path: Path, percents: Sequence[float], seeds: Sequence[int], variant: str, time_limit_s: float, linear_solver: str
) -> Iterator[tuple[float, int, BenchCase | str]]:
    """`(percent, seed, case)` for every corruption of one dataset; `case` is an error status if it failed.

    The dataset is read and its reference solved once, for all of its corruptions.
    """
    try:
        graph = read_g2o(path)
    except EgncError as error:
        status, reference = f"error: {error}", None
    else:
        status, reference = _in_child(_reference, (graph, linear_solver), max(time_limit_s, REFERENCE_MIN_TIME_S))
        status = status if status == "ok" else f"{status} (reference solve)"
    for percent in percents:
        for seed in seeds:
            if status != "ok":
                yield percent, seed, status
                continue
            try:
                corrupted = add_false_loops(
                    graph, percent, seed=seed, reference_poses=reference, variant=variant  # type: ignore[arg-type]
                )
            except EgncError as error:
                yield percent, seed, f"error: {error}"
                continue
            yield percent, seed, BenchCase(
                dataset=path.stem,
                percent=float(percent),
                seed=int(seed),
                graph=corrupted.graph,
                is_outlier=corrupted.is_outlier,
                known_inliers=corrupted.graph.is_odometry,
                reference=reference,  # type: ignore[arg-type]
            )


def run_irl(
    path: str | os.PathLike,
    methods: Sequence[str | MethodSpec],
    *,
    time_limit_s: float = 300.0,
    linear_solver: str = "auto",
    progress: Progress | None = None,
) -> list[RunRecord]:
    """Run every method on an IRL log with its ground-truth labels (no corruption).

    The known inliers are the ODOMETRY entries; the reference is the least-squares optimum of
    the graph without the labelled outliers; `percent` is their share among the LOOP entries.
    """
    specs = _specs(methods, progress)
    log = read_irl(path)
    graph = log.graph
    counter = _Counter(len(specs), progress)
    loops = int(np.count_nonzero(~log.is_odometry))
    percent = 100.0 * np.count_nonzero(log.is_outlier) / loops if loops else 0.0
    clean = graph.subgraph_edges(~log.is_outlier)
    status, reference = _in_child(_reference, (clean, linear_solver), max(time_limit_s, REFERENCE_MIN_TIME_S))
    name = Path(path).stem
    if status != "ok":
        failed = f"{status} (reference solve)"
        return [counter.report(RunRecord(name, percent, None, spec.label, failed)) for spec in specs]
    case = BenchCase(name, percent, None, graph, log.is_outlier, log.is_odometry, reference)  # type: ignore[arg-type]
    return [
        counter.report(run_case(case, spec, time_limit_s=time_limit_s, linear_solver=linear_solver)) for spec in specs
    ]


def _specs(methods: Iterable[str | MethodSpec], progress: Progress | None) -> list[MethodSpec]:
    """Parsed specs, without the GTSAM ones when gtsam is missing (said through `progress`)."""
    specs = [parse_method(method) if isinstance(method, str) else method for method in methods]
    if not specs:
        raise EgncError("no method given")
    skipped = [spec.label for spec in specs if spec.is_gtsam and not gtsam_available()]
    if skipped and progress is not None:
        progress(f"gtsam is not importable (pip install egnc[bench]): skipping {', '.join(skipped)}")
    return [spec for spec in specs if spec.label not in skipped]


class _Counter:
    """Numbers the runs and reports each one through `progress`."""

    def __init__(self, total: int, progress: Progress | None):
        self.total = total
        self.done = 0
        self.progress = progress

    def report(self, record: RunRecord) -> RunRecord:
        self.done += 1
        if self.progress is not None:
            self.progress(f"[{self.done}/{self.total}] {describe_run(record)}")
        return record


def describe_run(record: RunRecord) -> str:
    """One line about a run, e.g. `csail 30% seed 2 egnc: ok P 1.000 R 0.992 ATE 0.0123 m 0.41 s`."""
    seed = "" if record.seed is None else f" seed {record.seed}"
    head = f"{record.dataset} {record.percent:g}%{seed} {record.method}"
    if not record.ok:
        return f"{head}: {record.status}"
    return (
        f"{head}: ok P {record.precision:.3f} R {record.recall:.3f} ATE {record.ate:.4g} m "
        f"{record.time_s:.3f} s"
    )


# --- reports ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SummaryRow:
    """Runs of one method on one (dataset, percent), aggregated over seeds.

    Attributes:
        dataset, percent, method: the group.
        runs: number of runs (seeds); `ok` of them finished.
        failures: e.g. `"1 timeout"`, empty when every run finished.
        precision, recall, ate, rpe_percent, time_s: means over the finished runs (nan if none).
        successes: runs with precision = recall = 1.
        time_ratio: `time_s` / the baseline method's `time_s` on the same group (nan without it).
    """

    dataset: str
    percent: float
    method: str
    runs: int
    ok: int
    failures: str
    precision: float
    recall: float
    successes: int
    ate: float
    rpe_percent: float
    time_s: float
    time_ratio: float


def summarize(records: Sequence[RunRecord], baseline_method: str | None = "risam") -> list[SummaryRow]:
    """Aggregate runs over seeds, per (dataset, percent, method), in first-seen order."""
    groups: dict[tuple[str, float, str], list[RunRecord]] = {}
    for record in records:
        groups.setdefault((record.dataset, record.percent, record.method), []).append(record)

    def mean(values: list[float]) -> float:
        return float(np.mean(values)) if values else math.nan

    means: dict[tuple[str, float, str], float] = {
        key: mean([r.time_s for r in runs if r.ok]) for key, runs in groups.items()
    }
    rows = []
    for (dataset, percent, method), runs in groups.items():
        finished = [r for r in runs if r.ok]
        failed: dict[str, int] = {}
        for r in runs:
            if not r.ok:
                kind = "timeout" if r.status == "timeout" else "error"
                failed[kind] = failed.get(kind, 0) + 1
        baseline = means.get((dataset, percent, baseline_method or ""), math.nan)
        time_s = means[(dataset, percent, method)]
        rows.append(
            SummaryRow(
                dataset=dataset,
                percent=percent,
                method=method,
                runs=len(runs),
                ok=len(finished),
                failures=", ".join(f"{count} {kind}" for kind, count in failed.items()),
                precision=mean([r.precision for r in finished]),
                recall=mean([r.recall for r in finished]),
                successes=sum(r.success for r in finished),
                ate=mean([r.ate for r in finished]),
                rpe_percent=mean([r.rpe_percent for r in finished]),
                time_s=time_s,
                time_ratio=time_s / baseline if baseline > 0 else math.nan,
            )
        )
    return rows


def format_markdown(rows: Sequence[SummaryRow], baseline_method: str | None = "risam") -> str:
    """A markdown table of `summarize`'s rows."""
    ratio = f"time / {baseline_method}" if baseline_method else "time ratio"
    lines = [
        "| dataset | outliers % | method | precision | recall | success | ATE (m) | RPE (%) | time (s) "
        f"| {ratio} | failed |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.dataset} | {row.percent:g} | {row.method} | {_fixed(row.precision, 4)} "
            f"| {_fixed(row.recall, 4)} | {row.successes}/{row.runs} | {_general(row.ate)} "
            f"| {_fixed(row.rpe_percent, 2)} | {_fixed(row.time_s, 3)} | {_fixed(row.time_ratio, 2)} "
            f"| {row.failures} |"
        )
    return "\n".join(lines)


def _fixed(value: float, digits: int) -> str:
    return "-" if math.isnan(value) else f"{value:.{digits}f}"


def _general(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.4g}"


def _csv_value(value: object) -> str:
    """CSV text: exact floats (`repr`), empty for nan/None, `true`/`false` for flags."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def write_outputs(
    records: Sequence[RunRecord],
    out_dir: str | os.PathLike,
    *,
    baseline_method: str | None = "risam",
    header: str = "",
) -> dict[str, Path]:
    """Write `results.csv`, `results.md` and, when matplotlib is importable, the plots.

    Args:
        records: the runs.
        out_dir: folder to write into (created if needed); each file is replaced atomically.
        baseline_method: label of the method the time ratios are relative to.
        header: text put above the table in `results.md` (e.g. the command and the machine).

    Returns:
        The written files by name: "csv", "md", and "runtime" / "precision_recall" for the plots.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise EgncError(f"{out}: cannot create folder: {error.strerror or error}") from None
    written = {"csv": out / "results.csv", "md": out / "results.md"}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for record in records:
        writer.writerow([_csv_value(getattr(record, column)) for column in CSV_COLUMNS])
    with atomic_text_file(written["csv"]) as handle:
        handle.write(buffer.getvalue())
    rows = summarize(records, baseline_method)
    with atomic_text_file(written["md"]) as handle:
        intro = header.rstrip() + "\n\n" if header.strip() else ""
        handle.write(intro + format_markdown(rows, baseline_method) + "\n")
    if importlib.util.find_spec("matplotlib") is not None and rows:
        written["runtime"] = out / "runtime.png"
        written["precision_recall"] = out / "precision_recall.png"
        _plot_runtime(rows, baseline_method, written["runtime"])
        _plot_precision_recall(rows, written["precision_recall"])
    return written


# --- plots (matplotlib, the `plot` extra) -------------------------------------------------------


def _save(figure, path: Path) -> None:
    """Save a figure atomically (a temporary file beside `path`, then a rename)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(figure)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        figure.savefig(temporary, dpi=120, format="png")
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None


def _plot_runtime(rows: Sequence[SummaryRow], baseline_method: str | None, path: Path) -> None:
    """Bars of the time ratio to the baseline, grouped by outlier rate, one panel per dataset."""
    from matplotlib.figure import Figure

    datasets = list(dict.fromkeys(row.dataset for row in rows))
    methods = list(dict.fromkeys(row.method for row in rows))
    figure = Figure(figsize=(max(4.0, 3.2 * len(datasets)), 3.4), layout="constrained")
    axes = figure.subplots(1, len(datasets), squeeze=False)[0]
    width = 0.8 / len(methods)
    for ax, dataset in zip(axes, datasets):
        percents = sorted({row.percent for row in rows if row.dataset == dataset})
        for k, method in enumerate(methods):
            by_percent = {row.percent: row for row in rows if row.dataset == dataset and row.method == method}
            heights = [by_percent[p].time_ratio if p in by_percent else math.nan for p in percents]
            ax.bar(np.arange(len(percents)) + (k - (len(methods) - 1) / 2) * width, heights, width, label=method)
        ax.axhline(1.0, color="0.3", linewidth=0.8, linestyle="--")
        ax.set_xticks(np.arange(len(percents)), [f"{p:g}%" for p in percents])
        ax.set_title(dataset)
        ax.set_xlabel("outlier rate")
    axes[0].set_ylabel(f"runtime / {baseline_method}" if baseline_method else "runtime ratio")
    axes[-1].legend(fontsize="small")
    _save(figure, path)


def _plot_precision_recall(rows: Sequence[SummaryRow], path: Path) -> None:
    """Two heat-map tables side by side (precision, recall): methods x (dataset, outlier rate)."""
    from matplotlib.figure import Figure

    methods = list(dict.fromkeys(row.method for row in rows))
    columns = list(dict.fromkeys((row.dataset, row.percent) for row in rows))
    cell = {(row.method, row.dataset, row.percent): row for row in rows}
    tables = {
        name: np.array(
            [[getattr(cell[(m, d, p)], name) if (m, d, p) in cell else math.nan for d, p in columns] for m in methods]
        )
        for name in ("precision", "recall")
    }
    finite = np.concatenate([values[np.isfinite(values)] for values in tables.values()])
    low = min(0.9, float(finite.min())) if len(finite) else 0.9  # 0.9 .. 1 unless worse
    size = (2 * (0.9 * len(columns) + 1.6) + 1.0, 0.45 * len(methods) + 1.4)
    figure = Figure(figsize=size, layout="constrained")
    axes = figure.subplots(1, 2, squeeze=False)[0]
    for ax, (name, values) in zip(axes, tables.items()):
        image = ax.imshow(values, cmap="RdYlGn", vmin=low, vmax=1.0, aspect="auto")
        for (i, j), value in np.ndenumerate(values):
            ax.text(j, i, "-" if math.isnan(value) else f"{value:.4f}", ha="center", va="center", fontsize="small")
        ax.set_yticks(np.arange(len(methods)), methods if ax is axes[0] else [])
        ax.set_xticks(np.arange(len(columns)), [f"{d}\n{p:g}%" for d, p in columns], fontsize="small")
        ax.set_title(name)
    figure.colorbar(image, ax=list(axes), shrink=0.9)
    _save(figure, path)
