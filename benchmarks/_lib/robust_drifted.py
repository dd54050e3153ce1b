"""Clean graphs from drifted guesses: the default against the guess-only default, GTSAM's GNC-TLS and LM.

`python benchmarks/robust.py drifted [--data-dir ../shared/datasets] [--extra FILE.g2o,...]`

A graph without false loops is the first test of a robust solver, and the file's guess should not
decide its result. For every shared file as given, and for clean files whose guess is re-chained
from odometry with extra seeded noise (`heading`: `N(0, level)` rad per step on the heading, or on
each rotation axis in 3D; `scaled`: translation noise of `level` times each step's own standard
deviation), this prints the loop closures each method rejects and the least-squares cost each
reaches, relative to the least-squares optimum (the lower of `l2` from the guess and from the
chordal initialization):

- `egnc`: the default (`egnc.solve`), with its other starts (`GncOptions.starts`: runs, chordal,
  chordal-all, regrouped, elimination);
- `guess only`: the default before them (`GncOptions(starts=())`);
- `gtsam-gnc-tls`: GTSAM's GncLMOptimizer (TLS, known inliers = odometry), rejected = loops whose
  `r^2 > chi2.ppf(0.99, d)` at its solution (its own inlier rule); `gtsam-lm`: GTSAM's LM from the
  same guess, over every edge.

Each run is a child process killed at `--time-limit` seconds ("timeout"). `--extra` adds files
from elsewhere (e.g. SE-Sync's data/torus3D.g2o and data/manhattan.g2o), solved from their own guess.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import egnc
from egnc.bench.child import Outcome, run_in_child
from egnc.bench.gtsam import gtsam_available, gtsam_solve
from egnc.datasets import grid_world
from egnc.graph import PoseGraph
from egnc.lie import so3
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.initialize import initialize_poses
from egnc.robust.gnc import GncOptions
from egnc.robust.kernels import chi2_quantile

NEEDS_REPAIR = {"cubicle": "nearest-pd"}
"""Shared files whose information matrices are not all positive definite, and the repair used."""


def drifted(graph: PoseGraph, kind: str, level: float, seed: int) -> PoseGraph:
    """`graph` with its guess chained from odometry with extra seeded noise (module docstring)."""
    rng = np.random.default_rng(seed)
    odometry = graph.is_odometry
    dim = graph.dim
    Z = to_matrices(dim, graph.measurements[odometry])
    if kind == "heading":
        if dim == 2:
            angle = rng.normal(0.0, level, size=len(Z))
            c, s = np.cos(angle), np.sin(angle)
            noise = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
        else:
            noise = so3.exp(rng.normal(0.0, level, size=(len(Z), 3)))
        Z[:, :dim, :dim] = Z[:, :dim, :dim] @ noise
    elif kind == "scaled":
        sigma = np.sqrt(np.diagonal(np.linalg.inv(graph.information[odometry]), axis1=1, axis2=2))[:, :dim]
        Z[:, :dim, dim] += level * sigma * rng.standard_normal((len(Z), dim))
    else:
        raise ValueError(f"unknown drift {kind!r}")
    known = np.arange(graph.num_poses) == 0
    poses = initialize_poses(dim, graph.edges[odometry], from_matrices(dim, Z), poses=graph.poses, known=known)
    return graph.with_poses(poses)


def solve_egnc(graph: PoseGraph, method: str, init: str, other_starts: bool) -> dict:
    """One egnc solve (child process): rejected loops, all-edge cost, start, time, warnings."""
    options = GncOptions() if other_starts else GncOptions(starts=())
    result = egnc.solve(graph, method, init=init, gnc_options=options)
    return {
        "rejected": len(result.rejected_edges),
        "cost": result.cost,
        "start": result.start,
        "time_s": result.time_s,
        "warnings": len(result.warnings),
    }


def solve_gtsam(graph: PoseGraph, method: str) -> dict:
    """One GTSAM solve (child process): loops failing `r^2 <= chi2.ppf(0.99, d)` at its solution, cost, time."""
    poses, time_s, _ = gtsam_solve(graph, graph.is_odometry, method)
    factors = BetweenFactors.from_graph(graph)
    r = factors.whitened_norms(factors.residuals(to_matrices(graph.dim, poses)))
    rejected = graph.is_loop_closure & (r**2 > chi2_quantile(0.99, graph.tangent_dim))
    return {"rejected": int(rejected.sum()), "cost": float(0.5 * np.sum(r**2)), "time_s": time_s}


def field(outcome: Outcome | None, key: str, optimum: float | None = None) -> str:
    """One table cell: the value of `key`, relative to `optimum` if given, or why there is none."""
    if outcome is None:
        return "-"
    if outcome.status != "ok":
        return outcome.status.split(":")[0]
    value = outcome.value[key]
    if optimum is not None:
        return f"{value / optimum:.4f}"
    return f"{value:.2f}" if isinstance(value, float) else str(value)


def load(data_dir: Path, name: str) -> PoseGraph:
    """A shared file of `data_dir` (repaired where `NEEDS_REPAIR` says), or `grid3d`: a generated 2000-pose 3D grid."""
    if name == "grid3d":
        return grid_world(3, 2000, seed=1).graph
    return egnc.read_g2o(data_dir / f"{name}.g2o", information=NEEDS_REPAIR.get(name, "strict"))


def cases(args: argparse.Namespace) -> list[tuple[str, PoseGraph]]:
    """`(name, graph)` of every row: shared files as given, their drifted variants, the extra files.

    `args` needs `data_dir`, `files`, `drifted`, `heading`, `scaled`, `seeds` and `extra` (`robust.py drifted`).
    """
    rows = []
    for name in filter(None, args.files.split(",")):
        rows.append((name, load(args.data_dir, name)))
    for name in filter(None, args.drifted.split(",")):
        graph = load(args.data_dir, name)
        for kind, levels in (("heading", args.heading), ("scaled", args.scaled)):
            for level in (float(value) for value in levels.split(",") if value):
                for seed in (int(value) for value in args.seeds.split(",")):
                    rows.append((f"{name} {kind} {level:g} s{seed}", drifted(graph, kind, level, seed)))
    for path in filter(None, args.extra.split(",")):
        rows.append((Path(path).stem, egnc.read_g2o(path)))
    return rows


def run(args: argparse.Namespace) -> int:
    """Print one markdown row per case as it finishes (`args`: the options of `robust.py drifted`)."""
    use_gtsam = gtsam_available() and not args.no_gtsam
    print(
        "| case | loops | egnc rejected | start | egnc cost / LS opt | guess only rejected | guess only cost / LS opt"
        " | gtsam-gnc-tls rejected | gtsam-lm cost / LS opt | egnc s | guess only s | gtsam-gnc-tls s |"
    )
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, graph in cases(args):
        limit = args.time_limit
        new = run_in_child(solve_egnc, (graph, "egnc", "file", True), limit)
        old = run_in_child(solve_egnc, (graph, "egnc", "file", False), limit)
        optimum = min(
            outcome.value["cost"]
            for outcome in (run_in_child(solve_egnc, (graph, "l2", init, False), limit) for init in ("file", "chordal"))
            if outcome.status == "ok"
        )
        tls = run_in_child(solve_gtsam, (graph, "gtsam-gnc-tls"), limit) if use_gtsam else None
        lm = run_in_child(solve_gtsam, (graph, "gtsam-lm"), limit) if use_gtsam else None

        print(
            f"| {name} | {int(graph.is_loop_closure.sum())} | {field(new, 'rejected')} | {field(new, 'start')}"
            f" | {field(new, 'cost', optimum)} | {field(old, 'rejected')} | {field(old, 'cost', optimum)}"
            f" | {field(tls, 'rejected')} | {field(lm, 'cost', optimum)} | {field(new, 'time_s')}"
            f" | {field(old, 'time_s')} | {field(tls, 'time_s')} |",
            flush=True,
        )
    return 0
