"""g2o's own Gauss-Newton on a g2o file, through the `g2opy` wheel (optional: `g2o_available()`).

`solve_g2o` loads the file with `SparseOptimizer.load` (g2o's reader and its `EdgeSE2` /
`EdgeSE3` factors), fixes one vertex (the gauge egnc fixes), and runs
`OptimizationAlgorithmGaussNewton` over a `BlockSolverSE2` / `BlockSolverSE3` with
`LinearSolverEigen` (Eigen's sparse Cholesky; the PyPI wheel is built without CHOLMOD and CSparse).
It stops as egnc's least squares does: a `SparseOptimizerTerminateAction` ends the loop once the
relative cost decrease `(chi2_prev - chi2) / chi2` falls below `rel_cost_tol`, or after
`max_iterations`.

g2o's edge error is not egnc's: `EdgeSE3` takes the vector part of the error quaternion (half the
rotation angle for small errors, so rotation residuals weigh a quarter as much), and `EdgeSE2` the
translation of `Z^-1 Xi^-1 Xj` rather than its SE(2) log. Its optimum is therefore another point;
the caller compares it with egnc's by evaluating egnc's cost at g2o's poses.

References:
- Kuemmerle, Grisetti, Strasdat, Konolige, Burgard, "g2o: A General Framework for Graph
  Optimization", ICRA 2011; g2o's `core/sparse_optimizer_terminate_action.cpp`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class G2oRun:
    """One g2o Gauss-Newton solve."""

    time_s: float  # `initialize_optimization()` plus `optimize()`, seconds (reading excluded)
    iterations: int
    poses: np.ndarray  # `(N, dim + 1, dim + 1)` homogeneous matrices, in the order of `vertex_ids`


def g2o_available() -> bool:
    """Whether the `g2opy` wheel can be imported here."""
    try:
        import g2opy  # noqa: F401
    except ImportError:
        return False
    return True


def solve_g2o(
    path: Path,
    dim: int,
    vertex_ids: np.ndarray,
    fixed_id: int,
    rel_cost_tol: float = 1e-10,
    max_iterations: int = 100,
) -> G2oRun:
    """Solve the g2o file `path` with g2o's Gauss-Newton, vertex `fixed_id` held; the poses of `vertex_ids` `(N,)`."""
    import g2opy as g2o

    linear = g2o.LinearSolverEigenSE3() if dim == 3 else g2o.LinearSolverEigenSE2()
    block = g2o.BlockSolverSE3(linear) if dim == 3 else g2o.BlockSolverSE2(linear)
    optimizer = g2o.SparseOptimizer()
    optimizer.set_algorithm(g2o.OptimizationAlgorithmGaussNewton(block))
    if not optimizer.load(str(path)):
        raise ValueError(f"g2o could not read {path}")
    optimizer.vertex(int(fixed_id)).set_fixed(True)
    terminate = g2o.SparseOptimizerTerminateAction()
    terminate.set_gain_threshold(rel_cost_tol)
    terminate.set_max_iterations(max_iterations)
    optimizer.add_post_iteration_action(terminate)
    started = time.perf_counter()
    optimizer.initialize_optimization()
    iterations = optimizer.optimize(max_iterations)
    time_s = time.perf_counter() - started
    poses = np.array([_matrix(optimizer.vertex(int(key)).estimate(), dim) for key in vertex_ids])
    return G2oRun(time_s, int(iterations), poses)


def _matrix(estimate, dim: int) -> np.ndarray:
    """A vertex estimate (`SE2` or `Isometry3d`) as a `(dim + 1, dim + 1)` homogeneous matrix."""
    if dim == 3:
        return np.asarray(estimate.matrix(), dtype=float)
    x, y, theta = np.asarray(estimate.vector(), dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])
