"""The chordal start: a drifted guess no longer decides the result, and false loops never bend it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import egnc
from egnc.api import marginal_covariances, solve
from egnc.cli.report import summary
from egnc.datasets import add_false_loops, grid_world
from egnc.decision import truncated_cost
from egnc.diagnostics import solve_warnings
from egnc.factors import to_matrices
from egnc.gnc import GncOptions
from egnc.graph import PoseGraph
from egnc.initialize import initialize_poses
from egnc.kernels import chi2_quantile
from egnc.least_squares import Problem
from egnc.marginals import pose_covariances

GUESS_ONLY = GncOptions(chordal_start=False, regroup_start=False, elimination_start=False)
"""The default before the chordal start: decide from the GNC solve of the initial guess alone."""


def drifted_guess(graph: PoseGraph, seed: int, heading_sigma: float) -> PoseGraph:
    """`graph` with its guess re-chained from odometry whose headings got `N(0, heading_sigma)` rad per step."""
    rng = np.random.default_rng(seed)
    odometry = graph.is_odometry
    measurements = graph.measurements[odometry].copy()
    measurements[:, 2] += rng.normal(0.0, heading_sigma, size=len(measurements))
    known = np.arange(graph.num_poses) == 0
    return graph.with_poses(initialize_poses(2, graph.edges[odometry], measurements, poses=graph.poses, known=known))


def test_truncated_cost_caps_each_loop_at_the_threshold():
    r = np.array([1.0, 2.0, 10.0, 10.0])
    robust = np.array([False, True, True, False])
    q = chi2_quantile(0.99, 3)
    assert truncated_cost(r, robust, 3, 0.99) == pytest.approx(0.5 * (1.0 + 4.0 + q + 100.0))


def test_a_drifted_guess_no_longer_decides_the_result():
    graph = drifted_guess(grid_world(2, 1000, seed=1).graph, seed=2, heading_sigma=0.5)
    guess_only = solve(graph, gnc_options=GUESS_ONLY)
    result = solve(graph)
    least_squares = solve(graph, "l2", init="chordal")
    assert result.start == "chordal" and "chordal initialization" in result.message
    assert len(result.rejected_edges) < len(guess_only.rejected_edges)
    assert result.truncated_cost < guess_only.truncated_cost
    # what it rejects fails the outlier test at the least-squares optimum of every edge too
    q = chi2_quantile(0.99, 3)
    assert np.all(least_squares.residual_norms[result.rejected_edges] ** 2 > q)


def test_false_loops_keep_the_decision_of_the_guess():
    world = grid_world(2, 300, seed=3, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 30, seed=4, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
    assert result.start == "guess"
    # the chordal start ran (its map fits other loops) but was not adopted
    assert [stage.kind for stage in result.stages].count("probe") == 1
    guess_only = solve(corrupted.graph, gnc_options=GUESS_ONLY)
    np.testing.assert_array_equal(result.graph.poses, guess_only.graph.poses)


def test_least_squares_rejects_nothing_and_its_covariances_use_every_edge():
    world = grid_world(2, 200, seed=6, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 30, seed=7, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph, "l2")
    assert result.inliers.all() and len(result.rejected_edges) == 0
    ids = result.graph.vertex_ids[[5, 150]]
    rows = np.searchsorted(result.graph.vertex_ids, ids)
    problem = Problem.from_graph(result.graph, result.linear_solver)
    expected = pose_covariances(problem, to_matrices(2, result.graph.poses), rows)
    np.testing.assert_allclose(marginal_covariances(result, ids), expected, rtol=1e-10)


def test_manhattan_with_a_noisy_heading_keeps_every_loop(dataset_path):
    # The guess-only default folded this map and rejected true loops; the least-squares optimum
    # from the chordal guess keeps them all.
    graph = drifted_guess(egnc.read_g2o(dataset_path("manhattanOlson3500.g2o")), seed=1, heading_sigma=0.3)
    result = solve(graph)
    assert len(result.rejected_edges) == 0 and result.start == "chordal"
    assert result.cost == pytest.approx(solve(graph, "l2", init="chordal").cost, rel=1e-6)
    assert len(solve(graph, gnc_options=GUESS_ONLY).rejected_edges) > 0


def test_loops_the_two_starts_dispute_and_an_unsettled_decision_are_warnings():
    graph = grid_world(2, 200, seed=6).graph
    result = solve(graph)
    r = result.residual_norms
    robust = ~result.known_inliers
    disputed = np.zeros(graph.num_edges, dtype=bool)
    disputed[np.flatnonzero(robust)[[3, 7]]] = True
    fits = np.ones(graph.num_edges, dtype=bool)
    quiet = solve_warnings(graph, result.stages, robust, result.inliers, r, r, fits, result.graph.poses)
    warned = solve_warnings(
        graph, result.stages, robust, result.inliers, r, r, fits, result.graph.poses, settled=False, disputed=disputed
    )
    assert quiet == ()
    assert any("did not settle" in warning for warning in warned)
    edges = ", ".join(str(k) for k in np.flatnonzero(disputed))
    assert any(f"2 rejected loop closures (edges {edges})" in warning for warning in warned)


def test_the_summary_never_says_converged_alone_when_there_are_warnings():
    graph = grid_world(2, 200, seed=6).graph
    result = solve(graph)
    assert result.warnings == () and "read them" not in summary(result, [])
    warned = dataclasses.replace(result, warnings=("something to check",))
    assert "converged" in warned.message and "warnings: 1, read them" in summary(warned, [])
