"""Replay a g2o pose graph pose by pose through GTSAM's ISAM2, with an estimate after every update.

    python benchmarks/online.py isam2 FILE.g2o [--relinearize-threshold 0.1] [--relinearize-skip 10]
        [--reference] [--output ESTIMATE.g2o]

The non-robust incremental baseline that `egnc-solve FILE --online` is timed against
(`online.py vs-isam2`, `online_vs_isam2`). The steps are those of `egnc.online.replay`
(`egnc.online.replay.replay_steps` on the file read by `egnc.io.read_g2o`, odometry = consecutive
ids): one `ISAM2.update` per new pose with its odometry, then its loop closures, in file order,
followed by `calculateEstimate()`. The first update also holds the gauge, the prior of the reference
protocol (`gtsam_lm.load_g2o`: sigma 1e-3 on the lowest id, at its value in the file),
as egnc's replay adds its prior before the first update. A new pose's initial value is its
odometry composed onto the current estimate of the other end (the file's vertex values are not
used after the first pose). The factors are GTSAM's own (`gtsam.readG2o`); every one is checked
to join the same two ids as the egnc edge of the same index.

ISAM2 parameters: GTSAM's defaults (Gauss-Newton, Cholesky, `relinearizeThreshold` 0.1,
`relinearizeSkip` 10), except what the two options set.

Prints one JSON line:
- `file`, `dim`, `poses`, `edges`, `updates` (one per new pose), `gtsam` (version),
  `relinearize_threshold`, `relinearize_skip`;
- `read_s`: both reads; `total_s`: sum over updates of `update()` plus `calculateEstimate()`, the
  counterpart of egnc's `online.total_s` (building the factors excluded, as egnc times
  `OnlineSolver.update()` without the `add_*` calls); `update_s`, `estimate_s`: its two parts;
  `replay_s`: the whole loop, factor building included;
- `update_ms`: `p50`, `p99`, `max` of the per-update times (update plus estimate), milliseconds;
- `cost`: `graph.error` of the final estimate (0.5 * sum of squared whitened residuals, prior
  included); `peak_rss_mib`: this process's peak resident memory (`ru_maxrss`);
- with `--reference` (after everything above is measured): `lm_cost`, the cost of GTSAM's
  Levenberg-Marquardt optimum started from the final estimate (tolerances 1e-10), `lm_s`, and
  `ate_vs_lm_m`, the ATE of the final estimate against it (`egnc.metrics.ate`), metres.
With `--output`, the final estimate is written as a g2o file (`gtsam.writeG2o`).
"""

from __future__ import annotations

import importlib.metadata
import json
import resource
import time

import gtsam
import numpy as np

from egnc.io import read_g2o
from egnc.metrics import ate
from egnc.online.replay import latency_summary, replay_steps

from .gtsam_lm import lm_params, load_g2o, values_to_arrays


def replay_isam2(path: str, relinearize_threshold: float, relinearize_skip: int) -> dict:
    """Replay `path` through ISAM2; the figures of the module docstring and the final `estimate` and `graph`."""
    started = time.perf_counter()
    loaded = load_g2o(path)
    graph = read_g2o(path)
    read_s = time.perf_counter() - started
    edge_ids = graph.vertex_ids[graph.edges]
    if loaded.num_edges != graph.num_edges or not np.array_equal(edge_ids, loaded.edge_keys):
        raise ValueError(f"{path}: gtsam.readG2o and egnc.io.read_g2o disagree on the edges")
    gauge = int(graph.vertex_ids[np.flatnonzero(graph.fixed)[0] if graph.fixed.any() else 0])
    if gauge != min(loaded.initial.keys()):
        raise ValueError(f"{path}: the gauge pose {gauge} is not the lowest id, which the reference prior holds")

    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(relinearize_threshold)
    params.relinearizeSkip = relinearize_skip
    isam = gtsam.ISAM2(params)
    pose_at = "atPose3" if loaded.is_3d else "atPose2"
    known = graph.is_odometry
    estimate = gtsam.Values()
    update_s, estimate_s = [], []
    replay_started = time.perf_counter()
    for number, step in enumerate(replay_steps(graph, known)):
        factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if number == 0:
            factors.add(loaded.graph.at(loaded.prior_index))
            values.insert(gauge, getattr(loaded.initial, pose_at)(gauge))
        for k in step.tolist():
            factor = loaded.graph.at(k)
            factors.add(factor)
            a, b = (int(key) for key in edge_ids[k])
            has_a = estimate.exists(a) or values.exists(a)
            has_b = estimate.exists(b) or values.exists(b)
            if has_a and has_b:
                continue
            if not known[k] or (not has_a and not has_b):
                raise ValueError(f"{path}: edge {k} ({a}, {b}) reaches a pose no earlier odometry placed")
            source = estimate if estimate.exists(a if has_a else b) else values
            if has_a:
                values.insert(b, getattr(source, pose_at)(a).compose(factor.measured()))
            else:
                values.insert(a, getattr(source, pose_at)(b).compose(factor.measured().inverse()))
        tick = time.perf_counter()
        isam.update(factors, values)
        tock = time.perf_counter()
        estimate = isam.calculateEstimate()
        update_s.append(tock - tick)
        estimate_s.append(time.perf_counter() - tock)
    replay_s = time.perf_counter() - replay_started
    update_ms = 1e3 * (np.array(update_s) + np.array(estimate_s))
    return {
        "file": str(path),
        "dim": graph.dim,
        "poses": graph.num_poses,
        "edges": graph.num_edges,
        "updates": len(update_s),
        "gtsam": importlib.metadata.version("gtsam"),
        "relinearize_threshold": relinearize_threshold,
        "relinearize_skip": relinearize_skip,
        "read_s": read_s,
        "total_s": 1e-3 * float(update_ms.sum()),
        "update_s": float(sum(update_s)),
        "estimate_s": float(sum(estimate_s)),
        "replay_s": replay_s,
        "update_ms": latency_summary(update_ms),
        "cost": loaded.graph.error(estimate),
        "estimate": estimate,
        "loaded": loaded,
    }


def report(file: str, relinearize_threshold: float, relinearize_skip: int, reference: bool, output: str | None) -> int:
    """Replay `file` and print the JSON line of the module docstring; write the estimate to `output` if given."""
    row = replay_isam2(file, relinearize_threshold, relinearize_skip)
    estimate, loaded = row.pop("estimate"), row.pop("loaded")
    row["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    if reference:
        started = time.perf_counter()
        optimum = gtsam.LevenbergMarquardtOptimizer(loaded.graph, estimate, lm_params(1e-10, 1e-10, 100)).optimize()
        row["lm_s"] = time.perf_counter() - started
        row["lm_cost"] = loaded.graph.error(optimum)
        poses, optimal_poses = (values_to_arrays(values, loaded.is_3d)[1] for values in (estimate, optimum))
        row["ate_vs_lm_m"] = ate(poses, optimal_poses, 3 if loaded.is_3d else 2)
    if output is not None:
        gtsam.writeG2o(loaded.graph, estimate, output)
    print(json.dumps(row))
    return 0
