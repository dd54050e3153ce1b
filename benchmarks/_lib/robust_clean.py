"""Clean files first: the default robust solve against least squares on every shared dataset.

`python benchmarks/robust.py clean [--data-dir ../shared/datasets] [--files MIT,csail,...] [--gtsam-chordal]`

A file without false loop closures is the first test of a robust solver: it must never be worse
than least squares. For each file (cubicle needs `--information`, see its row) this prints the
loop closures the default `egnc.solve` rejects, its ATE against the `l2` optimum, both
least-squares costs over all edges (a lower egnc cost means egnc found a better least-squares
minimum than `l2` from the file's guess), the warnings, and both solve times. With gtsam
installed, `--gtsam-chordal` adds the cost GTSAM's LM reaches from `gtsam.InitializePose3` (3D
files) for comparison.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import egnc
from egnc.metrics import ate


def gtsam_chordal_cost(path: Path) -> float:
    """Least-squares cost GTSAM's LM reaches from `InitializePose3` (3D), with a prior on the first pose."""
    import gtsam

    graph, initial = gtsam.readG2o(str(path), True)
    first = initial.keys()[0]
    graph.add(gtsam.PriorFactorPose3(first, initial.atPose3(first), gtsam.noiseModel.Isotropic.Sigma(6, 1e-3)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(1000)
    start = gtsam.InitializePose3.initialize(graph)
    return float(graph.error(gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()))


def run(data_dir: Path, files: str, gtsam_chordal: bool) -> int:
    """Print the clean-file table of `files` (comma-separated names in `data_dir`) in markdown."""
    columns = ("file", "loops", "rejected", "rejected %", "ATE to l2 (m)", "cost egnc", "cost l2", "warnings")
    header = "| " + " | ".join(columns) + " | egnc (s) | l2 (s) |"
    print(header + (" GTSAM LM from chordal |" if gtsam_chordal else ""))
    print("|---|---:|---:|---:|---:|---:|---:|---|---:|---:|" + ("---:|" if gtsam_chordal else ""))
    for name in files.split(","):
        path = data_dir / f"{name}.g2o"
        if not path.is_file():
            print(f"skipping {name}: {path} not found", file=sys.stderr)
            continue
        graph = egnc.read_g2o(path)
        started = time.perf_counter()
        least_squares = egnc.solve(graph, "l2")
        l2_s = time.perf_counter() - started
        started = time.perf_counter()
        result = egnc.solve(graph)
        egnc_s = time.perf_counter() - started
        loops = int(np.count_nonzero(~result.known_inliers))
        rejected = len(result.rejected_edges)
        row = (
            f"| {name} | {loops} | {rejected} | {100 * rejected / max(loops, 1):.2f} |"
            f" {ate(result.graph.poses, least_squares.graph.poses, graph.dim):.3g} |"
            f" {result.cost:.7g} | {least_squares.cost:.7g} | {'; '.join(result.warnings) or '-'} |"
            f" {egnc_s:.2f} | {l2_s:.2f} |"
        )
        if gtsam_chordal:
            row += f" {gtsam_chordal_cost(path):.7g} |" if graph.dim == 3 else " - |"
        print(row, flush=True)
    return 0
