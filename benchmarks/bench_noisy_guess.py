"""False loops on manhattanOlson3500 with a worse initial guess: success counts per method.

`python benchmarks/bench_noisy_guess.py [--guess-seeds 1,2] [--percent 10,30,50] [--seeds 1,2]`

The file's guess chains its own odometry. Here the guess chains the odometry measurements with
extra seeded Gaussian noise (`--sigma` metres and radians per step; the measurements the solver
sees are unchanged), so the drift is larger and the first, least-squares stage starts farther
away. Every guess then goes through the riSAM false-loop protocol (`egnc-bench`'s grid, each run
in its own process) with egnc, risam and gnc-tls. The reference of each corrupted case is the
least-squares optimum of its clean graph from the same guess; the script prints its cost next to
the cost from the file's own guess, so a reference stuck in another minimum would show.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import egnc
from egnc.bench import format_markdown, run_grid, summarize
from egnc.graph import PoseGraph
from egnc.nonlinear.initialize import initialize_poses

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "datasets"


def noisier_guess(graph: PoseGraph, seed: int, sigma: tuple[float, float]) -> np.ndarray:
    """`(N, 3)` guess: the 2D odometry with `N(0, sigma)` added per step (translation m, heading rad), chained."""
    rng = np.random.default_rng(seed)
    odometry = graph.is_odometry
    measurements = graph.measurements[odometry].copy()
    measurements[:, :2] += rng.normal(0.0, sigma[0], size=(len(measurements), 2))
    measurements[:, 2] += rng.normal(0.0, sigma[1], size=len(measurements))
    known = np.zeros(graph.num_poses, dtype=bool)
    known[0] = True
    return initialize_poses(2, graph.edges[odometry], measurements, poses=graph.poses, known=known)


def main(argv: list[str] | None = None) -> int:
    """Print the success table of every method on every noisier guess."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data-dir", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--guess-seeds", default="1,2")
    parser.add_argument("--sigma", default="0.05,0.01", help="extra odometry noise per step: metres,radians")
    parser.add_argument("--percent", default="10,30,50")
    parser.add_argument("--seeds", default="1,2")
    parser.add_argument("--methods", default="egnc,risam,gnc-tls")
    parser.add_argument("--time-limit", type=float, default=300.0)
    args = parser.parse_args(argv)
    sigma = tuple(float(value) for value in args.sigma.split(","))
    source = egnc.read_g2o(args.data_dir / "manhattanOlson3500.g2o")
    file_cost = egnc.solve(source, "l2").cost
    with tempfile.TemporaryDirectory(prefix="egnc-noisy-guess-") as folder:
        paths = []
        for seed in (int(value) for value in args.guess_seeds.split(",")):
            graph = source.with_poses(noisier_guess(source, seed, sigma))  # type: ignore[arg-type]
            path = Path(folder) / f"manhattan_guess{seed}.g2o"
            egnc.write_g2o(graph, path)
            paths.append(path)
            l2 = egnc.solve(graph, "l2")
            print(
                f"guess seed {seed}: initial cost {l2.initial_cost:.6g}, l2 cost {l2.cost:.7g} from it"
                f" ({l2.message}), {file_cost:.7g} from the file's guess",
                file=sys.stderr,
            )
        records = run_grid(
            paths,
            [float(value) for value in args.percent.split(",")],
            [int(value) for value in args.seeds.split(",")],
            args.methods.split(","),
            time_limit_s=args.time_limit,
            progress=lambda line: print(line, file=sys.stderr, flush=True),
        )
    print(format_markdown(summarize(records, None), None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
