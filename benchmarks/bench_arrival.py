"""How well an online update's stages are predicted at arrival (`egnc.online.arrival`), against solving them.

    python benchmarks/bench_arrival.py [--datasets csail,intel,manhattanOlson3500] [--percents 10,30,50]
        [--seeds 0]

Each case (riSAM-protocol false loops, `egnc.datasets.add_false_loops`) is replayed with the egnc
schedule and *every* update solved, as by default; at each loop update the solver also predicts
it as `OnlineOptions(decide_at_arrival=True)` would (a subclass overrides the private method that
answers, and answers "solve"), so that the prediction is compared with the solve on the same
states. Poses and edges are fed as `egnc.online.replay` feeds them (`add_gauge`, `add_step`).

Columns:
- `predicted loops`: new loops of the updates whose first stage was predicted (the others lack
  a factorized map, or a loop hangs at both ends);
- `first stage`: `|log10(r_predicted / r_solved)|` of the new loops' residual after the first
  stage, median and 99th percentile;
- `decided`: updates the option would have decided at arrival;
- `solve kept a loop`: of those, the solve ended with a new loop accepted (`r^2` below the 0.99
  quantile);
- `solve found lower`: of those, the solve ended at a cost (all loops at `mu = 1`) lower than
  the start's by more than 0.1 %: a move the update decided at arrival does not make;
- `moved > 1 m`: of those, the solve moved some pose by more than 1 m.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

DATASETS = Path(os.environ.get("EGNC_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets"))

HEADER = (
    "| dataset | % | seed | loop updates | predicted loops | first stage median / p99 | decided"
    " | solve kept a loop | solve found lower | moved > 1 m |"
)


def run(graph, known) -> str:
    """Replay one corrupted graph; its row's cells after the first three."""
    from egnc.online import OnlineOptions, OnlineSolver
    from egnc.online.replay import add_gauge, add_step, replay_steps
    from egnc.robust.losses import KernelLoss

    watch: dict = {}

    class Watched(OnlineSolver):
        def _first_stage(self, new_loops, num_old_poses, num_old_edges):  # type: ignore[override]
            first = super()._first_stage(new_loops, num_old_poses, num_old_edges)
            watch["first"] = None if first is None else first.residual_norms[new_loops]
            return first

        def _decided_at_arrival(self, new_loops, first):  # type: ignore[override]
            mu = self._mu.copy()
            mu[new_loops] = 1.0
            cost = float(np.sum(KernelLoss(self._kernel, mu, self._robust).cost(self._r)))
            watch["decided"] = (super()._decided_at_arrival(new_loops, first), self._T.copy(), cost)
            return False

    ratios, outcomes = [], []
    solver = Watched(graph.dim, "egnc", online_options=OnlineOptions(decide_at_arrival=True))
    add_gauge(solver, graph)
    for edges in replay_steps(graph, known):
        add_step(solver, graph, edges, known)
        report = solver.update()
        predicted, decided = watch.pop("first", None), watch.pop("decided", None)
        if predicted is None or not len(report.new_loops):
            continue
        ratios.extend(np.abs(np.log10(predicted / report.residual_history[0])))
        if decided is not None and decided[0]:
            _, T_before, cost_before = decided
            rows = len(T_before)
            moved = np.max(np.linalg.norm(solver._T[:rows, :-1, -1] - T_before[:, :-1, -1], axis=1))
            cost_after = float(np.sum(KernelLoss(solver._kernel, solver._mu, solver._robust).cost(solver._r)))
            kept = not np.isin(report.new_loops, solver.rejected).all()
            outcomes.append((kept, cost_after < cost_before * (1 - 1e-3), moved > 1.0))
    counts = np.array(outcomes, dtype=bool).reshape(-1, 3).sum(axis=0)
    median, p99 = (np.percentile(ratios, q) if ratios else np.nan for q in (50, 99))
    return (
        f" {len(ratios)} | {median:.4f} / {p99:.3f} | {len(outcomes)} | {counts[0]} | {counts[1]} | {counts[2]} |"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--datasets", default="csail,intel,manhattanOlson3500")
    parser.add_argument("--percents", default="10,30,50")
    parser.add_argument("--seeds", default="0")
    args = parser.parse_args()

    import egnc
    from egnc.api import solve
    from egnc.datasets import add_false_loops
    from egnc.io import read_g2o
    from egnc.online.replay import replay_steps

    print(
        f"egnc {egnc.__version__}, Python {platform.python_version()}, numpy {np.__version__},"
        f" {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}",
        file=sys.stderr,
    )
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    for name in filter(None, args.datasets.split(",")):
        graph = read_g2o(DATASETS / f"{name}.g2o")
        reference = solve(graph, "l2").graph.poses
        for percent in (float(p) for p in args.percents.split(",")):
            for seed in (int(s) for s in args.seeds.split(",")):
                corrupted = add_false_loops(graph, percent, seed=seed, reference_poses=reference).graph
                known = corrupted.is_odometry
                loop_updates = sum(bool((~known[step]).any()) for step in replay_steps(corrupted, known))
                cells = run(corrupted, known)
                print(f"| {name} | {percent:.0f} | {seed} | {loop_updates} |{cells}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
