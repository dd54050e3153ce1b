"""Solve a shipped g2o file with false loop closures and write the result: `egnc-solve` in Python.

Run from anywhere:

    python examples/01_solve_g2o.py [output.g2o]

The output (default `solved.g2o` in the current folder) has the same vertices, FIX lines and
edges as the input; only the poses change.
"""

import sys
from pathlib import Path

import egnc
from egnc.datasets import read_labels

DATASETS = Path(__file__).resolve().parents[1] / "datasets"


def main() -> None:
    output = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("solved.g2o")
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    print(f"read grid2d_outliers.g2o: {graph.num_poses} poses, {graph.num_edges} edges ({graph.dim}D)")

    result = egnc.solve(graph)  # the default method (egnc) and linear solver, as egnc-solve uses
    print(f"method {result.method} on {result.linear_solver}: {len(result.stages)} stages, {result.message}")

    # The generator's ground truth says which loop closures are false; compare with the rejections.
    is_false, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    rejected = ~result.inliers
    print(f"rejected {rejected.sum()} of {int(graph.is_loop_closure.sum())} loop closures, "
          f"{(rejected & is_false).sum()} of the {is_false.sum()} false ones")

    egnc.write_g2o(result.graph, output)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
