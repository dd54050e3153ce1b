"""The elimination start: false loops that least squares fits on a weak map are found and rejected."""

from __future__ import annotations

import numpy as np
import pytest

from egnc.api import solve
from egnc.bench.cases import solve_reference
from egnc.datasets import add_false_loops, grid_world
from egnc.io import read_g2o
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.marginals import innovations, relative_covariances
from egnc.robust.elimination import STEP_BUDGET, deletion_statistics
from egnc.robust.gnc import GncOptions

WITHOUT_ELIMINATION = GncOptions(starts=("runs", "chordal", "chordal-all", "regrouped"))
"""The default before the elimination start."""


def test_relative_covariances_are_the_maps_share_of_the_innovation_covariance():
    graph = grid_world(2, 60, seed=2, noise_scale=0.5).graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[:4]] = True
    kept = graph.subgraph_edges(~left_out)
    problem = Problem.from_graph(kept, "scipy")
    poses = to_matrices(2, solve(kept, "l2").graph.poses)
    loops = BetweenFactors.from_graph(graph).subset(np.flatnonzero(left_out))
    _, S = innovations(problem, poses, loops)
    d = 3
    blocks = np.stack([S[k * d : (k + 1) * d, k * d : (k + 1) * d] for k in range(4)])
    np.testing.assert_allclose(
        relative_covariances(problem, poses, loops), blocks - np.linalg.inv(loops.information), rtol=1e-8, atol=1e-14
    )


def test_deletion_statistic_is_the_innovation_against_the_map_without_the_loop():
    # Low noise keeps the model nearly linear, where the two are equal.
    graph = grid_world(2, 80, seed=4, noise_scale=0.05).graph
    factors = BetweenFactors.from_graph(graph)
    poses = to_matrices(2, solve(graph, "l2").graph.poses)
    problem = Problem.from_graph(graph, "scipy")
    loops = np.flatnonzero(graph.is_loop_closure)[:5]
    statistics = deletion_statistics(problem, poses, factors.subset(loops))
    for k, edge in enumerate(loops):
        keep = np.ones(graph.num_edges, dtype=bool)
        keep[edge] = False
        without = graph.subgraph_edges(keep)
        without_poses = to_matrices(2, solve(without, "l2").graph.poses)
        e, S = innovations(Problem.from_graph(without, "scipy"), without_poses, factors.subset(np.array([edge])))
        expected = float(e[0] @ np.linalg.solve(S, e[0]))
        assert statistics[k] == pytest.approx(expected, rel=1e-3)
        assert statistics[k] >= factors.whitened_norms(factors.residuals(poses))[edge] ** 2


def test_an_edge_nothing_else_constrains_cannot_be_contradicted():
    # With every edge of a tree robust, each one is a bridge: no statistic, 0.
    graph = grid_world(2, 30, seed=1, loop_probability=0.0).graph
    factors = BetweenFactors.from_graph(graph)
    poses = to_matrices(2, graph.poses)
    problem = Problem.from_graph(graph, "scipy")
    statistics = deletion_statistics(problem, poses, factors)
    np.testing.assert_array_equal(statistics, 0.0)


@pytest.mark.parametrize(("percent", "seed"), [(10, 0), (10, 3), (30, 3)])
def test_mit_keeps_its_honest_loops_with_false_loops_added(dataset_path, percent, seed):
    # MIT's map is weak: least squares fits the false loops, and the robust stage from the
    # file's poor guess lets 13 of the 20 honest loops go.
    graph = read_g2o(dataset_path("MIT.g2o"))
    corrupted = add_false_loops(graph, percent, seed=seed, reference_poses=solve_reference(graph, "auto"))
    before = solve(corrupted.graph, gnc_options=WITHOUT_ELIMINATION)
    result = solve(corrupted.graph)
    assert np.count_nonzero(~before.inliers & ~corrupted.is_outlier) >= 10
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
    assert result.start == "elimination" and "backward elimination" in result.message
    assert result.truncated_cost < before.truncated_cost


def test_the_start_is_skipped_where_it_would_cost_too_much():
    graph = grid_world(2, 2000, seed=1).graph
    reference = solve(graph, "l2").graph.poses
    corrupted = add_false_loops(graph, 30, seed=1, reference_poses=reference)
    result = solve(corrupted.graph)
    assert np.count_nonzero(corrupted.graph.is_loop_closure) > STEP_BUDGET // 10  # far past the budget
    assert all(stage.start != "elimination" for stage in result.stages)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_a_clean_weak_map_is_left_as_least_squares_leaves_it(dataset_path):
    graph = read_g2o(dataset_path("MIT.g2o"))
    result = solve(graph)
    assert len(result.rejected_edges) == 0
    assert result.cost <= solve(graph, "l2", init="chordal").cost * (1 + 1e-6)
