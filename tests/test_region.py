"""Local regions (`egnc.online.region`): neighbourhoods, the local problem, the boundary's block-Jacobi decrease."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.graph import PoseGraph
from egnc.linalg.normal_equations import edge_products
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.online.region import LocalProblem, Neighbourhoods, block_jacobi_decrease

DATA = Path(__file__).parents[1] / "datasets"


def _chain_with_loop() -> np.ndarray:
    """Edges of a 20-pose chain and one loop 2 -> 17."""
    chain = np.stack([np.arange(19), np.arange(1, 20)], axis=1)
    return np.vstack([chain, [[2, 17]]])


def test_within_counts_hops_through_every_edge():
    neighbourhoods = Neighbourhoods.of(_chain_with_loop(), 20)
    assert neighbourhoods.within(np.array([10]), 2).tolist() == [8, 9, 10, 11, 12]
    # From pose 1, the loop reaches 17 in two hops.
    assert neighbourhoods.within(np.array([1]), 2).tolist() == [0, 1, 2, 3, 17]
    assert neighbourhoods.within(np.array([4, 4, 0]), 0).tolist() == [0, 4]


def test_edges_of_are_the_edges_with_an_end_among_the_poses():
    edges = _chain_with_loop()
    neighbourhoods = Neighbourhoods.of(edges, 20)
    rows = np.array([2, 3])
    expected = np.flatnonzero(np.isin(edges, rows).any(axis=1))
    assert neighbourhoods.edges_of(rows).tolist() == expected.tolist() == [1, 2, 3, 19]


def _within_by_passes(edges: np.ndarray, num_poses: int, seeds: np.ndarray, hops: int) -> np.ndarray:
    """The reference: one pass over every edge per hop."""
    inside = np.zeros(num_poses, dtype=bool)
    inside[seeds] = True
    for _ in range(hops):
        inside[edges[inside[edges].any(axis=1)]] = True
    return np.flatnonzero(inside)


def test_a_grown_index_answers_as_passes_over_every_edge_do():
    rng = np.random.default_rng(5)
    num_poses = 3000
    chain = np.stack([np.arange(num_poses - 1), np.arange(1, num_poses)], axis=1)
    loops = rng.integers(0, num_poses, size=(1500, 2))
    loops = loops[loops[:, 0] != loops[:, 1]]
    edges = np.vstack([chain, loops])[rng.permutation(len(chain) + len(loops))]
    neighbourhoods = Neighbourhoods()
    grown = 0
    rebuilt_with_a_tail = False
    while grown < len(edges):
        grown = min(len(edges), grown + int(rng.integers(1, 400)))
        seen = edges[:grown]
        poses = int(seen.max()) + 1
        neighbourhoods.grow(seen, poses)
        # Some states hold an index and a tail at once: both must be read.
        rebuilt_with_a_tail |= 0 < neighbourhoods._indexed < grown
        hops_along = rng.random(grown) < 0.7
        seeds = rng.integers(0, poses, size=3)
        hops = int(rng.integers(0, 6))
        expected = _within_by_passes(seen[hops_along], poses, seeds, hops)
        assert neighbourhoods.within(seeds, hops, hops_along).tolist() == expected.tolist()
        rows = rng.choice(poses, size=20)
        assert neighbourhoods.edges_of(rows).tolist() == np.flatnonzero(np.isin(seen, rows).any(axis=1)).tolist()
    assert rebuilt_with_a_tail


def _graph() -> PoseGraph:
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o")
    rng = np.random.default_rng(3)
    # Off the optimum, so that every gradient below is far from zero.
    poses = graph.poses + rng.normal(scale=[0.05, 0.05, 0.02], size=graph.poses.shape)
    return graph.with_poses(poses)


def _whole_system(graph: PoseGraph, T: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense `H` `(3N, 3N)` and `g` `(3N,)` of every pose, none fixed, from the per-edge products."""
    factors = BetweenFactors.from_graph(graph)
    products = edge_products(factors.linearize(T), factors.information, weights)
    d, n = 3, graph.num_poses
    H, g = np.zeros((n * d, n * d)), np.zeros(n * d)
    for e, (i, j) in enumerate(graph.edges):
        index = np.r_[i * d : (i + 1) * d, j * d : (j + 1) * d]
        H[np.ix_(index, index)] += products[e, :, : 2 * d]
        g[index] += products[e, :, 2 * d]
    return H, g


def test_the_local_problem_has_the_whole_graphs_gradient_and_hessian_at_its_free_poses():
    graph = _graph()
    T = to_matrices(2, graph.poses)
    factors = BetweenFactors.from_graph(graph)
    neighbourhoods = Neighbourhoods.of(graph.edges, graph.num_poses)
    region = neighbourhoods.within(np.array([100, 300]), 3)
    held = int(region[2])
    local = LocalProblem.build(region, neighbourhoods, factors, held, "scipy")
    assert np.isin(local.boundary, np.setdiff1d(local.rows, region)).sum() == len(local.boundary) - 1
    assert held in local.boundary and not np.isin(local.rows[local.free], held).any()
    assert np.array_equal(local.rows[local.free], np.setdiff1d(region, [held]))
    # Every edge with a free end is in it, and no other.
    free_rows = local.rows[local.free]
    expected = np.flatnonzero(np.isin(graph.edges, free_rows).any(axis=1) | np.isin(graph.edges, region).any(axis=1))
    assert local.edges.tolist() == expected.tolist()

    weights = np.linspace(0.2, 1.0, graph.num_edges)
    H, g = _whole_system(graph, T, weights)
    problem = local.problem
    lin = problem.factors.linearize(T[local.rows])
    data, gradient = problem.pattern.scatter(edge_products(lin, problem.factors.information, weights[local.edges]))
    pattern = problem.pattern
    H_local = np.zeros((pattern.size, pattern.size))
    for column in range(pattern.size):
        span = slice(pattern.indptr[column], pattern.indptr[column + 1])
        H_local[pattern.indices[span], column] = data[span]
    if pattern.lower_only:
        H_local = np.tril(H_local) + np.tril(H_local, -1).T
    # Unknown k of the local problem is free pose rows[free][...] in the pattern's block order.
    block_of_row = pattern.free_index[local.free]
    whole_index = (free_rows[:, None] * 3 + np.arange(3)).ravel()
    local_index = (block_of_row[:, None] * 3 + np.arange(3)).ravel()
    np.testing.assert_allclose(gradient[local_index], g[whole_index], rtol=1e-10, atol=1e-9)
    H_free = H[np.ix_(whole_index, whole_index)]
    np.testing.assert_allclose(H_local[np.ix_(local_index, local_index)], H_free, rtol=1e-10, atol=1e-7)


def test_block_jacobi_decrease_is_each_poses_own_newton_step():
    graph = _graph()
    T = to_matrices(2, graph.poses)
    factors = BetweenFactors.from_graph(graph)
    weights = np.linspace(0.2, 1.0, graph.num_edges)
    H, g = _whole_system(graph, T, weights)
    rows = np.array([0, 7, 250, 499])
    edges = Neighbourhoods.of(graph.edges, graph.num_poses).edges_of(rows)
    decrease = block_jacobi_decrease(factors, edges, T, weights[edges], rows)
    for k, row in enumerate(rows):
        block = slice(3 * row, 3 * row + 3)
        step = np.linalg.solve(H[block, block], g[block])
        assert decrease[k] == pytest.approx(0.5 * g[block] @ step, rel=1e-9)
        assert decrease[k] > 0.0
