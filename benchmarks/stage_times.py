"""Time per GNC stage with false loop closures in the factorization, with and without pruning.

    python benchmarks/stage_times.py [--dataset manhattanOlson3500] [--percent 10 50] [--seed 1]

Prints one markdown row per stage: edges factorized, iterations, stage time and milliseconds per
iteration, for egnc with the default options and with `GncOptions(prune_weight=1e-4)`.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from egnc.api import solve
from egnc.datasets import add_false_loops
from egnc.gnc import GncOptions
from egnc.io import read_g2o

DATASETS = Path(os.environ.get("EGNC_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets"))


def main() -> None:
    """Parse arguments, run egnc on each corrupted graph, print the per-stage table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="manhattanOlson3500")
    parser.add_argument("--percent", type=float, nargs="+", default=[10.0, 50.0])
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    graph = read_g2o(DATASETS / f"{args.dataset}.g2o")
    reference = solve(graph, "l2").graph.poses
    print("| false loops | pruning | stage | mu | edges factorized | iterations | stage time (s) | ms / iteration |")
    print("|---|---|---:|---|---:|---:|---:|---:|")
    for percent in args.percent:
        corrupted = add_false_loops(graph, percent, seed=args.seed, reference_poses=reference)
        for label, options in (("off", GncOptions()), ("1e-4", GncOptions(prune_weight=1e-4))):
            result = solve(corrupted.graph, "egnc", gnc_options=options)
            for index, stage in enumerate(result.stages):
                mu = "-" if np.isnan(stage.mu_mean) else f"{stage.mu_min:.2f}-{stage.mu_max:.2f}"
                per_iteration = 1000 * stage.time_s / max(stage.iterations, 1)
                print(
                    f"| {percent:g} % | {label} | {index} | {mu} | {stage.active_edges} | {stage.iterations}"
                    f" | {stage.time_s:.2f} | {per_iteration:.0f} |"
                )


if __name__ == "__main__":
    main()
