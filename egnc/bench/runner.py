"""Run the benchmark grid (datasets x outlier percentages x seeds x methods) or an IRL log.

Every run, and every dataset's reference solve, is a `Call` in its own child process, killed at
its time limit (`egnc.bench.child`); a run that does not answer in time is reported as "timeout"
and one that fails as "error: <message>". The calls go to a pool (`egnc.bench.parallel`): one
child at a time (the default), `workers` children at once, or a Dask cluster. The records come
back in the grid's order whatever the pool, so the results table is the same; progress lines are
printed as the runs finish, numbered in that order.
"""

from __future__ import annotations

import os
import typing
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from egnc.bench.cases import (
    REFERENCE_MIN_TIME_S,
    BenchCase,
    corrupted_cases,
    irl_case,
    irl_outlier_percent,
    resolve_dataset,
    solve_reference,
)
from egnc.bench.child import Call, run_in_child
from egnc.bench.gtsam import gtsam_available
from egnc.bench.methods import MethodSpec, parse_method
from egnc.bench.parallel import Pool, open_pool
from egnc.bench.runs import RunRecord, describe_run, record_run, solve_and_score
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io import read_g2o, read_irl
from egnc.io.irl_covariance import CovarianceOrder

__all__ = ["Progress", "run_case", "run_grid", "run_irl"]

Progress = Callable[[str], None]

_Key = typing.TypeVar("_Key", bound=Hashable)


def run_case(
    case: BenchCase, spec: MethodSpec, *, time_limit_s: float = 300.0, linear_solver: str = "auto"
) -> RunRecord:
    """Solve one case with one method in a child process killed after `time_limit_s` seconds."""
    return record_run(case, spec, run_in_child(solve_and_score, (case, spec, linear_solver), time_limit_s))


def run_grid(
    datasets: Sequence[str | os.PathLike],
    percents: Sequence[float],
    seeds: Sequence[int],
    methods: Sequence[str | MethodSpec],
    *,
    data_dir: str | os.PathLike = "../shared/datasets",
    variant: str = "random",
    outlier_rule: str = "squared",
    time_limit_s: float = 300.0,
    linear_solver: str = "auto",
    progress: Progress | None = None,
    workers: int = 1,
    dask_scheduler: str | None = None,
) -> list[RunRecord]:
    """Run every method on every (dataset, percent, seed) corruption (`egnc.bench.cases`).

    Args:
        datasets: g2o paths or names resolved in `data_dir` (`csail` -> `data_dir/csail.g2o`).
        percents: outlier percentages among loop closures, each in [0, 100).
        seeds: corruption seeds.
        methods: specs (`"egnc"`, `"egnc[threshold=distance]"`, `"gtsam-gnc-tls"`, ...) or `MethodSpec`s;
            GTSAM methods are skipped (with a progress note) when gtsam is not importable.
        data_dir: where dataset names are looked up.
        variant: false-loop variant of `add_false_loops` ("random", "group", "mixed", "close").
        outlier_rule: which false-loop candidates count as outliers (`add_false_loops`):
            "squared" (`r^2 > chi2.ppf(0.95, d)`) or "distance" (riSAM's, `r > chi2.ppf(0.95, d)`).
        time_limit_s: per-run limit in seconds.
        linear_solver: egnc's linear backend for every solve, reference included.
        progress: called with one line of text after every run (and for notes).
        workers: child processes at once on this machine (ignored with `dask_scheduler`).
        dask_scheduler: address of a Dask scheduler (`"tcp://127.0.0.1:8786"`) to run the calls on.

    Returns:
        One `RunRecord` per (dataset, percent, seed, method), in that nesting order.

    Raises:
        EgncError: a dataset is not found, the grid has no case, no method can run, or the Dask
            scheduler cannot be reached.
    """
    specs = _specs(methods, progress)
    paths = [resolve_dataset(name, data_dir) for name in datasets]
    if not paths or not percents or not seeds:
        raise EgncError("the grid has no case: give at least one dataset, one percentage and one seed")
    counter = _Counter(len(paths) * len(percents) * len(seeds) * len(specs), progress)
    with open_pool(workers, dask_scheduler) as pool:
        graphs: dict[Path, PoseGraph | str] = {}
        for path in paths:
            try:
                graphs[path] = read_g2o(path)
            except EgncError as error:
                graphs[path] = f"error: {error}"
        references = _references(pool, graphs, time_limit_s, linear_solver)

        def cases() -> Iterator[tuple[Path, float, int, BenchCase | str]]:
            for path in paths:
                reference = references[path]
                if isinstance(reference, str):  # every case of the dataset says why it failed
                    yield from ((path, float(p), int(s), reference) for p in percents for s in seeds)
                else:
                    graph = typing.cast(PoseGraph, graphs[path])
                    corruptions = corrupted_cases(path.stem, graph, reference, percents, seeds, variant, outlier_rule)
                    yield from ((path, float(p), int(s), case) for p, s, case in corruptions)

        runs = (
            (case if isinstance(case, BenchCase) else RunRecord(path.stem, percent, seed, spec.label, case), spec)
            for path, percent, seed, case in cases()
            for spec in specs
        )
        return _run_all(pool, runs, counter, time_limit_s, linear_solver)


def run_irl(
    path: str | os.PathLike,
    methods: Sequence[str | MethodSpec],
    *,
    time_limit_s: float = 300.0,
    linear_solver: str = "auto",
    progress: Progress | None = None,
    workers: int = 1,
    dask_scheduler: str | None = None,
    covariance_order: CovarianceOrder | None = None,
) -> list[RunRecord]:
    """Run every method on an IRL log scored against its own labels (no corruption; see
    `egnc.bench.cases.irl_case`); `covariance_order`: how a 3D log's covariances are read
    (`egnc.io.read_irl`); the other arguments as in `run_grid`."""
    specs = _specs(methods, progress)
    log = read_irl(path, covariance_order)
    name = Path(path).stem
    counter = _Counter(len(specs), progress)
    with open_pool(workers, dask_scheduler) as pool:
        clean = log.graph.subgraph_edges(~log.is_outlier)
        reference = _references(pool, {name: clean}, time_limit_s, linear_solver)[name]
        runs: Iterable[tuple[BenchCase | RunRecord, MethodSpec]]
        if isinstance(reference, str):
            percent = irl_outlier_percent(log)
            runs = ((RunRecord(name, percent, None, spec.label, reference), spec) for spec in specs)
        else:
            case = irl_case(name, log, reference)
            runs = ((case, spec) for spec in specs)
        return _run_all(pool, runs, counter, time_limit_s, linear_solver)


def _references(
    pool: Pool, graphs: Mapping[_Key, PoseGraph | str], time_limit_s: float, linear_solver: str
) -> dict[_Key, np.ndarray | str]:
    """The reference poses `(N, P)` of each graph, solved at once through `pool`; an "error: ..."
    status instead for a graph that is one already, or whose solve failed or timed out."""
    limit = max(time_limit_s, REFERENCE_MIN_TIME_S)
    calls = (
        (key, Call(solve_reference, (graph, linear_solver), limit))
        for key, graph in graphs.items()
        if isinstance(graph, PoseGraph)
    )
    solved = {key: outcome for key, outcome in pool.run(calls)}
    references: dict[_Key, np.ndarray | str] = {}
    for key, graph in graphs.items():
        outcome = solved.get(key)
        if outcome is None:
            references[key] = typing.cast(str, graph)
        elif outcome.status == "ok":
            references[key] = outcome.value
        else:
            references[key] = f"{outcome.status} (reference solve)"
    return references


def _run_all(
    pool: Pool,
    runs: Iterable[tuple[BenchCase | RunRecord, MethodSpec]],
    counter: _Counter,
    time_limit_s: float,
    linear_solver: str,
) -> list[RunRecord]:
    """Run every `(case, spec)` through `pool` (a `RunRecord` in place of the case is already
    decided, e.g. a case that could not be built); the records in the order of `runs`."""
    records: dict[int, RunRecord] = {}
    in_flight: dict[int, tuple[BenchCase, MethodSpec]] = {}

    def calls() -> Iterator[tuple[int, Call]]:
        for slot, (case, spec) in enumerate(runs):
            if isinstance(case, RunRecord):
                records[slot] = counter.report(case)
            else:
                in_flight[slot] = (case, spec)
                yield slot, Call(solve_and_score, (case, spec, linear_solver), time_limit_s)

    for slot, outcome in pool.run(calls()):
        case, spec = in_flight.pop(typing.cast(int, slot))
        records[typing.cast(int, slot)] = counter.report(record_run(case, spec, outcome))
    return [records[slot] for slot in sorted(records)]


def _specs(methods: Iterable[str | MethodSpec], progress: Progress | None) -> list[MethodSpec]:
    """Parsed specs, without the GTSAM ones when gtsam is missing (said through `progress`).

    Raises:
        EgncError: no method given, or none of them can run here.
    """
    specs = [parse_method(method) if isinstance(method, str) else method for method in methods]
    if not specs:
        raise EgncError("no method given")
    skipped = [spec.label for spec in specs if spec.is_gtsam and not gtsam_available()]
    if len(skipped) == len(specs):
        raise EgncError(f"nothing to run: gtsam is not importable (pip install 'egnc[bench]') for {', '.join(skipped)}")
    if skipped and progress is not None:
        progress(f"gtsam is not importable (pip install 'egnc[bench]'): skipping {', '.join(skipped)}")
    return [spec for spec in specs if spec.label not in skipped]


class _Counter:
    """Numbers the runs as they finish and reports each one through `progress`."""

    def __init__(self, total: int, progress: Progress | None):
        self.total = total
        self.done = 0
        self.progress = progress

    def report(self, record: RunRecord) -> RunRecord:
        self.done += 1
        if self.progress is not None:
            self.progress(f"[{self.done}/{self.total}] {describe_run(record)}")
        return record
