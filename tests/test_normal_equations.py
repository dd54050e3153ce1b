"""The fixed-pattern assembly equals a dense J^T W J built edge by edge."""

import numpy as np
import pytest

import egnc.linalg.normal_equations as normal_equations_module
from egnc.linalg.linearization import Linearization
from egnc.linalg.normal_equations import NormalEquationsPattern, edge_products


def dense_normal_equations(edges, fixed, d, lin, information, weights):
    """Reference: dense H and g from a stacked dense Jacobian, free poses only."""
    num_poses = len(fixed)
    rows = []
    for k, (i, j) in enumerate(edges):
        J = np.zeros((d, num_poses * d))
        J[:, i * d : (i + 1) * d] += lin.J_e_xi[k]
        J[:, j * d : (j + 1) * d] += lin.J_e_xj[k]
        rows.append(J)
    free_cols = np.concatenate([np.arange(v * d, (v + 1) * d) for v in range(num_poses) if not fixed[v]])
    H = np.zeros((len(free_cols), len(free_cols)))
    g = np.zeros(len(free_cols))
    for k, J in enumerate(rows):
        Jf = J[:, free_cols]
        W = weights[k] * information[k]
        H += Jf.T @ W @ Jf
        g += Jf.T @ W @ lin.residuals[k]
    return H, g


def random_case(rng, num_poses, d):
    chain = np.stack([np.arange(num_poses - 1), np.arange(1, num_poses)], axis=1)
    extra = rng.integers(0, num_poses, size=(2 * num_poses, 2))
    extra = extra[extra[:, 0] != extra[:, 1]]
    edges = np.concatenate([chain, extra, extra[:3, ::-1]])  # duplicates and reversed pairs
    E = len(edges)
    lin = Linearization(rng.normal(size=(E, d)), rng.normal(size=(E, d, d)), rng.normal(size=(E, d, d)))
    A = rng.normal(size=(E, d, d))
    information = A @ A.transpose(0, 2, 1) + d * np.eye(d)
    weights = rng.uniform(0.1, 2.0, size=E)
    return edges, lin, information, weights


def to_dense(pattern, data):
    n = pattern.size
    H = np.zeros((n, n))
    for col in range(n):
        for slot in range(pattern.indptr[col], pattern.indptr[col + 1]):
            H[pattern.indices[slot], col] += data[slot]
    return H


@pytest.mark.parametrize("d", [3, 6])
@pytest.mark.parametrize("lower_only", [False, True])
@pytest.mark.parametrize("fixed_rows", [[0], [0, 4], [3]])
def test_assembly_matches_dense(d, lower_only, fixed_rows):
    rng = np.random.default_rng(d * 10 + len(fixed_rows))
    num_poses = 9
    edges, lin, information, weights = random_case(rng, num_poses, d)
    fixed = np.zeros(num_poses, dtype=bool)
    fixed[fixed_rows] = True
    pattern = NormalEquationsPattern.build(edges, fixed, d, lower_only)
    data, g = pattern.assemble(lin, information, weights)
    H_ref, g_ref = dense_normal_equations(edges, fixed, d, lin, information, weights)
    H = to_dense(pattern, data)
    expected = np.tril(H_ref) if lower_only else H_ref
    np.testing.assert_allclose(H, expected, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(data[pattern.diagonal_slots], np.diag(H_ref), rtol=1e-12)


@pytest.mark.parametrize("d", [3, 6])
@pytest.mark.parametrize("lower_only", [False, True])
def test_assembly_in_a_block_order_is_the_permuted_dense_system(d, lower_only):
    rng = np.random.default_rng(d + 100 * lower_only)
    num_poses = 9
    edges, lin, information, weights = random_case(rng, num_poses, d)
    fixed = np.zeros(num_poses, dtype=bool)
    fixed[[0, 5]] = True
    order = rng.permutation(num_poses - 2)  # unknown block k is the order[k]-th free pose
    pattern = NormalEquationsPattern.build(edges, fixed, d, lower_only, block_order=order)
    data, g = pattern.assemble(lin, information, weights)
    H_ref, g_ref = dense_normal_equations(edges, fixed, d, lin, information, weights)
    scalar = (order[:, None] * d + np.arange(d)).ravel()
    H_ref, g_ref = H_ref[scalar][:, scalar], g_ref[scalar]
    expected = np.tril(H_ref) if lower_only else H_ref
    np.testing.assert_allclose(to_dense(pattern, data), expected, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(data[pattern.diagonal_slots], np.diag(H_ref), rtol=1e-12)
    free_rows = np.flatnonzero(~fixed)
    np.testing.assert_array_equal(pattern.free_index[free_rows[order]], np.arange(num_poses - 2))


@pytest.mark.parametrize("lower_only", [False, True])
def test_an_edge_from_a_pose_to_itself_assembles_as_dense(lower_only):
    """Graphs reject such an edge, but the pattern's off-diagonal blocks must not assume it away:
    both of its poses' blocks land in the one diagonal block."""
    rng = np.random.default_rng(7 + lower_only)
    edges, lin, information, weights = random_case(rng, 6, 3)
    edges[-1] = [4, 4]
    fixed = np.zeros(6, dtype=bool)
    fixed[0] = True
    pattern = NormalEquationsPattern.build(edges, fixed, 3, lower_only)
    data, g = pattern.assemble(lin, information, weights)
    H_ref, g_ref = dense_normal_equations(edges, fixed, 3, lin, information, weights)
    np.testing.assert_allclose(to_dense(pattern, data), np.tril(H_ref) if lower_only else H_ref, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=1e-10)


def test_pattern_is_valid_csc():
    rng = np.random.default_rng(1)
    edges, *_ = random_case(rng, 12, 3)
    fixed = np.zeros(12, dtype=bool)
    fixed[0] = True
    pattern = NormalEquationsPattern.build(edges, fixed, 3, lower_only=False)
    assert pattern.indptr[-1] == pattern.nnz
    for col in range(pattern.size):
        rows = pattern.indices[pattern.indptr[col] : pattern.indptr[col + 1]]
        assert np.all(np.diff(rows) > 0), "rows within a column must be sorted and unique"


@pytest.mark.parametrize("d", [3, 6])
def test_edge_products_in_chunks_equal_one_product_of_all_edges_bit_for_bit(d, monkeypatch):
    _, lin, information, weights = random_case(np.random.default_rng(7), 30, d)
    whole = lin.stacked[:, :, : 2 * d].transpose(0, 2, 1) @ ((weights[:, None, None] * information) @ lin.stacked)
    monkeypatch.setattr(normal_equations_module, "PRODUCTS_CHUNK", 7)  # 92 edges: 14 chunks, the last of one
    np.testing.assert_array_equal(edge_products(lin, information, weights), whole)
