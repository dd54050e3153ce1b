"""Factors exposed by the linear solvers and the quadratic forms `B^T H^-1 B` solved on a reach."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import egnc.nonlinear.marginals as marginals_module
from egnc.api import marginal_covariances, solve
from egnc.datasets import grid_world
from egnc.errors import GraphError
from egnc.linalg.linear_solvers import (
    NotPositiveDefiniteError,
    TriangularFactor,
    cholmod_available,
    make_linear_solver,
    rslab_available,
)
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.marginals import innovations, pose_covariances, quadratic_form

BACKENDS = [
    "scipy",
    pytest.param("cholmod", marks=pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")),
    pytest.param("rslab", marks=pytest.mark.skipif(not rslab_available(), reason="no rslab")),
]


def chain_with_branches(n: int, seed: int) -> np.ndarray:
    """An SPD matrix of 3x3 blocks on a chain of `n // 3` poses plus a few random long edges (a pose graph's shape)."""
    rng = np.random.default_rng(seed)
    blocks = n // 3
    pairs = [(k, k + 1) for k in range(blocks - 1)] + [tuple(rng.choice(blocks, 2, replace=False)) for _ in range(4)]
    matrix = np.zeros((n, n))
    for i, j in pairs:
        J = np.zeros((3, n))
        J[:, 3 * i : 3 * i + 3] = -np.eye(3) + 0.1 * rng.normal(size=(3, 3))
        J[:, 3 * j : 3 * j + 3] = np.eye(3)
        matrix += J.T @ J
    return matrix + np.eye(n)


def factorized(backend: str, matrix: np.ndarray):
    stored = sp.csc_matrix(np.tril(matrix) if backend in ("cholmod", "rslab") else matrix)
    return make_linear_solver(backend, stored.indptr, stored.indices).factorize(stored.data)


@pytest.mark.parametrize("backend", ["scipy", BACKENDS[1]])
def test_the_exposed_factor_rebuilds_the_matrix(backend):
    matrix = chain_with_branches(60, seed=1)
    factor = factorized(backend, matrix).triangular()
    assert factor is not None
    L = factor.lower.toarray()
    assert np.allclose(L, np.tril(L))
    D = np.ones(len(L)) if factor.pivots is None else factor.pivots
    permuted = matrix[np.ix_(factor.order, factor.order)]  # P A P^T
    np.testing.assert_allclose(L @ np.diag(D) @ L.T, permuted, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_quadratic_forms_on_the_reach_and_by_whole_solves_equal_a_dense_inverse(backend, monkeypatch):
    matrix = chain_with_branches(90, seed=2)
    rng = np.random.default_rng(3)
    B = sp.csc_matrix(np.where(rng.random((90, 6)) < 0.05, rng.normal(size=(90, 6)), 0.0))
    expected = B.T @ np.linalg.solve(matrix, B.toarray())
    factorization = factorized(backend, matrix)
    np.testing.assert_allclose(quadratic_form(B, factorization), expected, rtol=1e-9, atol=1e-12)  # whole: small
    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    reached = []
    monkeypatch.setattr(marginals_module, "_reach_solve", spy(marginals_module._reach_solve, reached))
    np.testing.assert_allclose(quadratic_form(B, factorization), expected, rtol=1e-9, atol=1e-12)
    assert reached == ([] if backend == "rslab" else [True])  # rslab does not expose its factor
    # A reach too large for the right-hand-side bound, or for the share, falls back to whole solves.
    for name, value in (("_MAX_RHS_VALUES", 1), ("REACH_MAX_SHARE", 0.0)):
        with monkeypatch.context() as patched:
            patched.setattr(marginals_module, name, value)
            reached.clear()
            np.testing.assert_allclose(quadratic_form(B, factorization), expected, rtol=1e-9, atol=1e-12)
            assert reached == ([] if backend == "rslab" else [False])


def spy(reach_solve, calls: list):
    """`reach_solve` recording whether each call solved on the reach (True) or declined (False)."""

    def recorded(factor, B):
        out = reach_solve(factor, B)
        calls.append(out is not None)
        return out

    return recorded


def test_the_reach_solve_is_zero_outside_the_reach_and_exact_on_it(monkeypatch):
    # A chain's first loop closure reaches only the poses eliminated after its ends.
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    matrix = chain_with_branches(90, seed=4)
    factor = factorized("scipy", matrix).triangular()
    assert factor is not None
    B = sp.csc_matrix(([1.0, -1.0], ([5, 40], [0, 0])), shape=(90, 1))
    reach, W = marginals_module._reach_solve(factor, B)
    full = np.linalg.solve(factor.lower.toarray(), B.toarray()[factor.order])
    np.testing.assert_allclose(W, full[reach], rtol=1e-12, atol=1e-14)
    outside = np.setdiff1d(np.arange(90), reach)
    assert len(outside) > 0 and np.all(full[outside] == 0.0)


@pytest.mark.parametrize("backend", ["cholmod", "scipy"])
def test_a_reach_solve_leaves_the_factor_as_it_was(backend, monkeypatch):
    # The solve scales the restricted factor's columns in place: never the factor's own arrays,
    # which every later quadratic form of the same factorization reads again.
    if backend == "cholmod" and not cholmod_available():
        pytest.skip("scikit-sparse is not installed")
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    factor = factorized(backend, chain_with_branches(300, seed=2)).triangular()
    assert factor is not None
    lower = factor.lower.copy()
    B = sp.csc_matrix(([1.0, -1.0, 1.0, -1.0], ([7, 150, 60, 299], [0, 0, 1, 1])), shape=(300, 2))
    first = marginals_module._reach_solve(factor, B)
    second = marginals_module._reach_solve(factor, B)
    assert first is not None and second is not None
    np.testing.assert_array_equal(first[1], second[1])
    assert (factor.lower != lower).nnz == 0
    full = np.linalg.solve(lower.toarray(), B.toarray()[factor.order])
    np.testing.assert_allclose(first[1], full[first[0]], rtol=1e-10, atol=1e-13)


def test_a_factor_whose_columns_reach_past_their_tree_ancestors_is_solved_on_its_whole_reach(monkeypatch):
    # Column 0 holds rows 1 and 2, column 1 only its diagonal: the elimination tree (first row
    # below the diagonal) makes 1 the parent of 0 and misses that 0 reaches 2 directly.
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    lower = sp.csc_matrix(np.array([[2.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.5, 0.0, 1.0]]))
    factor = TriangularFactor(lower, np.arange(3), None)
    B = sp.csc_matrix(np.array([[1.0], [0.0], [0.0]]))
    reach, W = marginals_module._reach_solve(factor, B)
    np.testing.assert_array_equal(reach, [0, 1, 2])
    np.testing.assert_allclose(W[:, 0], np.linalg.solve(lower.toarray(), [1.0, 0.0, 0.0]))


def test_a_panel_joins_only_columns_whose_rows_continue_each_other(monkeypatch):
    # Columns 0 and 1 look like one supernode by their counts (3 and 2) and column 0's first row
    # below the diagonal (1), but column 0 holds row 3 where column 1 holds row 2: solved as one
    # panel, column 0's row-3 entry would land on row 2. Columns 2 and 3 do form one.
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    lower = np.array([[2.0, 0, 0, 0], [0.5, 1.5, 0, 0], [0.0, -0.7, 1.2, 0], [0.3, 0.0, 0.4, 1.1]])
    factor = TriangularFactor(sp.csc_matrix(lower), np.arange(4), None)
    B = sp.csc_matrix(np.array([[1.0, 0.2], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]]))
    reach, W = marginals_module._reach_solve(factor, B)
    np.testing.assert_array_equal(reach, [0, 1, 2, 3])
    np.testing.assert_allclose(W, np.linalg.solve(lower, B.toarray()), rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_innovations_of_a_problem_in_block_order_are_the_same_on_the_reach(backend, monkeypatch):
    # SciPy factorizes a problem's pattern in its block order (`egnc.linalg.analysis.InBlockOrder`): the exposed
    # factor's elimination order maps back to the problem's unknowns.
    graph = grid_world(2, 300, seed=5, noise_scale=0.5).graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[::3]] = True
    poses = to_matrices(2, solve(graph.subgraph_edges(~left_out), "l2").graph.poses)
    problem = Problem.from_graph(graph.subgraph_edges(~left_out), backend)
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    whole = innovations(problem, poses, loops)[1]
    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    reached = []
    monkeypatch.setattr(marginals_module, "_reach_solve", spy(marginals_module._reach_solve, reached))
    on_reach = innovations(problem, poses, loops)[1]
    assert reached == ([] if backend == "rslab" else [True])
    np.testing.assert_allclose(on_reach, whole, rtol=1e-9, atol=1e-12)


def test_columns_without_entries_have_zero_covariance_on_the_reach(monkeypatch):
    # A loop between two fixed poses has no unknowns: its columns of B are empty.
    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    matrix = chain_with_branches(30, seed=6)
    factorization = factorized("scipy", matrix)
    empty = sp.csc_matrix((30, 3))
    np.testing.assert_array_equal(quadratic_form(empty, factorization), np.zeros((3, 3)))
    B = sp.hstack([sp.csc_matrix(np.eye(30)[:, [4]]), empty], format="csc")
    expected = np.zeros((4, 4))
    expected[0, 0] = np.linalg.inv(matrix)[4, 4]
    np.testing.assert_allclose(quadratic_form(B, factorization), expected, rtol=1e-10, atol=1e-14)


CHOLMOD_ONLY = pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")


@CHOLMOD_ONLY
def test_the_exact_factor_pattern_is_that_of_a_dense_cholesky():
    from egnc.linalg.linear_solvers import exact_factor_pattern

    rng = np.random.default_rng(7)
    for _ in range(20):
        n = int(rng.integers(2, 40))
        mask = np.tril(rng.random((n, n)) < 0.1, -1)
        values = np.where(mask, rng.normal(size=(n, n)), 0.0)
        matrix = values + values.T
        matrix += np.diag(np.abs(matrix).sum(axis=0) + 1.0)  # diagonally dominant: positive definite
        factor, order = exact_factor_pattern(sp.csc_matrix(np.tril(matrix)))
        dense = np.linalg.cholesky(matrix[np.ix_(order, order)])  # random values: no entry cancels
        np.testing.assert_array_equal(factor.toarray() != 0, np.abs(dense) > 1e-14)


@CHOLMOD_ONLY
def test_the_reach_estimate_counts_the_entries_of_an_exact_factor_of_the_system(monkeypatch):
    # Column by column, the pose-level estimate equals the exact (simplicial) factor of the
    # system itself, in the same order; the reach of a query is the same positions.
    from egnc.linalg.linear_solvers import exact_factor_pattern

    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    graph = grid_world(2, 400, seed=3).graph
    problem = Problem.from_graph(graph, "cholmod")
    estimate = marginals_module.ReachEstimate.of(problem)
    assert estimate is not None
    pattern = problem.pattern
    lower = sp.csc_matrix((np.ones(pattern.nnz), pattern.indices, pattern.indptr), shape=(pattern.size,) * 2)
    factor, order = exact_factor_pattern(lower)
    d = problem.tangent_dim
    counts = np.diff(factor.indptr)
    position = np.empty(len(order), dtype=np.int64)
    position[order] = np.arange(len(order))
    per_block = np.zeros(pattern.size // d, dtype=np.int64)
    np.add.at(per_block, estimate.position[order // d], counts)  # scalar columns summed by block
    np.testing.assert_array_equal(per_block[np.argsort(estimate.position)], estimate.entries)
    B = sp.csc_matrix(np.eye(pattern.size)[:, np.r_[3 * d : 4 * d, 233 * d : 234 * d]])  # two poses' unknowns
    reach = marginals_module._ancestors(marginals_module._elimination_tree(factor), position[B.indices])
    assert estimate.share(B) == pytest.approx(counts[reach].sum() / counts.sum(), rel=1e-12)


@CHOLMOD_ONLY
def test_the_factor_is_exported_only_for_a_query_that_may_and_a_reach_the_estimate_lets_pay(monkeypatch):
    graph = grid_world(2, 300, seed=5, noise_scale=0.5).graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[::3]] = True
    poses = to_matrices(2, solve(graph.subgraph_edges(~left_out), "l2").graph.poses)
    problem = Problem.from_graph(graph.subgraph_edges(~left_out), "cholmod")
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    whole = innovations(problem, poses, loops)[1]  # a small system: whole solves
    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    estimate = marginals_module.ReachEstimate.of(problem)
    for share, export, exported in ((0.0, True, False), (1.0, False, False), (1.0, True, True)):
        monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", share)
        covariance_solve = marginals_module.covariance_solver(problem, poses)
        S = innovations(problem, poses, loops, covariance_solve, estimate, export)[1]
        assert (covariance_solve.triangular(build=False) is not None) == exported
        np.testing.assert_allclose(S, whole, rtol=1e-9, atol=1e-12)


@CHOLMOD_ONLY
def test_the_reach_solve_on_a_supernodal_factor_equals_whole_solves(monkeypatch):
    # A 3D grid's factor has wide supernodes: the reach is solved in dense panels of many columns.
    graph = grid_world(3, 1500, seed=2).graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[::7]] = True
    problem = Problem.from_graph(graph.subgraph_edges(~left_out), "cholmod")
    poses = to_matrices(3, graph.poses)
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    covariance_solve = marginals_module.covariance_solver(problem, poses)
    whole = innovations(problem, poses, loops, covariance_solve)[1]
    monkeypatch.setattr(marginals_module, "REACH_MIN_UNKNOWNS", 0)
    monkeypatch.setattr(marginals_module, "REACH_MAX_SHARE", 1.0)
    reached = []
    monkeypatch.setattr(marginals_module, "_reach_solve", spy(marginals_module._reach_solve, reached))
    on_reach = innovations(problem, poses, loops, covariance_solve)[1]
    assert reached == [True]
    factor = covariance_solve.triangular()
    # Consecutive columns whose counts fall by one (the diagonal) are a supernode's.
    steps = np.concatenate([[False], np.diff(np.diff(factor.lower.indptr)) == -1, [False]])
    assert np.max(np.diff(np.flatnonzero(~steps))) > 6  # panels wider than one pose
    np.testing.assert_allclose(on_reach, whole, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_poses_the_accepted_edges_cut_off_are_named_not_the_backends_failure(backend):
    """Before, CHOLMOD's own "t_cholmod_rowfac.c:430: not positive definite" or SuperLU's "exactly singular"."""
    graph = grid_world(2, 30, seed=1).graph
    result = solve(graph, "l2", linear_solver=backend)
    cut_off = np.isin(graph.edges, [4, 5]).any(axis=1)  # every edge of rows 4 and 5
    apart = dataclasses.replace(result, inliers=result.inliers & ~cut_off)
    with pytest.raises(
        GraphError,
        match=r"^marginal_covariances: poses \{4\.\.5\} \(2 of 30, in 2 parts of the graph\)"
        r" have no path of accepted edges to a fixed pose, so they have no covariance; accept an edge joining them"
        r" to the rest, or hold one pose of each part fixed$",
    ):
        marginal_covariances(apart)
    problem = Problem.from_graph(graph.subgraph_edges(apart.inliers), backend)
    with pytest.raises(GraphError, match=r"^marginal_covariances: poses \{104\.\.105\} \(2 of 30, in 2 parts"):
        pose_covariances(problem, to_matrices(2, graph.poses), np.arange(3), vertex_ids=graph.vertex_ids + 100)
    assert marginal_covariances(result, graph.vertex_ids[:6]).shape == (6, 3, 3)  # connected: as before


def test_a_singular_information_is_reported_in_egncs_words(monkeypatch):
    def singular(problem, poses):
        raise NotPositiveDefiniteError("normal equations are not positive definite (t_cholmod_rowfac.c:430)")

    monkeypatch.setattr(marginals_module, "covariance_solver", singular)
    result = solve(grid_world(2, 10, seed=1).graph, "l2")
    with pytest.raises(NotPositiveDefiniteError, match="^marginal_covariances: the information of the accepted"):
        marginal_covariances(result)
