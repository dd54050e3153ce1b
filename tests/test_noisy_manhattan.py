"""Noisy-Manhattan datasets: seeded reproducibility, labels, outlier test, noise statistics, IRL output."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

import egnc
from egnc.datasets import NoisyGraph, grid_world, make_noisy_manhattan
from egnc.datasets.noisy_manhattan import outlier_count
from egnc.errors import EgncError
from egnc.io import read_g2o, read_irl, write_irl
from egnc.nonlinear.factors import BetweenFactors, group_of, to_matrices

THRESHOLD = {2: chi2.ppf(0.95, 3), 3: chi2.ppf(0.95, 6)}


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def world(request):
    """An exact grid world per dimension: its measurements are its ground truth's."""
    return grid_world(request.param, 400 if request.param == 2 else 200, seed=5, noise_scale=0.0)


def squared_errors_at(graph, poses):
    """Squared whitened residual norms `(E,)` of every edge of `graph` at `poses` `(N, P)`."""
    factors = BetweenFactors.from_graph(graph)
    return factors.whitened_norms(factors.residuals(to_matrices(graph.dim, poses))) ** 2


def tangent_noise(noisy: NoisyGraph) -> np.ndarray:
    """`(E, d)` tangent vectors `n` with `Z = (X_i^-1 X_j) Exp(n)` at the ground truth."""
    graph, group = noisy.graph, group_of(noisy.graph.dim)
    T = to_matrices(graph.dim, noisy.ground_truth)
    T_i_j = group.between(T[graph.edges[:, 0]], T[graph.edges[:, 1]])
    return group.log(group.between(T_i_j, to_matrices(graph.dim, graph.measurements)))


def test_same_seed_gives_identical_data_and_files_another_seed_does_not(tmp_path, world):
    first = make_noisy_manhattan(world.graph, world.ground_truth, seed=3)
    again = make_noisy_manhattan(world.graph, world.ground_truth, seed=3)
    other = make_noisy_manhattan(world.graph, world.ground_truth, seed=4)
    for name in ("poses", "measurements"):
        assert np.array_equal(getattr(first.graph, name), getattr(again.graph, name))
    assert np.array_equal(first.is_outlier, again.is_outlier)
    assert not np.array_equal(first.graph.measurements, other.graph.measurements)
    assert not np.array_equal(first.is_outlier, other.is_outlier)
    for name, noisy in (("a", first), ("b", again)):
        write_irl(noisy.to_irl("noisy", date="2024-01-01"), tmp_path / f"{name}.irl")
    assert (tmp_path / "a.irl").read_bytes() == (tmp_path / "b.irl").read_bytes()


def test_labels_are_the_requested_share_of_the_loop_closures_perturbed_in_place(world):
    graph = world.graph
    noisy = make_noisy_manhattan(graph, world.ground_truth, seed=1)
    num_loops = int(np.count_nonzero(graph.is_loop_closure))
    assert np.count_nonzero(noisy.is_outlier) == outlier_count(num_loops, 0.3) == round(0.3 * num_loops)
    assert not np.any(noisy.is_outlier & graph.is_odometry)
    # Same edges, order, information and gauge as the source: only the measurements change.
    assert np.array_equal(noisy.graph.edges, graph.edges)
    assert np.array_equal(noisy.graph.information, graph.information)
    assert np.array_equal(noisy.graph.fixed, graph.fixed)
    for fraction, expected in ((0.0, 0), (1.0, num_loops)):
        none_or_all = make_noisy_manhattan(graph, world.ground_truth, seed=1, outlier_fraction=fraction)
        assert np.count_nonzero(none_or_all.is_outlier) == expected
    assert (outlier_count(10, 0.25), outlier_count(10, 0.35), outlier_count(733, 0.3)) == (3, 4, 220)


def test_every_outlier_fails_the_chi2_test_at_the_ground_truth_and_at_the_outlier_free_optimum(world):
    # A small perturbation makes many draws fall below the threshold, so the redraws are exercised.
    noisy = make_noisy_manhattan(world.graph, world.ground_truth, seed=2, outlier_sigma=(0.1, 0.03))
    graph, threshold = noisy.graph, THRESHOLD[world.graph.dim]
    inlier_loops = graph.is_loop_closure & ~noisy.is_outlier
    at_truth = squared_errors_at(graph, noisy.ground_truth)
    at_optimum = squared_errors_at(graph, noisy.reference)
    assert np.all(at_truth[noisy.is_outlier] > threshold) and np.all(at_optimum[noisy.is_outlier] > threshold)
    assert at_truth[noisy.is_outlier].min() < 2 * threshold  # the test, not the sigma, decided
    assert np.all(at_truth[inlier_loops] < 1e-12)  # loop_sigma 0: exact inlier loops
    # The reference is the least-squares optimum without the outliers.
    clean = graph.subgraph_edges(~noisy.is_outlier)
    assert np.abs(egnc.solve(clean, "l2").graph.poses - noisy.reference).max() < 1e-6


def test_a_larger_minimum_error_keeps_only_gross_outliers():
    world = grid_world(2, 400, seed=5, noise_scale=0.0)
    noisy = make_noisy_manhattan(world.graph, world.ground_truth, seed=2, outlier_min_r2=90.0)
    for poses in (noisy.ground_truth, noisy.reference):
        assert np.all(squared_errors_at(noisy.graph, poses)[noisy.is_outlier] > 90.0)


def test_odometry_and_loop_noise_have_the_configured_statistics():
    world = grid_world(2, 3000, seed=8, noise_scale=0.0)
    noisy = make_noisy_manhattan(world.graph, world.ground_truth, seed=9, loop_sigma=(0.02, 0.005))
    n = tangent_noise(noisy)
    odometry, inlier_loops = noisy.graph.is_odometry, noisy.graph.is_loop_closure & ~noisy.is_outlier
    for mask, sigma in ((odometry, [0.06, 0.06, 0.015]), (inlier_loops, [0.02, 0.02, 0.005])):
        assert np.count_nonzero(mask) > 500
        np.testing.assert_allclose(n[mask].std(axis=0), sigma, rtol=0.1)
        assert np.all(np.abs(n[mask].mean(axis=0)) < 4 * np.array(sigma) / np.sqrt(np.count_nonzero(mask)))
    # Per-component sigmas: the shipped case's x-and-theta-only odometry noise.
    only_x_theta = make_noisy_manhattan(world.graph, world.ground_truth, seed=9, odometry_sigma=(0.061, 0.0, 0.0152))
    n = tangent_noise(only_x_theta)[odometry]
    assert np.abs(n[:, 1]).max() < 1e-8
    np.testing.assert_allclose(n[:, [0, 2]].std(axis=0), [0.061, 0.0152], rtol=0.1)


def test_initial_guess_composes_the_noisy_odometry_from_the_true_first_pose(world):
    noisy = make_noisy_manhattan(world.graph, world.ground_truth, seed=6)
    graph, group = noisy.graph, group_of(world.graph.dim)
    T = to_matrices(graph.dim, graph.poses)
    np.testing.assert_allclose(T[0], to_matrices(graph.dim, world.ground_truth[:1])[0], atol=1e-9)
    odometry = graph.is_odometry
    composed = group.between(T[graph.edges[odometry, 0]], T[graph.edges[odometry, 1]])
    np.testing.assert_allclose(composed, to_matrices(graph.dim, graph.measurements[odometry]), atol=1e-6)


def test_irl_round_trip_keeps_the_labels_and_the_graph(tmp_path):
    world = grid_world(2, 300, seed=4, noise_scale=0.0)
    noisy = make_noisy_manhattan(world.graph, world.ground_truth, seed=7)
    write_irl(noisy.to_irl("noisy", date="2024-01-01", notes="seed 7"), tmp_path / "noisy.irl")
    log = read_irl(tmp_path / "noisy.irl")
    assert np.array_equal(log.is_outlier, noisy.is_outlier)
    assert np.array_equal(log.graph.measurements, noisy.graph.measurements)
    np.testing.assert_allclose(log.graph.poses, noisy.graph.poses, atol=1e-9)
    assert (log.name, log.notes) == ("noisy", "seed 7")


def test_manhattan3500(dataset_path):
    graph = read_g2o(dataset_path("manhattanOlson3500.g2o"))
    truth = egnc.solve(graph, "l2", linear_solver="scipy").graph.poses
    noisy = make_noisy_manhattan(graph, truth, seed=1)
    assert (np.count_nonzero(graph.is_loop_closure), np.count_nonzero(noisy.is_outlier)) == (2099, 630)
    at_optimum = squared_errors_at(noisy.graph, noisy.reference)
    assert np.all(at_optimum[noisy.is_outlier] > THRESHOLD[2])
    assert np.all(at_optimum[noisy.graph.is_loop_closure & ~noisy.is_outlier] < THRESHOLD[2])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"outlier_fraction": 1.5}, "outlier_fraction must lie in [0, 1]"),
        ({"odometry_sigma": (0.1, 0.1, 0.1, 0.1)}, "odometry_sigma must have 2 or 3 entries"),
        ({"loop_sigma": (-1.0, 0.0)}, "loop_sigma must be finite and non-negative"),
        ({"outlier_sigma": (0.0, 0.0)}, "outlier_sigma must have a positive entry"),
        ({"outlier_sigma": (1e-6, 1e-6)}, "outlier draws still pass as inliers"),
        ({"outlier_min_r2": -1.0}, "outlier_min_r2 must be finite and non-negative"),
    ],
)
def test_invalid_arguments_raise(change, message):
    world = grid_world(2, 60, seed=1, noise_scale=0.0)
    with pytest.raises(EgncError, match=message.replace("[", r"\[").replace("]", r"\]")):
        make_noisy_manhattan(world.graph, world.ground_truth, seed=1, **change)
    with pytest.raises(EgncError, match="ground_truth has shape"):
        make_noisy_manhattan(world.graph, world.ground_truth[:-1], seed=1)
