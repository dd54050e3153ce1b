"""The sparse GN/LM solver: exact answers on tiny graphs, a dense reference, GTSAM's optima."""

from __future__ import annotations

import numpy as np
import pytest

from egnc.api import solve
from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.io import read_g2o
from egnc.linalg.linear_solvers import cholmod_available, rslab_available
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares

BACKENDS = [
    "scipy",
    pytest.param("cholmod", marks=pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")),
    pytest.param("rslab", marks=pytest.mark.skipif(not rslab_available(), reason="no rslab")),
]

# GTSAM 4.3 LevenbergMarquardtOptimizer from each file's initial guess, prior sigma 1e-3 on the
# first pose, relative/absolute error tolerance 1e-12 (`benchmarks/least_squares.py reference` reproduces them).
GTSAM_OPTIMA = {
    "csail.g2o": 19.56406892,
    "intel.g2o": 273.2315612,
    "manhattanOlson3500.g2o": 73.0393643,
    "city10000.g2o": 255.9937253,
    "sphere2500.g2o": 675.7009629,
    "parking-garage.g2o": 0.6341923996,
    "smallGrid3D.g2o": 517.9253324,
    "tinyGrid3D.g2o": 9.313909434,
}


def triangle_graph(dim: int, consistent: bool) -> PoseGraph:
    """Three poses, two odometry edges and one loop closing the triangle."""
    if dim == 2:
        Z = np.array([[1.0, 0.0, np.pi / 2], [1.0, 0.0, np.pi / 2], [1.0, 1.0 if consistent else 1.3, np.pi]])
        poses = np.array([[0.0, 0.0, 0.0], [0.9, 0.2, 1.4], [1.2, 0.8, 3.0]])  # near the truth
    else:
        q90 = [0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
        Z = np.array([[1.0, 0, 0, *q90], [1.0, 0, 0, *q90], [1.0, 1.0 if consistent else 1.3, 0, 0, 0, 1.0, 0.0]])
        poses = np.array([[0.0, 0, 0, 0, 0, 0, 1], [0.9, 0.1, 0.1, 0, 0, 0.6, 0.8], [1.1, 0.8, 0, 0, 0, 1, 0.1]])
    d = 3 if dim == 2 else 6
    return PoseGraph(
        dim=dim,
        vertex_ids=np.arange(3),
        poses=poses,
        edges=np.array([[0, 1], [1, 2], [0, 2]]),
        measurements=Z,
        information=np.tile(np.eye(d), (3, 1, 1)),
    )


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_consistent_triangle_reaches_zero_cost(dim, backend):
    result = solve(triangle_graph(dim, consistent=True), "l2", linear_solver=backend)
    assert result.converged
    assert result.cost < 1e-20
    # Pose 0 is the gauge: it stays where it was.
    np.testing.assert_allclose(result.graph.poses[0], triangle_graph(dim, True).poses[0], atol=0)


@pytest.mark.parametrize("dim", [2, 3])
def test_single_edge_solution_equals_measurement(dim):
    graph = triangle_graph(dim, consistent=False).subgraph_edges(np.array([True, False, False]))
    graph = PoseGraph(dim, graph.vertex_ids[:2], graph.poses[:2], graph.edges, graph.measurements, graph.information)
    result = solve(graph, "l2")
    T = to_matrices(dim, result.graph.poses)
    Z = to_matrices(dim, graph.measurements[0])
    np.testing.assert_allclose(np.linalg.inv(T[0]) @ T[1], Z, atol=1e-12)


def dense_gauss_newton(graph: PoseGraph, iterations: int) -> np.ndarray:
    """Independent reference: GN with a dense Jacobian assembled edge by edge and np.linalg.solve."""
    factors = BetweenFactors.from_graph(graph)
    from egnc.nonlinear.factors import group_of

    group = group_of(graph.dim)
    d = graph.tangent_dim
    T = to_matrices(graph.dim, graph.poses)
    n = graph.num_poses
    for _ in range(iterations):
        lin = factors.linearize(T)
        J = np.zeros((graph.num_edges * d, n * d))
        for k, (i, j) in enumerate(graph.edges):
            L = np.linalg.cholesky(graph.information[k]).T  # whitening: L^T L = Omega
            J[k * d : (k + 1) * d, i * d : (i + 1) * d] = L @ lin.J_e_xi[k]
            J[k * d : (k + 1) * d, j * d : (j + 1) * d] = L @ lin.J_e_xj[k]
        e = np.concatenate(
            [np.linalg.cholesky(graph.information[k]).T @ lin.residuals[k] for k in range(graph.num_edges)]
        )
        Jf = J[:, d:]  # pose 0 fixed
        step = np.linalg.solve(Jf.T @ Jf, -Jf.T @ e)
        T[1:] = group.rplus(T[1:], step.reshape(-1, d))
    return T


@pytest.mark.parametrize("backend", BACKENDS)
def test_sparse_solver_matches_dense_solve(dataset_path, backend):
    graph = read_g2o(dataset_path("tinyGrid3D.g2o"))
    expected = dense_gauss_newton(graph, iterations=100)
    tight = SolverOptions(rel_cost_tol=0.0, gradient_tol=1e-13, max_iterations=500)
    result = solve(graph, "l2", linear_solver=backend, options=tight)
    # LM judges steps by the cost, which on this graph cannot resolve a decrease below about
    # eps * cost ~ 2e-15 (GN converges only linearly here: the optimum has cost 9.3). Where it
    # stops in that noise depends on rounding: over 20 starts perturbed by 1e-6, the final pose
    # error ranged up to 1.6e-8 (median 4e-10) with either backend and summation order.
    np.testing.assert_allclose(to_matrices(3, result.graph.poses), expected, atol=1e-7)


@pytest.mark.parametrize("name", sorted(GTSAM_OPTIMA))
@pytest.mark.parametrize("backend", BACKENDS)
def test_least_squares_optimum_equals_gtsam(dataset_path, name, backend):
    result = solve(read_g2o(dataset_path(name)), "l2", linear_solver=backend)
    assert result.converged, result.message
    assert result.cost == pytest.approx(GTSAM_OPTIMA[name], rel=1e-6)


@pytest.mark.parametrize("method", ["gn", "lm"])
def test_gauss_newton_and_levenberg_marquardt_agree(dataset_path, method):
    graph = read_g2o(dataset_path("intel.g2o"))
    result = solve(graph, "l2", options=SolverOptions(method=method))
    assert result.cost == pytest.approx(GTSAM_OPTIMA["intel.g2o"], rel=1e-8)


def unjoined_pair_graph() -> PoseGraph:
    """A noisy 2D chain of three poses and, joined to it by no edge, a pair of poses that fits its
    one edge exactly: the pair holds no fixed pose, so its gauge is free and the undamped normal
    equations are singular (with integer Jacobians, exactly: every backend meets a zero pivot)."""
    poses = np.array([[0.0, 0.0, 0.0], [0.9, 0.2, 0.4], [2.1, 0.3, 0.2], [5.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
    return PoseGraph(
        dim=2,
        vertex_ids=np.arange(5),
        poses=poses,
        edges=np.array([[0, 1], [1, 2], [3, 4]]),
        measurements=np.array([[1.0, 0.0, 0.3], [1.0, 0.0, 0.3], [1.0, 0.0, 0.0]]),
        information=np.tile(np.eye(3), (3, 1, 1)),
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_gauss_newton_on_singular_normal_equations_says_to_use_levenberg_marquardt(backend):
    graph = unjoined_pair_graph()
    with pytest.raises(SolverError, match=r"singular.*method='lm'.*--solver lm"):
        solve(graph, "l2", linear_solver=backend, options=SolverOptions(method="gn"))
    result = solve(graph, "l2", linear_solver=backend, options=SolverOptions(method="lm"))
    assert result.converged, result.message
    assert result.cost < 1e-12


def weakly_held_chain() -> PoseGraph:
    """A 2D chain of six poses whose second edge has information 1e-16: the poses after it are held
    only through that edge, and the undamped normal equations are ill-conditioned."""
    rng = np.random.default_rng(0)
    information = np.tile(np.eye(3), (5, 1, 1))
    information[1] *= 1e-16
    return PoseGraph(
        dim=2,
        vertex_ids=np.arange(6),
        poses=np.c_[np.arange(6.0), rng.normal(0, 0.3, 6), rng.normal(0, 0.3, 6)],
        edges=np.c_[np.arange(5), np.arange(1, 6)],
        measurements=np.tile([1.0, 0.0, 0.3], (5, 1)),
        information=information,
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_gauss_newton_on_ill_conditioned_normal_equations_says_to_use_levenberg_marquardt(backend):
    # Depending on the backend's rounding the undamped system factorizes (and the full step
    # increases the cost) or shows a negative pivot: either way the user is told what to do.
    graph = weakly_held_chain()
    try:
        stuck = solve(graph, "l2", linear_solver=backend, options=SolverOptions(method="gn"))
    except SolverError as error:
        message = str(error)
    else:
        assert stuck.status == 4
        message = stuck.message
    assert "--solver lm" in message
    result = solve(graph, "l2", linear_solver=backend, options=SolverOptions(method="lm"))
    assert result.converged, result.message


def test_edges_only_file_solves_from_spanning_tree_guess(dataset_path):
    graph = read_g2o(dataset_path("kitti_00.g2o"))
    result = solve(graph, "l2")
    assert result.converged, result.message
    assert result.cost < 1e-3 * result.initial_cost


def test_iteration_limit_is_reported_not_raised(dataset_path):
    graph = read_g2o(dataset_path("manhattanOlson3500.g2o"))
    result = solve(graph, "l2", options=SolverOptions(max_iterations=1))
    assert result.iterations == 1
    assert result.status == 0 and not result.converged
    assert "maximum number of iterations" in result.message


def test_fixed_poses_do_not_move(dataset_path):
    graph = read_g2o(dataset_path("smallGrid3D.g2o"))
    fixed = np.zeros(graph.num_poses, dtype=bool)
    fixed[[3, 40]] = True
    pinned = PoseGraph(
        graph.dim, graph.vertex_ids, graph.poses, graph.edges, graph.measurements, graph.information, fixed=fixed
    )
    result = solve(pinned, "l2")
    np.testing.assert_array_equal(result.graph.poses[fixed], from_matrices(3, to_matrices(3, graph.poses[fixed])))
    assert not np.allclose(result.graph.poses[0], graph.poses[0])


def test_cost_history_never_increases(dataset_path):
    graph = read_g2o(dataset_path("csail.g2o"))
    problem = Problem.from_graph(graph)
    result = solve_least_squares(problem, to_matrices(2, graph.poses))
    assert np.all(np.diff(result.cost_history) <= 0)
    assert result.cost_history[-1] == result.cost


def test_a_solve_continued_from_kept_errors_is_the_solve_that_evaluates_them(dataset_path):
    graph = read_g2o(dataset_path("intel.g2o"))
    problem = Problem.from_graph(graph)
    guess = to_matrices(2, graph.poses)
    first = solve_least_squares(problem, guess, options=SolverOptions(max_iterations=2), keep_errors=True)
    assert first.errors is not None
    evaluated = problem.factors.evaluate(first.poses)
    np.testing.assert_array_equal(first.errors.residuals, evaluated.residuals)
    np.testing.assert_array_equal(first.errors.T_j_i, evaluated.T_j_i)
    given = solve_least_squares(problem, first.poses, errors=first.errors)
    fresh = solve_least_squares(problem, first.poses)
    assert given.iterations == fresh.iterations > 0
    np.testing.assert_array_equal(given.poses, fresh.poses)
    np.testing.assert_array_equal(given.cost_history, fresh.cost_history)
    assert fresh.errors is None  # not kept unless asked
    # The given residuals are taken as they are: nothing re-evaluates them at the poses.
    at_guess = problem.factors.evaluate(guess)
    stale = solve_least_squares(problem, first.poses, options=SolverOptions(max_iterations=0), errors=at_guess)
    assert stale.cost == first.cost_history[0] != first.cost


@pytest.mark.parametrize("stop_after", [1, 3])
def test_a_solve_continued_at_its_next_damping_is_the_uninterrupted_solve(dataset_path, stop_after):
    graph = read_g2o(dataset_path("manhattanOlson3500.g2o"))
    problem = Problem.from_graph(graph)
    guess = to_matrices(2, graph.poses)
    whole = solve_least_squares(problem, guess, options=SolverOptions(max_iterations=stop_after + 3))
    first = solve_least_squares(problem, guess, options=SolverOptions(max_iterations=stop_after))
    assert 0 < first.next_damping < SolverOptions().initial_damping  # LM lowered it after good steps
    rest = solve_least_squares(
        problem, first.poses, options=SolverOptions(max_iterations=3, initial_damping=first.next_damping)
    )
    np.testing.assert_allclose(rest.cost_history, whole.cost_history[stop_after:], rtol=1e-12)
    np.testing.assert_allclose(rest.poses, whole.poses, atol=1e-10)
    restarted = solve_least_squares(problem, first.poses, options=SolverOptions(max_iterations=3))
    assert not np.allclose(restarted.cost_history, whole.cost_history[stop_after:], rtol=1e-12, atol=0)
    assert solve_least_squares(problem, guess, options=SolverOptions(method="gn", max_iterations=1)).next_damping == 0
