"""What an online update costs as the map grows: odometry-only and loop-closure updates at several map sizes.

    python benchmarks/bench_online_growth.py [--sizes 1000,10000,100000] [--updates 200] [--every 10]
        [--linear-solver auto]

For each size N: an `OnlineSolver` (2D, `egnc` schedule) takes a chain of N odometry edges in one
batch and one update (a slight turn per step, so the chain curls into a spiral); then `--updates`
more updates each add one pose with its odometry, and every `--every`-th also a loop closure to
the pose 5 steps back (its measurement the chain's own relative pose, perturbed by 0.01 m and
0.001 rad, so that it moves the poses around it a little). Each update's wall time is
`UpdateReport.time_s`.

Columns: `poses` (N); `odometry p50 / max ms`: the updates that added only a pose and its
odometry; `loop p50 / max ms`: those that added a loop closure; `loop region poses`: the median
`UpdateReport.region_poses` of those (0: the whole map). An update whose cost follows what it
changed costs the same at every N.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import egnc
from egnc.nonlinear.factors import from_matrices, to_matrices
from egnc.online import OnlineSolver

INFORMATION = np.diag([100.0, 100.0, 400.0])
STEP = np.array([1.0, 0.0, 0.01])  # x y theta: 1 m forward, 0.01 rad to the left


def measure(size: int, updates: int, every: int, linear_solver: str) -> dict:
    """One row: the update times of `updates` updates after a chain of `size` poses."""
    solver = OnlineSolver(2, "egnc", linear_solver=linear_solver)
    solver.add_prior(0, [0.0, 0.0, 0.0])
    ids = np.stack([np.arange(size), np.arange(1, size + 1)], axis=1)
    solver.add_odometry_batch(ids, np.tile(STEP, (size, 1)), np.tile(INFORMATION, (size, 1, 1)))
    solver.update()
    back = 5
    # X_{k+1}^-1 X_{k+1-back} along the chain (`back` steps of STEP undone), perturbed.
    T_back = np.linalg.inv(np.linalg.matrix_power(to_matrices(2, STEP[None])[0], back))
    loop_measurement = from_matrices(2, T_back[None])[0] + np.array([0.01, -0.01, 0.001])
    odometry_ms, loop_ms, region_poses = [], [], []
    for k in range(size, size + updates):
        solver.add_odometry(k, k + 1, STEP, INFORMATION)
        with_loop = (k - size + 1) % every == 0
        if with_loop:
            solver.add_loop(k + 1, k + 1 - back, loop_measurement, INFORMATION)
        report = solver.update()
        (loop_ms if with_loop else odometry_ms).append(1e3 * report.time_s)
        if with_loop:
            region_poses.append(report.region_poses)
    return {
        "poses": size,
        "odometry": (np.median(odometry_ms), np.max(odometry_ms)),
        "loop": (np.median(loop_ms), np.max(loop_ms)) if loop_ms else (np.nan, np.nan),
        "region": float(np.median(region_poses)) if region_poses else np.nan,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1000,10000,100000", help="map sizes (poses), comma-separated")
    parser.add_argument("--updates", type=int, default=200, help="timed updates per size")
    parser.add_argument("--every", type=int, default=10, help="every this many updates adds a loop closure")
    parser.add_argument("--linear-solver", default="auto")
    args = parser.parse_args()
    print(
        f"egnc {egnc.__version__}, numpy {np.__version__}, Python {platform.python_version()},"
        f" {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}"
    )
    print("| poses | odometry p50 / max ms | loop p50 / max ms | loop region poses |")
    print("|---:|---|---|---:|")
    for size in (int(value) for value in args.sizes.split(",")):
        row = measure(size, args.updates, args.every, args.linear_solver)
        odometry, loop = row["odometry"], row["loop"]
        print(
            f"| {size} | {odometry[0]:.3f} / {odometry[1]:.3f} | {loop[0]:.2f} / {loop[1]:.2f} | {row['region']:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
