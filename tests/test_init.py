"""`egnc.solve(init=...)` / `egnc-solve --init`: the file's guess, composed odometry, chordal."""

from __future__ import annotations

import numpy as np
import pytest

import egnc
from egnc.api import initial_guess
from egnc.datasets import grid_world


def test_odometry_init_ignores_the_file_poses_but_the_gauge():
    world = grid_world(2, 100, seed=3)
    graph = world.graph
    scrambled = graph.poses.copy()
    scrambled[1:] += 50.0  # garbage everywhere but the gauge pose 0
    from_scrambled = initial_guess(graph.with_poses(scrambled), "odometry", graph.is_odometry, "scipy")
    from_file = initial_guess(graph, "odometry", graph.is_odometry, "scipy")
    np.testing.assert_allclose(from_scrambled, from_file, atol=1e-12)
    # and it is the odometry chain: every odometry edge has zero residual
    no_steps = egnc.SolverOptions(max_iterations=0)
    result = egnc.solve(graph.with_poses(scrambled), "l2", init="odometry", options=no_steps)
    assert np.all(result.residual_norms[graph.is_odometry] < 1e-6)
    assert result.init == "odometry"


def test_chordal_init_finds_the_better_minimum_of_mit(dataset_path):
    graph = egnc.read_g2o(dataset_path("MIT.g2o"))
    from_file = egnc.solve(graph, "l2")
    from_chordal = egnc.solve(graph, "l2", init="chordal")
    assert from_chordal.cost < 0.1 * from_file.cost  # 20.6 against 385.1: another, far better minimum


def test_unknown_init_is_a_clear_error():
    graph = grid_world(2, 20, seed=1).graph
    with pytest.raises(egnc.EgncError, match="unknown init 'gps'"):
        egnc.solve(graph, init="gps")


def test_odometry_init_needs_connected_odometry():
    graph = grid_world(2, 50, seed=2).graph
    with pytest.raises(egnc.GraphError, match="init 'odometry'"):
        egnc.solve(graph, "l2", init="odometry", known_inliers=np.zeros(graph.num_edges, dtype=bool))
