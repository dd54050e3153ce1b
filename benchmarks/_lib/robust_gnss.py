"""GNSS fixes with multipath outliers and false loop closures: egnc and GTSAM's GNC-TLS side by side.

`python benchmarks/robust.py gnss [--files manhattanOlson3500,sphere2500,city10000] [--loops 0,10,30]
[--priors 0,10,20] [--every 10] [--sigma 2] [--seed 1] [--guess file|heading:0.3|scaled:10]
[--gtsam-time-limit 900] [--no-gtsam]`

For each file: the least-squares optimum of the clean file is the reference of the generators; a
position prior every `--every` poses (sigma `--sigma` m, `egnc.datasets.add_position_priors`),
then false loops (`add_false_loops`) and multipath jumps of 10-50 m (`add_multipath_outliers`),
single or in bursts of 5-20 consecutive fixes. `--guess` other than `file` replaces each case's
guess by its odometry chained with seeded extra noise (`robust_drifted.drifted`: heading noise in
rad a step, or translation noise in odometry sigmas), as a back-end's drifted estimate would be.
Each case is solved by the default `egnc.solve`
(priors and loops both candidates) and, in the same run, by GTSAM's `GncLMOptimizer` (TLS,
per-factor thresholds `setInlierCostThresholdsAtProbability(0.99)`, odometry known inliers; a
`GPSFactor` per fix in 3D, a `PoseTranslationPrior2D` in 2D). Precision and recall (outliers
positive) for loops and for priors apart; ATE without alignment against the least-squares
optimum of the outlier-free factors (the fixes fix the frame); GTSAM's row says "timeout" where
its child process passed `--gtsam-time-limit` seconds; time, and egnc's time over its
solve of the clean file with its clean fixes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

import egnc
from egnc.bench.child import run_in_child
from egnc.datasets import add_false_loops, add_multipath_outliers, add_position_priors
from egnc.graph import PoseGraph
from egnc.io import read_g2o
from egnc.metrics import ate, precision_recall
from egnc.nonlinear.factors import from_matrices, to_matrices

from .paths import dataset_path
from .robust_drifted import drifted


@dataclass(frozen=True)
class Case:
    """One corrupted graph and its labels."""

    name: str
    loops: float
    priors: float
    bursts: bool
    graph: PoseGraph
    false_edges: np.ndarray
    false_priors: np.ndarray
    reference: np.ndarray  # `(N, P)` least-squares optimum of the outlier-free factors


def cases(name: str, loops: list[float], priors: list[float], every: int, sigma: float, seed: int) -> list[Case]:
    """The grid of one file: every false-loop share against every prior-outlier share (single and bursts)."""
    clean = read_g2o(dataset_path(name))
    optimum = egnc.solve(clean, "l2").graph.poses
    built = []
    for loop_share in loops:
        corrupted = add_false_loops(clean, loop_share, seed=seed, reference_poses=optimum) if loop_share else None
        graph = clean if corrupted is None else corrupted.graph
        false_edges = np.zeros(graph.num_edges, bool) if corrupted is None else corrupted.is_outlier
        fixed = add_position_priors(graph, optimum, every=every, sigma=sigma, seed=seed)
        reference = egnc.solve(fixed.subgraph_edges(~false_edges), "l2").graph.poses
        for prior_share in priors:
            for bursts in (False, True) if prior_share else (False,):
                moved = add_multipath_outliers(fixed, prior_share, seed=seed, bursts=bursts, reference_poses=optimum)
                built.append(
                    Case(name, loop_share, prior_share, bursts, moved.graph, false_edges, moved.is_outlier, reference)
                )
    return built


def gtsam_gnc_tls(graph: PoseGraph) -> tuple[np.ndarray, np.ndarray, float]:
    """GTSAM's GNC-TLS on `graph` (edges then position priors): poses `(N, P)`, weights `(E + K,)`, seconds."""
    import gtsam

    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    is_3d = graph.dim == 3
    T = to_matrices(graph.dim, graph.poses)
    Z = to_matrices(graph.dim, graph.measurements)
    keys = graph.vertex_ids.astype(int)
    for k, key in enumerate(keys):
        values.insert(int(key), gtsam.Pose3(T[k]) if is_3d else gtsam.Pose2(*graph.poses[k]))
    order = [3, 4, 5, 0, 1, 2] if is_3d else [0, 1, 2]  # GTSAM's Pose3 tangent is [omega, v]
    for e, (i, j) in enumerate(graph.edges):
        noise = gtsam.noiseModel.Gaussian.Information(graph.information[e][np.ix_(order, order)])
        if is_3d:
            factors.add(gtsam.BetweenFactorPose3(int(keys[i]), int(keys[j]), gtsam.Pose3(Z[e]), noise))
        else:
            factors.add(
                gtsam.BetweenFactorPose2(int(keys[i]), int(keys[j]), gtsam.Pose2(*graph.measurements[e]), noise)
            )
    dim = graph.dim
    for k, row in enumerate(graph.priors.rows):
        noise = gtsam.noiseModel.Gaussian.Information(graph.priors.information[k, :dim, :dim])
        z = graph.priors.measurements[k, :dim].copy()
        if is_3d:
            factors.add(gtsam.GPSFactor(int(keys[row]), z, noise))
        else:
            factors.add(gtsam.PoseTranslationPrior2D(int(keys[row]), z, noise))
    params = gtsam.GncLMParams(gtsam.LevenbergMarquardtParams())
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers([int(e) for e in np.flatnonzero(graph.is_odometry)])
    optimizer = gtsam.GncLMOptimizer(factors, values, params)
    optimizer.setInlierCostThresholdsAtProbability(0.99)
    started = time.perf_counter()
    result = optimizer.optimize()
    seconds = time.perf_counter() - started
    if is_3d:
        poses = from_matrices(3, np.array([result.atPose3(int(key)).matrix() for key in keys]))
    else:
        poses = np.array([[p.x(), p.y(), p.theta()] for p in (result.atPose2(int(key)) for key in keys)])
    return poses, np.asarray(optimizer.getWeights()), seconds


def guessed(graph: PoseGraph, guess: str, seed: int) -> PoseGraph:
    """`graph` with the guess `--guess` names: its own (`file`), or `KIND:LEVEL` drifted (module docstring)."""
    if guess == "file":
        return graph
    kind, level = guess.split(":")
    return drifted(graph, kind, float(level), seed)


def row(case: Case, clean_s: float, gtsam_limit_s: float) -> str:
    """The table row of one case: egnc's scores, then GTSAM's (in a child process stopped after
    `gtsam_limit_s` seconds; 0: no GTSAM column)."""
    graph, E = case.graph, case.graph.num_edges
    started = time.perf_counter()
    result = egnc.solve(graph)
    egnc_s = time.perf_counter() - started
    rejected_priors = np.isin(graph.prior_factor_index, result.rejected_priors)
    cells = [
        case.name,
        f"{case.loops:g}",
        f"{case.priors:g}{' bursts' if case.bursts else ''}",
        *scores(~result.inliers, rejected_priors, case),
        f"{ate(result.graph.poses, case.reference, graph.dim, align=False):.3f}",
        f"{egnc_s:.2f}",
        f"{egnc_s / clean_s:.2f}x",
    ]
    if gtsam_limit_s:
        outcome = run_in_child(gtsam_gnc_tls, (graph,), gtsam_limit_s)
        if outcome.status != "ok":
            return "| " + " | ".join([*cells, outcome.status, "", "", f"{outcome.wall_s:.0f}"]) + " |"
        poses, weights, gtsam_s = outcome.value
        cells += [
            *scores(weights[:E] < 0.5, weights[E:] < 0.5, case),
            f"{ate(poses, case.reference, graph.dim, align=False):.3f}",
            f"{gtsam_s:.2f}",
        ]
    return "| " + " | ".join(cells) + " |"


def scores(rejected_edges: np.ndarray, rejected_priors: np.ndarray, case: Case) -> list[str]:
    """`P/R` of the loops and of the priors, three decimals."""
    loops = precision_recall(rejected_edges, case.false_edges)
    priors = precision_recall(rejected_priors, case.false_priors)
    return [f"{loops[0]:.3f}/{loops[1]:.3f}", f"{priors[0]:.3f}/{priors[1]:.3f}"]


def run(args) -> int:  # noqa: ANN001 (argparse.Namespace)
    """Print the table of every file's grid (module docstring)."""
    loops = [float(v) for v in args.loops.split(",")]
    priors = [float(v) for v in args.priors.split(",")]
    gtsam_limit_s = 0.0 if args.no_gtsam else args.gtsam_time_limit
    head = "| file | false loops % | prior outliers % | egnc loops P/R | egnc priors P/R | egnc ATE m | egnc s"
    head += " | vs clean |"
    rule = "|---|---:|---|---|---|---:|---:|---:|"
    if gtsam_limit_s:
        head += " GNC-TLS loops P/R | GNC-TLS priors P/R | GNC-TLS ATE m | GNC-TLS s |"
        rule += "---|---|---:|---:|"
    print(head)
    print(rule, flush=True)
    for name in args.files.split(","):
        graph = read_g2o(dataset_path(name))
        optimum = egnc.solve(graph, "l2").graph.poses
        clean = add_position_priors(graph, optimum, every=args.every, sigma=args.sigma, seed=args.seed)
        egnc.solve(clean)  # warm: imports and first-call costs stay out of the clean time
        started = time.perf_counter()
        egnc.solve(clean)
        clean_s = time.perf_counter() - started
        for case in cases(name, loops, priors, args.every, args.sigma, args.seed):
            case = replace(case, graph=guessed(case.graph, args.guess, args.seed))
            print(row(case, clean_s, gtsam_limit_s), flush=True)
    return 0
