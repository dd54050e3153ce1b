"""The linear-solver backends: fill-reducing block orders and factorizations against dense answers."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

import egnc
import egnc.linalg.linear_solvers as linear_solvers
from egnc.datasets import add_false_loops, grid_world
from egnc.io import read_g2o
from egnc.linalg.linear_solvers import (
    NotPositiveDefiniteError,
    RslabSolver,
    block_order,
    cholmod_available,
    make_linear_solver,
    postorder,
    rslab_available,
)

needs_rslab = pytest.mark.skipif(not rslab_available(), reason="no rslab")


def elimination_tree(matrix: np.ndarray) -> np.ndarray:
    """`(n,)` parent of each column in the elimination tree of the SPD `matrix` (n for a root), densely."""
    n = len(matrix)
    L = np.linalg.cholesky(matrix)
    structural = np.abs(L) > 1e-12 * np.abs(L).max()
    return np.array([next((i for i in range(k + 1, n) if structural[i, k]), n) for k in range(n)])


def random_spd(n: int, density: float, seed: int) -> np.ndarray:
    """A random diagonally dominant symmetric matrix with a sparse pattern."""
    rng = np.random.default_rng(seed)
    upper = np.triu((rng.random((n, n)) < density) * -rng.random((n, n)), 1)
    off = upper + upper.T
    return off + np.diag(1.0 - off.sum(axis=1))


def is_postordered(parent: np.ndarray) -> bool:
    """Whether the columns are in a postorder of the tree `parent` `(n,)` (n for a root).

    In a postorder each column's parent comes later, and the descendants of column k are the
    columns k - size_k + 1 .. k - 1 (size_k counts k and its descendants).
    """
    n = len(parent)
    if not np.all(parent > np.arange(n)):
        return False
    size = np.ones(n + 1, dtype=int)
    for k in range(n):
        size[parent[k]] += size[k]
    first = np.arange(n) - size[:n] + 1
    child = np.flatnonzero(parent < n)
    return bool(np.all(first[parent[child]] <= first[child]))


def test_is_postordered_tells_a_postorder_from_another_topological_order():
    # 0 -> 4, 1 -> 3, 2 -> 4, 3 -> 4: the subtree {1, 3} is split by 2.
    assert not is_postordered(np.array([4, 3, 4, 4, 5]))
    assert is_postordered(np.array([4, 2, 4, 4, 5]))


@pytest.mark.parametrize("seed", range(5))
def test_postorder_puts_children_first_and_keeps_every_subtree_contiguous(seed):
    matrix = random_spd(40, 0.06, seed)
    order = postorder(sp.csc_matrix(np.linalg.cholesky(matrix)))
    assert sorted(order) == list(range(40))
    assert is_postordered(elimination_tree(matrix[np.ix_(order, order)]))


def test_scipy_block_order_keeps_the_fill_of_minimum_degree_and_is_postordered():
    graph = grid_world(2, 400, seed=3).graph
    pairs = graph.edges[(graph.edges != 0).all(axis=1)] - 1  # pose 0 fixed
    n = graph.num_poses - 1
    order = block_order("scipy", n, pairs)
    assert sorted(order) == list(range(n))
    rows, cols = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    adjacency = sp.csc_matrix((np.full(len(rows), -1.0), (rows, cols)), shape=(n, n))
    adjacency.sum_duplicates()
    matrix = (adjacency + sp.diags(1.0 - np.asarray(adjacency.sum(axis=0)).ravel())).toarray()
    lu = splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    minimum_degree = np.argsort(lu.perm_c)
    assert not is_postordered(elimination_tree(matrix[np.ix_(minimum_degree, minimum_degree)]))

    def fill(order: np.ndarray) -> int:
        return np.count_nonzero(np.abs(np.linalg.cholesky(matrix[np.ix_(order, order)])) > 1e-12)

    assert fill(order) == fill(minimum_degree)
    assert is_postordered(elimination_tree(matrix[np.ix_(order, order)]))


@pytest.mark.parametrize(
    ("backend", "lower_only"),
    [("scipy", False), pytest.param("rslab", False, marks=needs_rslab), pytest.param("rslab", True, marks=needs_rslab)],
)
def test_factorization_solves_like_a_dense_solve(backend, lower_only):
    matrix = random_spd(60, 0.08, seed=4)
    stored = sp.csc_matrix(np.tril(matrix) if lower_only else matrix)
    solver = make_linear_solver(backend, stored.indptr, stored.indices)
    rng = np.random.default_rng(1)
    # More columns than rslab solves at once (`_RSLAB_COLUMNS`), in either memory order.
    b, B = rng.normal(size=60), rng.normal(size=(60, 19))
    for values in (stored.data, 2.0 * stored.data):  # a second factorization of the same pattern
        solve = solver.factorize(values)
        dense = matrix * values[0] / stored.data[0]
        np.testing.assert_allclose(solve(b), np.linalg.solve(dense, b), rtol=1e-10, atol=1e-12)
        for rhs in (B, np.asfortranarray(B)):
            np.testing.assert_allclose(solve(rhs), np.linalg.solve(dense, B), rtol=1e-10, atol=1e-12)


@needs_rslab
def test_rslab_reports_indefinite_and_singular_matrices_as_not_positive_definite():
    pattern = sp.csc_matrix(np.tril(np.ones((3, 3))))
    solver = RslabSolver(pattern.indptr, pattern.indices)
    positive = np.array([[4.0, 1, 0], [1, 3, 1], [0, 1, 2]])
    indefinite = np.array([[4.0, 1, 0], [1, -3, 1], [0, 1, 2]])
    singular = np.array([[1.0, 1, 0], [1, 1, 0], [0, 0, 2]])

    def lower_data(matrix: np.ndarray) -> np.ndarray:
        return matrix[pattern.indices, np.repeat(np.arange(3), np.diff(pattern.indptr))]

    np.testing.assert_allclose(solver.solve(lower_data(positive), np.ones(3)), np.linalg.solve(positive, np.ones(3)))
    for matrix in (indefinite, singular):
        with pytest.raises(NotPositiveDefiniteError):
            solver.factorize(lower_data(matrix))


@pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")
@pytest.mark.parametrize("backend", [pytest.param("rslab", marks=needs_rslab), "scipy"])
def test_backend_and_cholmod_give_the_same_robust_solve_of_sphere2500(dataset_path, backend):
    graph = read_g2o(dataset_path("sphere2500.g2o"))
    reference = egnc.solve(graph, "l2", linear_solver="cholmod")
    corrupted = add_false_loops(graph, 10, seed=1, reference_poses=reference.graph.poses).graph
    results = {name: egnc.solve(corrupted, linear_solver=name) for name in ("cholmod", backend)}
    assert results[backend].linear_solver == backend
    np.testing.assert_array_equal(results[backend].inliers, results["cholmod"].inliers)
    assert [s.iterations for s in results[backend].stages] == [s.iterations for s in results["cholmod"].stages]
    np.testing.assert_allclose(results[backend].graph.poses, results["cholmod"].graph.poses, rtol=0, atol=1e-8)


needs_scipy_openblas = pytest.mark.skipif(
    linear_solvers._scipy_openblas() is None, reason="SciPy without its bundled OpenBLAS"
)


@needs_scipy_openblas
def test_serial_native_threads_runs_scipys_openblas_on_one_thread_and_restores_its_count(monkeypatch):
    monkeypatch.setattr(linear_solvers, "USER_CHOSE_OPENBLAS_THREADS", False)
    library = linear_solvers._scipy_openblas()
    before = library.scipy_openblas_get_num_threads()
    library.scipy_openblas_set_num_threads(2)
    try:
        with linear_solvers.serial_native_threads():
            assert library.scipy_openblas_get_num_threads() == 1
        assert library.scipy_openblas_get_num_threads() == 2
        # A count set after egnc's import (as Dask's LocalCluster does) is nobody's choice ...
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
        with linear_solvers.serial_native_threads():
            assert library.scipy_openblas_get_num_threads() == 1
        # ... one set before it is the user's, and left alone.
        monkeypatch.setattr(linear_solvers, "USER_CHOSE_OPENBLAS_THREADS", True)
        with linear_solvers.serial_native_threads():
            assert library.scipy_openblas_get_num_threads() == 2
    finally:
        library.scipy_openblas_set_num_threads(before)


@needs_scipy_openblas
def test_superlu_factorizes_and_solves_on_one_openblas_thread(monkeypatch):
    import scipy.sparse.linalg

    monkeypatch.setattr(linear_solvers, "USER_CHOSE_OPENBLAS_THREADS", False)
    library = linear_solvers._scipy_openblas()
    seen = []

    class Recorded:
        def __init__(self, lu):
            self.lu = lu

        def solve(self, rhs):
            seen.append(("solve", library.scipy_openblas_get_num_threads()))
            return self.lu.solve(rhs)

    def recorded_splu(*args, **kwargs):
        seen.append(("factorize", library.scipy_openblas_get_num_threads()))
        return Recorded(splu(*args, **kwargs))

    monkeypatch.setattr(scipy.sparse.linalg, "splu", recorded_splu)
    matrix = sp.csc_matrix(random_spd(40, 0.1, seed=2))
    before = library.scipy_openblas_get_num_threads()
    library.scipy_openblas_set_num_threads(2)
    try:
        solve = make_linear_solver("scipy", matrix.indptr, matrix.indices).factorize(matrix.data)
        x = solve(np.ones((40, 3)))
        assert library.scipy_openblas_get_num_threads() == 2
    finally:
        library.scipy_openblas_set_num_threads(before)
    assert seen == [("factorize", 1), ("solve", 1)]
    np.testing.assert_allclose(matrix @ x, np.ones((40, 3)), atol=1e-12)


def grid_block_pairs(poses: int) -> tuple[int, np.ndarray]:
    """`(blocks, (K, 2) block pairs)` of a generated 2D grid with pose 0 fixed (as `Problem.from_graph` orders)."""
    graph = grid_world(2, poses, seed=3).graph
    joined = graph.edges[(graph.edges != 0).all(axis=1)]
    return poses - 1, joined - 1


@pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")
def test_cholmod_orders_a_graph_of_metis_min_blocks_by_nested_dissection_and_solves_alike(monkeypatch):
    blocks, pairs = grid_block_pairs(3000)
    amd = block_order("cholmod", blocks, pairs)
    monkeypatch.setattr(linear_solvers, "METIS_MIN_BLOCKS", blocks)
    metis = block_order("cholmod", blocks, pairs)
    assert np.array_equal(np.sort(metis), np.arange(blocks)) and not np.array_equal(metis, amd)
    graph = grid_world(2, 3000, seed=3).graph
    with_metis = egnc.solve(graph, "l2", linear_solver="cholmod")
    monkeypatch.setattr(linear_solvers, "METIS_MIN_BLOCKS", blocks + 1)
    with_amd = egnc.solve(graph, "l2", linear_solver="cholmod")
    assert with_metis.converged and with_metis.iterations == with_amd.iterations
    np.testing.assert_allclose(with_metis.graph.poses, with_amd.graph.poses, rtol=0, atol=1e-8)


@pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")
def test_cholmod_without_metis_orders_a_large_graph_by_amd(monkeypatch):
    import sksparse.cholmod

    blocks, pairs = grid_block_pairs(500)
    amd = block_order("cholmod", blocks, pairs)
    analyze = sksparse.cholmod.analyze

    def without_metis(matrix, **options):
        if options.get("ordering_method") == "metis":
            raise sksparse.cholmod.CholmodNotInstalledError("METIS is not installed")
        return analyze(matrix, **options)

    monkeypatch.setattr(sksparse.cholmod, "analyze", without_metis)
    monkeypatch.setattr(linear_solvers, "METIS_MIN_BLOCKS", 1)
    np.testing.assert_array_equal(block_order("cholmod", blocks, pairs), amd)


def test_cholmods_block_pattern_is_the_lower_triangle_of_the_block_graph():
    """What CHOLMOD orders: every block's diagonal and one entry per joined pair, whatever the
    direction or repeats, against SciPy's own triangle of the symmetric pattern."""
    rng = np.random.default_rng(11)
    for blocks in (1, 2, 7, 60):
        pairs = rng.integers(0, blocks, size=(3 * blocks, 2))
        pairs = np.concatenate([pairs, pairs[: blocks // 2, ::-1]])  # repeats, both directions
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        pattern = linear_solvers._lower_block_pattern(blocks, pairs)
        symmetric = sp.coo_matrix(
            (np.ones(2 * len(pairs) + blocks), (np.r_[pairs[:, 0], pairs[:, 1], np.arange(blocks)],
                                                np.r_[pairs[:, 1], pairs[:, 0], np.arange(blocks)])),
            shape=(blocks, blocks),
        )
        expected = sp.tril(symmetric, format="csc")
        expected.sum_duplicates()
        expected.sort_indices()
        assert pattern.has_sorted_indices and pattern.indices.dtype == np.int32
        np.testing.assert_array_equal(pattern.indptr, expected.indptr)
        np.testing.assert_array_equal(pattern.indices, expected.indices)
