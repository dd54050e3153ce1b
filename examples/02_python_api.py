"""The Python API: a PoseGraph's arrays, SolverOptions, the Result, and errors that name the line.

Run from anywhere:

    python examples/02_python_api.py
"""

import tempfile
from pathlib import Path

import numpy as np

import egnc

DATASET = Path(__file__).resolve().parents[1] / "datasets" / "grid3d.g2o"


def main() -> None:
    # A PoseGraph holds read-only NumPy arrays in the file's parametrization.
    graph = egnc.read_g2o(DATASET)
    print(f"{DATASET.name}: poses {graph.poses.shape}, edges {graph.edges.shape}, "
          f"information {graph.information.shape}, loop closures {int(graph.is_loop_closure.sum())}")

    # Plain least squares by Gauss-Newton on SciPy's sparse solver (always available).
    options = egnc.SolverOptions(method="gn", max_iterations=20)
    result = egnc.solve(graph, "l2", linear_solver="scipy", options=options)
    print(f"{result.method}/{options.method}: cost {result.initial_cost:.6g} -> {result.cost:.6g}, "
          f"converged {result.converged} ({result.message})")
    for k, stage in enumerate(result.stages):
        print(f"  stage {k}: {stage.iterations} iterations, cost {stage.cost:.6g}, {stage.time_s:.3f} s")

    # Residual norms are whitened (Mahalanobis) distances, one per edge in file order.
    worst = int(np.argmax(result.residual_norms))
    i, j = graph.vertex_ids[graph.edges[worst]]
    print(f"largest residual r = {result.residual_norms[worst]:.3g} on edge {i} -> {j} "
          f"(line {graph.edge_lines[worst]} of the file)")

    # Every deliberate failure is an EgncError; file errors carry the path and line.
    with tempfile.TemporaryDirectory() as folder:
        bad = Path(folder) / "bad.g2o"
        bad.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0\n")
        try:
            egnc.read_g2o(bad)
        except egnc.G2oFormatError as error:
            print(f"G2oFormatError at line {error.line}: {error}")


if __name__ == "__main__":
    main()
