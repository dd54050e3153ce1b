"""The fourth start's gate and its effect: the chordal map of every edge against the initial guess.

    python benchmarks/bench_chordal_all.py [--files ...] [--drifted ...] [--corrupted ...]
        [--percent 10,30,50] [--extra SE-Sync/data/manhattan.g2o,...] [--graduate-corrupted]

For every row (shared files from their own guess, the drifted variants of benchmarks/bench_drifted.py,
shared files with riSAM-protocol false loops at seed 1, extra files from elsewhere) it prints the
truncated least-squares cost (`egnc.robust.decision.truncated_cost`) at the initial guess (`T guess`)
and at the chordal initialization of every edge (`T chordal`, its solve time `chordal s`), which
`egnc.robust.starts.all_edges_decision` compares before it runs; the default's decision (`rejected`,
`start`, `T`, `s`); and the decision of the GNC stage run from the chordal map of every edge
alone (`egnc.solve(graph, init="chordal")` with every other start off: `from chordal`), which is
what the fourth start adds where its gates open. On corrupted rows that last solve takes minutes
on the larger files (sphere2500 at 50 %: 179 s), so it runs there only with `--graduate-corrupted`.
`P`, `R`: precision and recall of the rejections (false loops positive) on corrupted rows.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import egnc
from egnc.api import initial_guess
from egnc.bench.cases import least_squares_optimum
from egnc.datasets import add_false_loops
from egnc.graph import PoseGraph
from egnc.metrics import precision_recall
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.robust.decision import truncated_cost
from egnc.robust.gnc import START_OPTIONS, GncOptions

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_drifted import DEFAULT_DATA, DRIFTED, SHARED, cases, load  # noqa: E402

GUESS_ONLY_FROM_CHORDAL = GncOptions(**dict.fromkeys(START_OPTIONS, False))
CORRUPTED = (
    "MIT,tinyGrid3D,smallGrid3D,csail,intel,kitti_00,manhattanOlson3500,sphere2500,city10000,parking-garage,"
    "sphere_a,cubicle"
)


def rows(args: argparse.Namespace):
    """`(name, graph, is_outlier or None, graduate)` of every row."""
    drifted_rows = argparse.Namespace(**vars(args), heading="0.1,0.3", scaled="10", seeds="1,2")
    for name, graph in cases(drifted_rows):  # clean files, their drifted variants, the extra files
        yield name, graph, None, True
    for name in filter(None, args.corrupted.split(",")):
        graph = load(args.data_dir, name)
        reference = least_squares_optimum(graph, "auto").graph.poses
        for percent in (float(value) for value in args.percent.split(",")):
            corrupted = add_false_loops(graph, percent, seed=1, reference_poses=reference)
            yield f"{name} {percent:g}%", corrupted.graph, corrupted.is_outlier, args.graduate_corrupted


def _decision(graph: PoseGraph, is_outlier: np.ndarray | None, **kwargs) -> str:
    started = time.perf_counter()
    result = egnc.solve(graph, **kwargs)
    seconds = time.perf_counter() - started
    cells = f"{len(result.rejected_edges)} | {result.start} | {result.truncated_cost:.1f} | {seconds:.2f}"
    if is_outlier is not None:
        precision, recall = precision_recall(~result.inliers, is_outlier)
        cells += f" | {precision:.3f} | {recall:.3f}"
    return cells


def main(argv: list[str] | None = None) -> int:
    """Print one markdown row per case as it finishes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--files", default=SHARED, help="shared files from their own guess")
    parser.add_argument("--drifted", default=DRIFTED, help="files (or grid3d) re-chained with drift")
    parser.add_argument("--corrupted", default=CORRUPTED, help="shared files with false loops (seed 1)")
    parser.add_argument("--percent", default="10,30,50")
    parser.add_argument("--extra", default="", help="comma-separated g2o files from elsewhere")
    parser.add_argument("--graduate-corrupted", action="store_true", help="also the 'from chordal' solve there")
    args = parser.parse_args(argv)
    print(
        "| case | loops | T guess | T chordal | chordal s | default: rejected | start | T | s | P | R"
        " | from chordal: rejected | start | T | s | P | R |"
    )
    print("|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|")
    for name, graph, is_outlier, graduate in rows(args):
        factors = BetweenFactors.from_graph(graph)
        robust = ~graph.is_odometry
        d = graph.tangent_dim
        started = time.perf_counter()
        chordal = to_matrices(graph.dim, initial_guess(graph, "chordal", graph.is_odometry, "auto"))
        chordal_s = time.perf_counter() - started
        at = {
            key: truncated_cost(factors.whitened_norms(factors.residuals(poses)), robust, d, 0.99)
            for key, poses in (("guess", to_matrices(graph.dim, graph.poses)), ("chordal", chordal))
        }
        empty = " | |" if is_outlier is None else ""
        default = _decision(graph, is_outlier) + empty
        from_chordal = (
            _decision(graph, is_outlier, init="chordal", gnc_options=GUESS_ONLY_FROM_CHORDAL) + empty
            if graduate
            else "- | - | - | - | - | -"
        )
        print(
            f"| {name} | {int(np.count_nonzero(robust))} | {at['guess']:.1f} | {at['chordal']:.1f} | {chordal_s:.2f}"
            f" | {default} | {from_chordal} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
