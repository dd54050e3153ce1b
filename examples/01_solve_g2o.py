"""Solve a shipped g2o file and write the optimized graph: the Python twin of `egnc-solve`.

Run from anywhere:

    python examples/01_solve_g2o.py [output.g2o]

The output (default `solved.g2o` in the current folder) has the same vertices, FIX lines and
edges as the input; only the poses change.
"""

import sys
from pathlib import Path

import egnc

DATASET = Path(__file__).resolve().parents[1] / "datasets" / "grid2d_outliers.g2o"


def main() -> None:
    output = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("solved.g2o")
    graph = egnc.read_g2o(DATASET)
    print(f"read {DATASET.name}: {graph.num_poses} poses, {graph.num_edges} edges ({graph.dim}D)")

    result = egnc.solve(graph)  # the default method and linear solver, as egnc-solve uses
    print(f"method {result.method} on {result.linear_solver}: {result.message}")
    print(f"cost {result.initial_cost:.6g} -> {result.cost:.6g} in {result.iterations} iterations")

    egnc.write_g2o(result.graph, output)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
