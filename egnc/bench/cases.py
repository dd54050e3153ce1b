"""The graphs of the benchmark grid: datasets, their outlier-free references, seeded corruptions.

For every dataset the outlier-free reference is the plain least-squares optimum of the clean
graph (`egnc.solve(graph, "l2")` from the file's guess or from the chordal initialization,
whichever reaches the lower cost: `solve_reference`, run in a child process), computed once. For
every (dataset, percent, seed) the graph is corrupted in memory with
`egnc.datasets.add_false_loops` against that reference; every method then solves the same
corrupted graph, with the odometry as known inliers. An IRL log with ground-truth labels is one
case as it is: its ODOMETRY entries are the known inliers and its reference is the least-squares
optimum of the graph without the labelled outliers (`irl_case`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.api import Result, solve
from egnc.datasets import add_false_loops
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io import IrlLog

__all__ = [
    "REFERENCE_MIN_TIME_S",
    "BenchCase",
    "corrupted_cases",
    "least_squares_optimum",
    "irl_case",
    "irl_outlier_percent",
    "resolve_dataset",
    "solve_reference",
]

REFERENCE_MIN_TIME_S = 60.0
"""The reference least-squares solve of a dataset gets at least this many seconds."""


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


def resolve_dataset(name: str | os.PathLike, data_dir: str | os.PathLike) -> Path:
    """An existing file path as is, else `data_dir/name` or `data_dir/name.g2o`."""
    path = Path(name)
    if path.is_file():
        return path
    for candidate in (Path(data_dir) / path, Path(data_dir) / f"{path}.g2o"):
        if candidate.is_file():
            return candidate
    raise EgncError(f"dataset {str(name)!r} not found: no such file, nor {Path(data_dir) / path}[.g2o]")


def least_squares_optimum(graph: PoseGraph, linear_solver: str) -> Result:
    """Least squares of a (clean) graph from the file's guess, or from the chordal initialization where that is lower.

    Lower means by more than 1e-6 relative: from a drifted guess least squares stops in another
    minimum (MIT: 19x the cost; a 100 000-pose grid: 4.1x), against which false loops would be
    drawn and scored. `Result.init` says which start it is.
    """
    from_guess = solve(graph, "l2", linear_solver=linear_solver)
    from_chordal = solve(graph, "l2", init="chordal", linear_solver=linear_solver)
    return from_chordal if from_chordal.cost < from_guess.cost * (1 - 1e-6) else from_guess


def solve_reference(graph: PoseGraph, linear_solver: str) -> np.ndarray:
    """The least-squares optimum `(N, P)` of a (clean) graph (`least_squares_optimum`); run it in a child process."""
    return least_squares_optimum(graph, linear_solver).graph.poses


def corrupted_cases(
    name: str,
    graph: PoseGraph,
    reference: np.ndarray,
    percents: Sequence[float],
    seeds: Sequence[int],
    variant: str,
    outlier_rule: str = "squared",
) -> Iterator[tuple[float, int, BenchCase | str]]:
    """`(percent, seed, case)` for every corruption of one clean graph, percent-major, lazily.

    `case` is an "error: ..." status instead when `add_false_loops` refuses the graph.
    """
    for percent in percents:
        for seed in seeds:
            try:
                corrupted = add_false_loops(
                    graph,
                    percent,
                    seed=seed,
                    reference_poses=reference,
                    variant=variant,  # type: ignore[arg-type]
                    outlier_rule=outlier_rule,  # type: ignore[arg-type]
                )
            except EgncError as error:
                yield percent, seed, f"error: {error}"
                continue
            yield (
                percent,
                seed,
                BenchCase(
                    dataset=name,
                    percent=float(percent),
                    seed=int(seed),
                    graph=corrupted.graph,
                    is_outlier=corrupted.is_outlier,
                    known_inliers=corrupted.graph.is_odometry,
                    reference=reference,
                ),
            )


def irl_case(name: str, log: IrlLog, reference: np.ndarray) -> BenchCase:
    """The case of an IRL log, scored against its own labels."""
    return BenchCase(name, irl_outlier_percent(log), None, log.graph, log.is_outlier, log.is_odometry, reference)


def irl_outlier_percent(log: IrlLog) -> float:
    """The labelled outliers' share among the log's LOOP entries, in percent (0 without loops)."""
    loops = int(np.count_nonzero(~log.is_odometry))
    return 100.0 * np.count_nonzero(log.is_outlier) / loops if loops else 0.0
