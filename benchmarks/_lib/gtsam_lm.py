"""GTSAM 4.3's least-squares baseline on g2o files: the reference protocol and its Levenberg-Marquardt.

Benchmark-only module: it imports `gtsam` (the optional `bench` extra) and egnc never imports it.

Reference protocol (reproduces every printed digit of `REFERENCE_ERRORS`):
- `gtsam.readG2o(path, is3D)`; graph keys are the g2o vertex ids.
- One prior on the lowest id, at its initial value, isotropic sigma 1e-3 on every tangent
  component. It is appended last, so factor `k < num_edges` is the k-th EDGE line of the file.
- `LevenbergMarquardtOptimizer` with `relativeErrorTol = absoluteErrorTol = 1e-12`,
  `maxIterations = 1000`, everything else GTSAM's default (`lm_params()`).
  GTSAM's own defaults (1e-5, 1e-5, 100) stop early on the 3D files and miss the reference in the
  9th significant digit (sphere2500 675.7009649, tinyGrid3D 9.313909534).
- Error is `graph.error(values)` = 0.5 * sum of squared whitened residuals (prior included).
- Times are wall-clock `time.perf_counter()` around `readG2o` and around `optimize()` alone.

Conventions of this gtsam wheel that egnc matches (checked numerically, see benchmarks/README.md):
`BetweenFactorPose{2,3}` error is `Logmap(Z^-1 Xi^-1 Xj)` (full SE(n) log as the chart);
tangent order is `(x, y, theta)` for Pose2 and `(rx, ry, rz, tx, ty, tz)` for Pose3; `readG2o`
permutes the g2o 6x6 information `(x, y, z, rx, ry, rz)` into that order without rescaling and
normalizes quaternions.

`python benchmarks/least_squares.py reference [files...]` prints the table (`report_lm`); GTSAM's
GNC on the same graphs is `gtsam_gnc`.

References:
- GTSAM 4.3, `gtsam/nonlinear/LevenbergMarquardtOptimizer.cpp`.
"""

from __future__ import annotations

import datetime
import os
import platform
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np

from egnc.bench import GTSAM_PRIOR_SIGMA, add_gtsam_reference_prior

from .paths import dataset_path

# Final LM errors of the reference protocol. Kept as strings: the printed precision is the
# tolerance of the match (see `matches_reference`).
REFERENCE_ERRORS: dict[str, str] = {
    "csail": "19.56406892",
    "intel": "273.2315612",
    "manhattanOlson3500": "73.0393643",
    "city10000": "255.9937253",
    "sphere2500": "675.7009629",
    "parking-garage": "0.6341923996",
    "smallGrid3D": "517.9253324",
    "tinyGrid3D": "9.313909434",
}


@dataclass(frozen=True)
class LoadedGraph:
    """A g2o file read by `gtsam.readG2o`, with the reference prior appended as the last factor."""

    path: str
    is_3d: bool
    graph: gtsam.NonlinearFactorGraph  # `num_edges` between factors in file order, then the prior
    initial: gtsam.Values
    num_poses: int
    num_edges: int
    edge_keys: np.ndarray  # `(num_edges, 2)` int64, (i, j) of each between factor
    prior_index: int  # factor index of the prior, == num_edges
    read_time_s: float  # `readG2o` alone


@dataclass(frozen=True)
class LmResult:
    """One least-squares LM solve under the reference protocol."""

    path: str
    is_3d: bool
    num_poses: int
    num_edges: int
    initial_error: float
    final_error: float  # graph.error(result), prior included
    iterations: int  # accepted LM steps (`optimizer.iterations()`)
    read_time_s: float
    optimize_time_s: float  # `optimize()` alone; median over repeats when repeated
    optimize_times_s: tuple[float, ...]  # every repeat
    reference: float | None
    matches: bool | None  # None when the file has no reference value


def g2o_is_3d(path: str | os.PathLike[str]) -> bool:
    """Whether a g2o file holds SE(3) poses, from its first VERTEX or EDGE tag."""
    with open(path) as handle:
        for line in handle:
            tag = line.split(maxsplit=1)[0] if line.strip() else ""
            if tag.startswith(("VERTEX_SE3", "EDGE_SE3")):
                return True
            if tag.startswith(("VERTEX_SE2", "EDGE_SE2")):
                return False
    raise ValueError(f"{path}: no VERTEX_SE2/SE3 or EDGE_SE2/SE3 line")


def load_g2o(path: str | os.PathLike[str]) -> LoadedGraph:
    """Read a g2o file with `gtsam.readG2o` and append the reference prior on the lowest id.

    Raises:
        ValueError: a factor refers to a pose without an initial value (e.g. an edges-only file).
    """
    path = dataset_path(path)
    is_3d = g2o_is_3d(path)
    start = time.perf_counter()
    graph, initial = gtsam.readG2o(str(path), is_3d)
    read_time_s = time.perf_counter() - start

    num_edges = graph.size()
    edge_keys = np.array([graph.at(k).keys() for k in range(num_edges)], dtype=np.int64)
    edge_keys = edge_keys.reshape(num_edges, 2)
    known = set(initial.keys())
    missing = sorted(set(edge_keys.ravel().tolist()) - known)
    if missing or not known:
        raise ValueError(
            f"{path}: {len(missing)} pose(s) without initial value (e.g. {missing[:3]}); "
            "this baseline needs VERTEX lines"
        )

    add_gtsam_reference_prior(graph, initial, min(known), is_3d)
    return LoadedGraph(
        path=str(path),
        is_3d=is_3d,
        graph=graph,
        initial=initial,
        num_poses=initial.size(),
        num_edges=num_edges,
        edge_keys=edge_keys,
        prior_index=num_edges,
        read_time_s=read_time_s,
    )


def lm_params(
    relative_error_tol: float = 1e-12,
    absolute_error_tol: float = 1e-12,
    max_iterations: int = 1000,
) -> gtsam.LevenbergMarquardtParams:
    """LM parameters of the reference protocol; everything not named keeps GTSAM's default.

    GTSAM stops when `newError <= errorTol` (0), or `currentError - newError <= absoluteErrorTol`,
    or `(currentError - newError) / currentError <= relativeErrorTol`, or after `max_iterations`
    accepted steps. Note: at 1e-12 the last step is below floating-point noise of the cost on the
    large files, so LM may spend its final iteration raising lambda to `lambdaUpperBound` (1e5)
    before stopping (about 17 extra solves on city10000); the error is unaffected.
    """
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(relative_error_tol)
    params.setAbsoluteErrorTol(absolute_error_tol)
    params.setMaxIterations(max_iterations)
    return params


def reference_error(path: str | os.PathLike[str]) -> float | None:
    """The reference final error of a dataset (by file stem), or None if there is none."""
    text = REFERENCE_ERRORS.get(Path(path).stem)
    return None if text is None else float(text)


def matches_reference(path: str | os.PathLike[str], error: float) -> bool | None:
    """Whether `error` rounds to the reference value at the reference's printed precision."""
    text = REFERENCE_ERRORS.get(Path(path).stem)
    if text is None:
        return None
    decimals = len(text.partition(".")[2])
    # Half a unit in the last printed place, plus a hair for binary rounding of the decimal.
    return abs(error - float(text)) <= 0.5 * 10.0**-decimals * (1.0 + 1e-9)


def run_lm(
    path: str | os.PathLike[str],
    params: gtsam.LevenbergMarquardtParams | None = None,
    repeat: int = 1,
) -> LmResult:
    """Solve a g2o file with GTSAM's LM under the reference protocol.

    Args:
        path: g2o file, or a dataset name in `paths.SHARED_DATASETS`.
        params: LM parameters; `lm_params()` when None.
        repeat: number of timed `optimize()` calls, each from the file's initial values; the
            reported time is their median and the error/iterations come from the last one.
    """
    loaded = load_g2o(path)
    params = lm_params() if params is None else params
    times = []
    for _ in range(max(1, repeat)):
        optimizer = gtsam.LevenbergMarquardtOptimizer(loaded.graph, loaded.initial, params)
        start = time.perf_counter()
        result = optimizer.optimize()
        times.append(time.perf_counter() - start)
    final_error = loaded.graph.error(result)
    return LmResult(
        path=loaded.path,
        is_3d=loaded.is_3d,
        num_poses=loaded.num_poses,
        num_edges=loaded.num_edges,
        initial_error=loaded.graph.error(loaded.initial),
        final_error=final_error,
        iterations=optimizer.iterations(),
        read_time_s=loaded.read_time_s,
        optimize_time_s=statistics.median(times),
        optimize_times_s=tuple(times),
        reference=reference_error(loaded.path),
        matches=matches_reference(loaded.path, final_error),
    )


def values_to_arrays(values: gtsam.Values, is_3d: bool) -> tuple[np.ndarray, np.ndarray]:
    """Poses of a `gtsam.Values` as arrays ordered by key.

    Returns:
        keys `(N,)` int64 ascending, and poses `(N, 3)` x, y, theta (radians) for 2D or
        `(N, 7)` x, y, z, qx, qy, qz, qw for 3D, with the quaternion sign chosen so qw >= 0.
    """
    keys = np.array(sorted(values.keys()), dtype=np.int64)
    if is_3d:
        poses = np.empty((len(keys), 7))
        for row, key in enumerate(keys.tolist()):
            pose = values.atPose3(key)
            quat = pose.rotation().toQuaternion()
            poses[row, :3] = pose.translation()
            poses[row, 3:] = (quat.x(), quat.y(), quat.z(), quat.w())
        poses[:, 3:] *= np.where(poses[:, 6:7] < 0.0, -1.0, 1.0)
    else:
        poses = np.empty((len(keys), 3))
        for row, key in enumerate(keys.tolist()):
            pose = values.atPose2(key)
            poses[row] = (pose.x(), pose.y(), pose.theta())
    return keys, poses


def format_lm_table(results: Sequence[LmResult | tuple[str, str]]) -> str:
    """Markdown table of LM results; a `(path, reason)` tuple is printed as a skipped row."""
    lines = [
        "| file | dim | poses | edges | final error | reference | match | iterations | read (s) | optimize (s) |",
        "|---|---|---:|---:|---:|---:|---|---:|---:|---:|",
    ]
    for item in results:
        if isinstance(item, tuple):
            lines.append(f"| {Path(item[0]).name} | | | | skipped: {item[1]} | | | | | |")
            continue
        ref = REFERENCE_ERRORS.get(Path(item.path).stem, "-")
        match = {True: "yes", False: "**no**", None: "-"}[item.matches]
        lines.append(
            f"| {Path(item.path).name} | {'3D' if item.is_3d else '2D'} | {item.num_poses} "
            f"| {item.num_edges} | {item.final_error:.10g} | {ref} | {match} | {item.iterations} "
            f"| {item.read_time_s:.3f} | {item.optimize_time_s:.3f} |"
        )
    return "\n".join(lines)


def report_lm(files: Sequence[str], repeat: int, tol: float, command: str) -> int:
    """Print the LM table of `files` (every reference dataset when empty); 1 if a file misses its reference."""
    rows: list[LmResult | tuple[str, str]] = []
    print(header(command))
    for name in files or list(REFERENCE_ERRORS):
        try:
            rows.append(run_lm(name, lm_params(tol, tol), repeat=repeat))
        except (ValueError, FileNotFoundError) as exc:
            rows.append((str(name), str(exc).splitlines()[0]))
    print(format_lm_table(rows))
    print(
        f"\nLM: relativeErrorTol={tol:g}, absoluteErrorTol={tol:g}, maxIterations=1000, "
        f"other GTSAM defaults; prior sigma {GTSAM_PRIOR_SIGMA:g} on the lowest id. "
        f"optimize (s): median of {max(1, repeat)} run(s)."
    )
    return 0 if all(isinstance(r, tuple) or r.matches is not False for r in rows) else 1


def header(command: str) -> str:
    """The command in backticks, then the date, gtsam's version and the machine, and a blank line."""
    stamp = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    return (
        f"`{command}`\n{stamp}, gtsam {_gtsam_version()}, Python {platform.python_version()}, "
        f"{platform.machine()}, {os.cpu_count()} cpus\n"
    )


def _gtsam_version() -> str:
    try:
        from importlib.metadata import version

        return version("gtsam")
    except Exception:  # metadata missing in a source build
        return "unknown"
