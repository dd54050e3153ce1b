"""Between factors: Jacobians against central differences, reuse of evaluated residuals, norms."""

import numpy as np
import pytest

from egnc.graph import PoseGraph
from egnc.nonlinear.factors import BetweenFactors, group_of, to_matrices


def random_graph(dim: int, rng: np.random.Generator, num_poses: int = 6) -> PoseGraph:
    """Random poses and measurements (angles up to about 3 rad) on a chain plus random pairs."""
    d = 3 if dim == 2 else 6
    group = group_of(dim)
    chain = np.stack([np.arange(num_poses - 1), np.arange(1, num_poses)], axis=1)
    extra = rng.integers(0, num_poses, size=(8, 2))
    edges = np.concatenate([chain, extra[extra[:, 0] != extra[:, 1]]])
    poses = group.exp(rng.normal(scale=1.0, size=(num_poses, d)))
    Z = group.exp(rng.normal(scale=1.0, size=(len(edges), d)))
    to_params = (lambda T: group.to_xytheta(T)) if dim == 2 else (lambda T: group.to_xyz_quat(T))
    A = rng.normal(size=(len(edges), d, d))
    return PoseGraph(
        dim=dim,
        vertex_ids=np.arange(num_poses),
        poses=to_params(poses),
        edges=edges,
        measurements=to_params(Z),
        information=A @ A.transpose(0, 2, 1) + d * np.eye(d),
    )


@pytest.mark.parametrize("dim", [2, 3])
def test_jacobians_match_central_differences(dim):
    rng = np.random.default_rng(dim)
    graph = random_graph(dim, rng)
    factors = BetweenFactors.from_graph(graph)
    group = group_of(dim)
    d = graph.tangent_dim
    T = to_matrices(dim, graph.poses)
    lin = factors.linearize(T)
    h = 1e-6
    for column, J in ((0, lin.J_e_xi), (1, lin.J_e_xj)):
        for k in range(d):
            delta = np.zeros(d)
            delta[k] = h
            numeric = np.empty((graph.num_edges, d))
            for e, pose in enumerate(graph.edges[:, column]):
                plus, minus = T.copy(), T.copy()
                plus[pose] = group.rplus(T[pose], delta)
                minus[pose] = group.rplus(T[pose], -delta)
                numeric[e] = (factors.residuals(plus)[e] - factors.residuals(minus)[e]) / (2 * h)
            np.testing.assert_allclose(J[:, :, k], numeric, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_linearize_reuses_evaluated_residuals_exactly(dim):
    rng = np.random.default_rng(10 + dim)
    graph = random_graph(dim, rng)
    factors = BetweenFactors.from_graph(graph)
    T = to_matrices(dim, graph.poses)
    fresh = factors.linearize(T)
    reused = factors.linearize(T, factors.evaluate(T))
    np.testing.assert_array_equal(fresh.stacked, reused.stacked)
    np.testing.assert_array_equal(fresh.residuals, factors.residuals(T))
    d = graph.tangent_dim
    np.testing.assert_array_equal(fresh.stacked[:, :, :d], fresh.J_e_xi)
    np.testing.assert_array_equal(fresh.stacked[:, :, d : 2 * d], fresh.J_e_xj)


@pytest.mark.parametrize("dim", [2, 3])
def test_whitened_norms_are_mahalanobis_distances(dim):
    rng = np.random.default_rng(20 + dim)
    graph = random_graph(dim, rng)
    factors = BetweenFactors.from_graph(graph)
    e = rng.normal(size=(graph.num_edges, graph.tangent_dim))
    expected = np.sqrt(np.einsum("ei,eij,ej->e", e, graph.information, e))
    np.testing.assert_allclose(factors.whitened_norms(e), expected, rtol=1e-13)
