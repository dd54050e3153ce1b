"""GTSAM baselines of the benchmark grid (the optional `bench` extra's `gtsam` wheel).

The runs follow `benchmarks/_lib/gtsam_lm.py`: the graph goes through a temporary g2o file and
`gtsam.readG2o`, a prior with sigma 1e-3 holds the lowest id at its initial value, the known
inliers are the odometry factors and that prior, GNC (`GncLMOptimizer`) uses GTSAM's default
parameters (inner LM included) and least squares (`LevenbergMarquardtOptimizer`) the reference
protocol's tolerances (1e-12, 1000 iterations). `gtsam` is imported only inside the functions,
which run in the benchmark's child processes.
"""

from __future__ import annotations

import importlib.util
import tempfile
import time
import typing
from pathlib import Path

import numpy as np

from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.interop.gtsam import values_to_poses
from egnc.io import write_g2o

__all__ = ["GTSAM_PRIOR_SIGMA", "add_gtsam_reference_prior", "gtsam_available", "gtsam_solve"]

GTSAM_PRIOR_SIGMA = 1e-3
"""Isotropic sigma of the prior that fixes GTSAM's gauge (benchmarks/_lib/gtsam_lm.py)."""


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


def gtsam_solve(graph: PoseGraph, known_inliers: np.ndarray, method: str) -> tuple[np.ndarray, float, int]:
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
    keys, poses = values_to_poses(values, graph.dim)
    if not np.array_equal(keys.view(np.int64), graph.vertex_ids):
        raise EgncError("GTSAM's result does not hold the graph's poses")
    return poses, time_s, int(iterations)
