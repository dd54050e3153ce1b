"""Spanning-tree initialization and connected components."""

from __future__ import annotations

import numpy as np
import pytest

from egnc.errors import GraphError
from egnc.graph.connectivity import connected_components, describe_components, require_connected
from egnc.lie import se2, se3
from egnc.nonlinear.initialize import compose_along_tree, initialize_poses, spanning_tree

GROUPS = {2: (se2, se2.from_xytheta, se2.to_xytheta), 3: (se3, se3.from_xyz_quat, se3.to_xyz_quat)}


def random_poses(rng: np.random.Generator, dim: int, n: int) -> np.ndarray:
    """`(n, P)` random poses: positions in a 20 m box, uniform headings / unit quaternions."""
    if dim == 2:
        return np.column_stack((rng.uniform(-10, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)))
    q = rng.normal(size=(n, 4))
    return np.column_stack((rng.uniform(-10, 10, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)))


def exact_graph(rng: np.random.Generator, dim: int, n: int, extra: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses, and edges with noise-free measurements: a chain with random directions plus loops."""
    group, from_params, to_params = GROUPS[dim]
    poses = random_poses(rng, dim, n)
    chain = np.column_stack((np.arange(n - 1), np.arange(1, n)))
    flip = rng.random(n - 1) < 0.5
    chain[flip] = chain[flip, ::-1]
    loops = rng.integers(0, n, (extra, 2))
    edges = np.concatenate((chain, loops[loops[:, 0] != loops[:, 1]]))
    rng.shuffle(edges)
    T = from_params(poses)
    measurements = to_params(group.between(T[edges[:, 0]], T[edges[:, 1]]))
    return poses, edges, measurements


def assert_same_poses(dim: int, a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> None:
    """Compare poses as matrices (quaternion sign and angle wrapping do not matter)."""
    _, from_params, _ = GROUPS[dim]
    np.testing.assert_allclose(from_params(a), from_params(b), rtol=0, atol=atol)


@pytest.mark.parametrize("dim", [2, 3])
def test_recovers_exact_poses_from_one_known_pose(dim):
    rng = np.random.default_rng(dim)
    poses, edges, measurements = exact_graph(rng, dim, 200, 100)
    known = np.zeros(len(poses), dtype=bool)
    known[0] = True
    guess = initialize_poses(dim, edges, measurements, poses=np.where(known[:, None], poses, 0.0), known=known)
    assert guess[0].tobytes() == poses[0].tobytes()
    assert_same_poses(dim, guess, poses)


@pytest.mark.parametrize("dim", [2, 3])
def test_without_known_poses_first_pose_is_identity(dim):
    rng = np.random.default_rng(10 + dim)
    poses, edges, measurements = exact_graph(rng, dim, 60, 30)
    group, from_params, to_params = GROUPS[dim]
    guess = initialize_poses(dim, edges, measurements)
    expected = to_params(group.between(from_params(poses[0]), from_params(poses)))
    assert_same_poses(dim, guess, expected)
    assert_same_poses(dim, guess[0], to_params(group.identity()), atol=0)


@pytest.mark.parametrize("dim", [2, 3])
def test_known_poses_kept_and_tree_edges_exact(dim):
    rng = np.random.default_rng(20 + dim)
    poses, edges, measurements = exact_graph(rng, dim, 100, 50)
    group, from_params, _ = GROUPS[dim]
    known = rng.random(len(poses)) < 0.3
    known[5] = True
    # Known poses that disagree with the measurements: they must still be kept bit for bit.
    start = np.where(known[:, None], random_poses(rng, dim, len(poses)), np.nan)
    guess = initialize_poses(dim, edges, measurements, poses=start, known=known)
    assert guess[known].tobytes() == start[known].tobytes()
    parent, tree_edge = spanning_tree(len(poses), edges, np.flatnonzero(known))
    np.testing.assert_array_equal(parent[known], -1)
    child = np.flatnonzero(~known)
    k = tree_edge[child]
    T = from_params(guess)
    X_i_j = group.between(T[edges[k, 0]], T[edges[k, 1]])
    np.testing.assert_allclose(X_i_j, from_params(measurements[k]), rtol=0, atol=1e-9)


def test_long_chain_needs_only_logarithmic_passes(monkeypatch):
    n = 20000
    rng = np.random.default_rng(3)
    poses, edges, measurements = exact_graph(rng, 2, n, 0)
    calls = []
    compose = se2.compose
    monkeypatch.setattr(se2, "compose", lambda A, B: calls.append(len(A)) or compose(A, B))
    known = np.arange(n) == 0
    guess = initialize_poses(2, edges, measurements, poses=poses, known=known)
    assert len(calls) <= int(np.ceil(np.log2(n))) + 1
    assert_same_poses(2, guess, poses, atol=1e-8)


def test_spanning_tree_is_breadth_first_and_prefers_first_parallel_edge():
    #   0 - 1 - 2 - 3, plus 0 - 3 twice (reversed, then forward) and a duplicate 1 - 2.
    edges = np.array([[0, 1], [2, 1], [2, 3], [3, 0], [0, 3], [1, 2]])
    parent, tree_edge = spanning_tree(4, edges, np.array([0]))
    np.testing.assert_array_equal(parent[[0, 1, 3]], [-1, 0, 0])
    assert parent[2] in (1, 3)
    np.testing.assert_array_equal(tree_edge[[0, 1, 3]], [-1, 0, 3])
    assert tree_edge[2] == (1 if parent[2] == 1 else 2)


def test_compose_along_tree_inverts_reversed_edges():
    # 1 is the parent of 0 through edge (0, 1): X_0 = X_1 Z^-1.
    Z = np.array([[1.0, 2.0, 0.5]])
    parent, tree_edge = np.array([1, -1]), np.array([0, -1])
    roots = np.array([[0.0, 0.0, 0.0], [3.0, -1.0, 1.0]])
    poses = compose_along_tree(2, parent, tree_edge, np.array([[0, 1]]), Z, roots)
    expected = se2.compose(se2.from_xytheta(roots[1]), se2.inverse(se2.from_xytheta(Z[0])))
    np.testing.assert_allclose(se2.from_xytheta(poses[0]), expected, atol=1e-12)
    assert poses[1].tobytes() == roots[1].tobytes()


def test_unreachable_pose_is_a_graph_error():
    with pytest.raises(GraphError, match="not connected to any pose with a known value"):
        spanning_tree(4, np.array([[0, 1], [2, 3]]), np.array([0]))


def test_components_ordered_by_lowest_row():
    count, labels = connected_components(7, np.array([[5, 6], [1, 2], [6, 0]]))
    assert count == 4
    np.testing.assert_array_equal(labels, [0, 1, 1, 2, 3, 0, 0])


def test_describe_components_compresses_id_runs():
    ids = np.array([0, 1, 2, 5, 7, 8, 10, 20, 30, 40, 50, 60])
    labels = np.array([0, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 4])
    text = describe_components(ids, labels)
    assert text == "{0..2, 5, 7..8, ...} (8 poses), {30} (1 pose), {40} (1 pose), ... (2 more)"


def test_require_connected():
    require_connected(np.array([3, 4, 9]), np.array([[0, 1], [2, 1]]))
    with pytest.raises(GraphError, match=r"^g\.g2o: .*2 connected components: \{3\} \(1 pose\), \{4, 9\} \(2 poses\)"):
        require_connected(np.array([3, 4, 9]), np.array([[1, 2]]), source="g.g2o")


def test_connected_components_match_scipy_csgraph():
    import scipy.sparse
    import scipy.sparse.csgraph

    rng = np.random.default_rng(7)
    graphs = [(int(n), rng.integers(0, n, size=(int(rng.integers(0, 2 * n)), 2))) for n in rng.integers(1, 60, 300)]
    chain = rng.permutation(5000)  # one long path, its edges shuffled: many hooking passes
    graphs.append((5000, np.column_stack((chain[:-1], chain[1:]))[rng.permutation(4999)]))
    graphs.append((4, np.zeros((0, 2), dtype=np.int64)))
    for n, edges in graphs:
        adjacency = scipy.sparse.csr_array((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        expected_count, expected = scipy.sparse.csgraph.connected_components(adjacency, directed=False)
        count, labels = connected_components(n, edges)
        assert count == expected_count
        # The same partition, numbered by each component's lowest row.
        _, lowest_row = np.unique(expected, return_index=True)
        rank = np.empty(expected_count, dtype=np.int64)
        rank[np.argsort(lowest_row)] = np.arange(expected_count)
        assert np.array_equal(labels, rank[expected])
