"""GTSAM 4.3's robust baseline: `GncLMOptimizer` (GNC-GM or GNC-TLS) on a g2o file, under a time limit.

The graph is the reference protocol's (`gtsam_lm.load_g2o`: readG2o and a prior on the lowest id);
GNC uses GTSAM's defaults (inlier threshold 0.5 chi2(0.99, d) on the factor error, mu step 1.4;
in 4.3 `setKnownInliers` appends to the existing list). Each run happens in a child process that
is killed at a time limit, so a stuck GTSAM solve becomes a reported timeout instead of a hang.

`python benchmarks/robust.py gnc [--loss gm|tls] [files...]` prints the table (`report_gnc`).

References:
- GTSAM 4.3, `gtsam/nonlinear/GncOptimizer.h`.
- Yang, Antonante, Tzoumas, Carlone, "Graduated Non-Convexity for Robust Spatial Perception",
  RA-L 2020.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import gtsam
import numpy as np

from .gtsam_lm import REFERENCE_ERRORS, LoadedGraph, header, lm_params, load_g2o, values_to_arrays
from .paths import dataset_path

GncKind = Literal["gm", "tls"]
GncStatus = Literal["ok", "timeout", "error"]


@dataclass(frozen=True)
class GncResult:
    """One GTSAM GNC solve, run in a child process under a time limit."""

    path: str
    kind: GncKind
    status: GncStatus  # "timeout": killed at `time_limit_s`; "error": see `message`
    message: str
    time_limit_s: float
    wall_time_s: float  # parent-side, includes process start and transfer
    read_time_s: float | None
    optimize_time_s: float | None  # `GncLMOptimizer.optimize()` alone
    keys: np.ndarray | None  # `(N,)` int64, ascending
    poses: np.ndarray | None  # `(N, 3)` x, y, theta or `(N, 7)` x, y, z, qx, qy, qz, qw (qw >= 0)
    edge_keys: np.ndarray | None  # `(M, 2)` int64, (i, j) of each file edge, in file order
    weights: np.ndarray | None  # `(M,)` final GNC weight of each file edge, in [0, 1]
    prior_weight: float | None
    known_inliers: np.ndarray | None  # factor indices passed to `setKnownInliers`
    final_error: float | None  # unweighted graph.error(result), prior included


def odometry_inliers(loaded: LoadedGraph) -> np.ndarray:
    """Factor indices of the default known inliers: odometry edges (`j == i + 1`) and the prior."""
    odometry = np.flatnonzero(loaded.edge_keys[:, 1] == loaded.edge_keys[:, 0] + 1)
    return np.append(odometry, loaded.prior_index).astype(np.int64)


def _gnc_params(kind: GncKind, known_inliers: np.ndarray, base: Literal["default", "tight"]) -> gtsam.GncLMParams:
    """GNC parameters: GTSAM defaults except the loss, the known inliers and the inner LM."""
    inner = gtsam.LevenbergMarquardtParams() if base == "default" else lm_params()
    params = gtsam.GncLMParams(inner)
    params.setLossType({"gm": gtsam.GncLossType.GM, "tls": gtsam.GncLossType.TLS}[kind])
    # setKnownInliers appends to the existing list; the params object is fresh here.
    params.setKnownInliers([int(k) for k in known_inliers])
    return params


def _gnc_child(conn, path: str, kind: GncKind, known_inliers, base) -> None:
    """Child-process body of `run_gnc`: solve and send one dict back through `conn`."""
    try:
        loaded = load_g2o(path)
        inliers = odometry_inliers(loaded) if known_inliers is None else np.asarray(known_inliers)
        optimizer = gtsam.GncLMOptimizer(loaded.graph, loaded.initial, _gnc_params(kind, inliers, base))
        start = time.perf_counter()
        result = optimizer.optimize()
        optimize_time_s = time.perf_counter() - start
        weights = np.asarray(optimizer.getWeights(), dtype=float)
        keys, poses = values_to_arrays(result, loaded.is_3d)
        conn.send(
            dict(
                status="ok",
                message="",
                read_time_s=loaded.read_time_s,
                optimize_time_s=optimize_time_s,
                keys=keys,
                poses=poses,
                edge_keys=loaded.edge_keys,
                weights=weights[: loaded.num_edges],
                prior_weight=float(weights[loaded.prior_index]),
                known_inliers=np.asarray(inliers, dtype=np.int64),
                final_error=loaded.graph.error(result),
            )
        )
    except Exception as exc:  # reported to the parent, never raised across the process boundary
        conn.send(dict(status="error", message=f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


def run_gnc(
    path: str | os.PathLike[str],
    kind: GncKind = "gm",
    time_limit_s: float = 600.0,
    known_inliers: Sequence[int] | None = None,
    base: Literal["default", "tight"] = "default",
) -> GncResult:
    """Solve a g2o file with `gtsam.GncLMOptimizer` in a child process killed at a time limit.

    The graph is the reference protocol's (readG2o + prior, see `load_g2o`); GNC uses GTSAM's
    defaults (inlier threshold 0.5 chi2(0.99, d) on the factor error, mu step 1.4).

    Args:
        path: g2o file, or a dataset name in `paths.SHARED_DATASETS`.
        kind: "gm" (Geman-McClure) or "tls" (truncated least squares).
        time_limit_s: wall-clock limit for the child (read + solve + transfer), seconds.
        known_inliers: factor indices never reweighted; default odometry edges and the prior
            (`odometry_inliers`). Edge k of the file is factor k, the prior is factor M.
        base: inner LM parameters: GTSAM's defaults, or the reference protocol's `lm_params()`.
    """
    if kind not in ("gm", "tls"):
        raise ValueError(f"kind must be 'gm' or 'tls', got {kind!r}")
    path_str = str(dataset_path(path))
    inliers = None if known_inliers is None else [int(k) for k in known_inliers]
    # spawn: the child starts clean, whatever threads or GTSAM state the caller has.
    context = multiprocessing.get_context("spawn")
    receiver, sender = context.Pipe(duplex=False)
    start = time.perf_counter()
    process = context.Process(target=_gnc_child, args=(sender, path_str, kind, inliers, base), daemon=True)
    process.start()
    sender.close()  # so a child that dies without sending shows up as EOF
    payload: dict = {}
    try:
        if receiver.poll(time_limit_s):
            payload = receiver.recv()
        else:
            payload = dict(status="timeout", message=f"killed after {time_limit_s:g} s")
    except EOFError:
        process.join(5.0)
        payload = dict(status="error", message=f"child exited with code {process.exitcode}")
    finally:
        if process.is_alive() and payload.get("status") != "ok":
            process.kill()
        process.join()
        receiver.close()
    wall_time_s = time.perf_counter() - start
    return GncResult(
        path=path_str,
        kind=kind,
        status=payload["status"],
        message=payload.get("message", ""),
        time_limit_s=time_limit_s,
        wall_time_s=wall_time_s,
        read_time_s=payload.get("read_time_s"),
        optimize_time_s=payload.get("optimize_time_s"),
        keys=payload.get("keys"),
        poses=payload.get("poses"),
        edge_keys=payload.get("edge_keys"),
        weights=payload.get("weights"),
        prior_weight=payload.get("prior_weight"),
        known_inliers=payload.get("known_inliers"),
        final_error=payload.get("final_error"),
    )


def format_gnc_table(results: Sequence[GncResult]) -> str:
    """Markdown table of GNC results: status, times, and how many loop closures were rejected."""
    lines = [
        "| file | kind | status | final error | loops | weight < 0.5 | optimize (s) | wall (s) |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for res in results:
        if res.status != "ok":
            lines.append(
                f"| {Path(res.path).name} | {res.kind} | {res.status}: {res.message} | | | | | {res.wall_time_s:.1f} |"
            )
            continue
        loops = res.edge_keys[:, 1] != res.edge_keys[:, 0] + 1
        rejected = int(np.count_nonzero(res.weights[loops] < 0.5))
        lines.append(
            f"| {Path(res.path).name} | {res.kind} | ok | {res.final_error:.10g} "
            f"| {int(loops.sum())} | {rejected} | {res.optimize_time_s:.3f} "
            f"| {res.wall_time_s:.1f} |"
        )
    return "\n".join(lines)


def report_gnc(files: Sequence[str], kind: GncKind, time_limit_s: float, command: str) -> int:
    """Print the GNC table of `files` (every reference dataset when empty); 1 if a run did not finish."""
    print(header(command))
    results = [run_gnc(name, kind, time_limit_s) for name in files or list(REFERENCE_ERRORS)]
    print(format_gnc_table(results))
    return 0 if all(r.status == "ok" for r in results) else 1
