"""The GTSAM process that `egnc-solve FILE --method l2 -o OUT` is timed against.

`python benchmarks/least_squares.py gtsam-solve IN.g2o OUT.g2o [--init file|chordal] [--json]`:
`readG2o`, a prior on the first pose (sigma 1e-3, as every GTSAM baseline here),
Levenberg-Marquardt with tolerances 1e-10 (egnc's `SolverOptions` defaults; GTSAM's own 1e-5
stops early on the 3D files) and at most 100 iterations (egnc's default too), `writeG2o`. The same
job as egnc-solve's, start-up and imports included, for whole-process timing:

    <timer> --vs 'python benchmarks/least_squares.py gtsam-solve F /tmp/g.g2o' \
        -- egnc-solve F --method l2 -o /tmp/e.g2o -q

`--init chordal` starts LM from GTSAM's own initialization instead of the file's poses, as
`egnc-solve --init chordal` does from egnc's: LAGO (`gtsam.lago.initialize`) in 2D, the chordal
relaxation `gtsam.InitializePose3.initialize` in 3D; its time is part of `solve_s`.

`--json` prints one line on stdout: `read_s`, `solve_s` (`optimize()` alone), `write_s` (seconds),
`cost` (GTSAM's `0.5 sum r^2`, the prior's included) and `iterations`
(`ls_scale` reads it). The entry imports nothing else before this module, so the process
loads what GTSAM's job needs and no more.
"""

from __future__ import annotations

import json
import time

import gtsam
import numpy as np


def solve_file(source: str, target: str, init: str = "file", as_json: bool = False) -> int:
    """Solve `source` by least squares and write the result to `target`; 0 if the cost is finite."""
    started = time.perf_counter()
    with open(source) as text:
        is_3d = any(line.startswith("VERTEX_SE3") or line.startswith("EDGE_SE3") for line in text)
    graph, initial = gtsam.readG2o(source, is_3d)
    first = initial.keys()[0]
    if is_3d:
        prior = gtsam.PriorFactorPose3(first, initial.atPose3(first), gtsam.noiseModel.Isotropic.Sigma(6, 1e-3))
    else:
        prior = gtsam.PriorFactorPose2(first, initial.atPose2(first), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3))
    graph.add(prior)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-10)
    params.setMaxIterations(100)
    read = time.perf_counter()
    if init == "chordal":
        initial = gtsam.InitializePose3.initialize(graph) if is_3d else gtsam.lago.initialize(graph)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    result = optimizer.optimize()
    solved = time.perf_counter()
    gtsam.writeG2o(graph, result, target)
    cost = graph.error(result)
    if as_json:
        figures = {"read_s": read - started, "solve_s": solved - read, "write_s": time.perf_counter() - solved}
        print(json.dumps(figures | {"cost": cost, "iterations": optimizer.iterations()}))
    return 0 if np.isfinite(cost) else 1
