"""Synthetic datasets: grid worlds, false loop closures, label sidecars and the shipped files."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from egnc.datasets import (
    VARIANTS,
    add_false_loops,
    false_loop_count,
    grid_world,
    read_labels,
    write_labels,
)
from egnc.datasets.false_loops import FALSE_LOOP_COVARIANCE
from egnc.errors import EgncError
from egnc.io import read_g2o, write_g2o
from egnc.nonlinear.factors import BetweenFactors, to_matrices

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "datasets"
SIZES = {2: 200, 3: 120}


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def world(request):
    """A small grid world per dimension; its ground truth serves as the outlier-free reference."""
    return grid_world(request.param, SIZES[request.param], seed=7)


def squared_errors_at(graph, poses):
    """Squared whitened residual norms `(E,)` of every edge of `graph` at `poses` `(N, P)`."""
    factors = BetweenFactors.from_graph(graph)
    return factors.whitened_norms(factors.residuals(to_matrices(graph.dim, poses))) ** 2


def write_pair(directory: Path, dim: int, seed: int) -> list[bytes]:
    """Generate a world and its corrupted copy with `seed`, write them, return the files' bytes."""
    world = grid_world(dim, SIZES[dim], seed=seed)
    corrupted = add_false_loops(world.graph, 30, seed=seed, reference_poses=world.ground_truth)
    directory.mkdir()
    write_g2o(world.graph, directory / "clean.g2o")
    write_g2o(corrupted.graph, directory / "outliers.g2o")
    write_labels(directory / "outliers.labels.json", corrupted.is_outlier, {"seed": seed})
    return [(directory / name).read_bytes() for name in ("clean.g2o", "outliers.g2o", "outliers.labels.json")]


# --- grid_world -------------------------------------------------------------------------------


@pytest.mark.parametrize("dim", [2, 3])
def test_same_seed_gives_identical_files_and_another_seed_does_not(tmp_path, dim):
    first = write_pair(tmp_path / "a", dim, seed=11)
    again = write_pair(tmp_path / "b", dim, seed=11)
    other = write_pair(tmp_path / "c", dim, seed=12)
    assert first == again
    assert all(a != c for a, c in zip(first, other))


def test_noise_free_measurements_have_zero_residual_at_ground_truth(world):
    dim = world.graph.dim
    exact = grid_world(dim, SIZES[dim], seed=7, odometry_sigma=(0.0, 0.0), loop_sigma=(0.0, 0.0))
    T_true = to_matrices(dim, exact.ground_truth)
    residuals = BetweenFactors.from_graph(exact.graph).residuals(T_true)
    # Only the rounding to 9 decimals remains.
    np.testing.assert_allclose(residuals, 0.0, atol=1e-8)
    # Chaining exact odometry reproduces the ground truth (compare matrices: angles may wrap).
    np.testing.assert_allclose(to_matrices(dim, exact.graph.poses), T_true, atol=1e-7)
    # The walk itself does not depend on the noise.
    np.testing.assert_array_equal(exact.graph.edges, world.graph.edges)


def test_noisy_measurements_are_consistent_with_their_information(world):
    # At the ground truth the squared whitened residuals are chi-square distributed with d dofs.
    squared = squared_errors_at(world.graph, world.ground_truth)
    assert abs(squared.mean() / world.graph.tangent_dim - 1.0) < 0.2


def test_walk_structure(world):
    graph, truth = world.graph, world.ground_truth
    dim, n = graph.dim, graph.num_poses
    is_loop = graph.is_loop_closure
    np.testing.assert_array_equal(graph.edges[~is_loop], np.column_stack((np.arange(n - 1), np.arange(1, n))))
    loops = graph.edges[is_loop]
    assert len(loops) > 0.2 * n
    # A loop closure joins a revisit to the latest earlier visit of the same cell, at most once per pose.
    np.testing.assert_allclose(truth[loops[:, 0], :dim], truth[loops[:, 1], :dim])
    assert np.all(loops[:, 1] - loops[:, 0] >= 2)
    assert len(np.unique(loops[:, 1])) == len(loops)
    for a, b in loops.tolist():
        between = np.all(truth[a + 1 : b, :dim] == truth[b, :dim], axis=1)
        assert not between.any()
    # Time order: each loop closure follows the odometry edge that reaches its newer pose.
    assert np.all(np.diff(graph.edges.max(axis=1)) >= 0)
    # Unit steps between consecutive poses, on the grid.
    steps = np.linalg.norm(np.diff(truth[:, :dim], axis=0), axis=1)
    np.testing.assert_allclose(steps, 1.0)
    np.testing.assert_array_equal(truth[:, :dim], np.round(truth[:, :dim]))
    np.testing.assert_array_equal(graph.poses[0], truth[0])


def test_grid_world_stays_in_its_square_and_climbs_in_3d():
    world = grid_world(3, 400, seed=5, size=6, levels=3)
    extent = np.ptp(world.ground_truth[:, :3], axis=0)
    np.testing.assert_array_equal(extent, [5.0, 5.0, 2.0])
    np.testing.assert_allclose(np.linalg.norm(world.ground_truth[:, 3:], axis=1), 1.0)


def test_grid_world_options():
    world = grid_world(2, 300, seed=1, step=2.5, loop_probability=0.0, odometry_sigma=(0.1, 0.2, 0.3))
    assert not world.graph.is_loop_closure.any()
    np.testing.assert_allclose(np.diag(world.graph.information[0]), [100.0, 25.0, 1.0 / 0.09])
    np.testing.assert_allclose(np.linalg.norm(np.diff(world.ground_truth[:, :2], axis=0), axis=1), 2.5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"dim": 4, "num_poses": 10},
        {"dim": 2, "num_poses": 1},
        {"dim": 2, "num_poses": 10, "step": 0.0},
        {"dim": 2, "num_poses": 10, "loop_probability": 1.5},
        {"dim": 2, "num_poses": 10, "odometry_sigma": (0.1, 0.1, 0.1, 0.1)},
        {"dim": 3, "num_poses": 10, "loop_sigma": (-0.1, 0.1)},
        {"dim": 2, "num_poses": 10, "size": 1},
        {"dim": 3, "num_poses": 10, "levels": 1},
    ],
)
def test_grid_world_rejects_bad_arguments(kwargs):
    with pytest.raises(EgncError):
        grid_world(seed=0, **kwargs)


# --- add_false_loops ----------------------------------------------------------------------------


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("percent", [0, 10, 30, 50])
def test_false_loops_follow_the_protocol(world, variant, percent):
    graph, reference = world.graph, world.ground_truth
    corrupted = add_false_loops(
        graph, percent, seed=3, reference_poses=reference, variant=variant, close_radius=5.0
    )
    num_loops = int(graph.is_loop_closure.sum())
    expected = int(np.floor(percent * num_loops / (100 - percent) + 0.5))
    assert false_loop_count(num_loops, percent) == expected
    assert corrupted.is_outlier.sum() == expected
    assert corrupted.graph.num_edges == graph.num_edges + expected

    # The original edges survive unchanged and in order.
    inliers = ~corrupted.is_outlier
    np.testing.assert_array_equal(corrupted.source_edges[inliers], np.arange(graph.num_edges))
    np.testing.assert_array_equal(corrupted.source_edges[corrupted.is_outlier], -1)
    np.testing.assert_array_equal(corrupted.graph.edges[inliers], graph.edges)
    np.testing.assert_array_equal(corrupted.graph.measurements[inliers], graph.measurements)
    np.testing.assert_array_equal(corrupted.graph.poses, graph.poses)

    # Every false loop: a loop closure, identity, riSAM's covariance, and a chi-square outlier.
    false = corrupted.graph.edges[corrupted.is_outlier]
    assert np.all(np.abs(false[:, 0] - false[:, 1]) >= 2)
    assert not corrupted.graph.is_odometry[corrupted.is_outlier].any()
    identity = np.zeros(graph.poses.shape[1])
    identity[-1] = 1.0 if graph.dim == 3 else 0.0
    information = np.linalg.inv(np.diag(FALSE_LOOP_COVARIANCE[graph.dim]))
    outlier = corrupted.is_outlier
    np.testing.assert_array_equal(corrupted.graph.measurements[outlier], np.tile(identity, (expected, 1)))
    np.testing.assert_allclose(corrupted.graph.information[outlier], np.tile(information, (expected, 1, 1)))
    squared = squared_errors_at(corrupted.graph, reference)[corrupted.is_outlier]
    assert np.all(squared > chi2.ppf(0.95, graph.tangent_dim))

    # No false loop repeats the pair of another edge, true or false.
    assert not corrupted.graph.is_duplicate.any()

    # Interleaved in time order, not appended where their position would give them away.
    assert np.all(np.diff(corrupted.graph.edges.max(axis=1)) >= 0)

    dim = graph.dim
    if variant == "close":
        distance = np.linalg.norm(reference[false[:, 0], :dim] - reference[false[:, 1], :dim], axis=1)
        assert np.all(distance <= 5.0)


def test_the_distance_rule_keeps_only_errors_past_the_quantile_itself(world):
    graph, reference = world.graph, world.ground_truth.copy()
    # A shrunken map with one heading: many candidates' errors lie near the quantile.
    reference[:, : graph.dim] *= 0.2
    reference[:, graph.dim :] = 0.0
    reference[:, -1] = 1.0 if graph.dim == 3 else 0.0
    quantile = chi2.ppf(0.95, graph.tangent_dim)
    squared_rule = add_false_loops(graph, 30, seed=3, reference_poses=reference)
    distance_rule = add_false_loops(graph, 30, seed=3, reference_poses=reference, outlier_rule="distance")
    squared = squared_errors_at(squared_rule.graph, reference)[squared_rule.is_outlier]
    distance = squared_errors_at(distance_rule.graph, reference)[distance_rule.is_outlier]
    assert distance_rule.is_outlier.sum() == squared_rule.is_outlier.sum()
    assert np.all(np.sqrt(distance) > quantile) and np.all(squared > quantile)
    assert np.any(np.sqrt(squared) <= quantile)  # the squared rule keeps some the distance rule refuses
    with pytest.raises(EgncError, match="outlier_rule"):
        add_false_loops(graph, 30, seed=3, reference_poses=reference, outlier_rule="r")  # type: ignore[arg-type]


@pytest.mark.parametrize("variant", ["group", "mixed"])
def test_false_loops_come_in_consecutive_groups(world, variant):
    corrupted = add_false_loops(
        world.graph, 40, seed=9, reference_poses=world.ground_truth, variant=variant, group_size=4
    )
    false = corrupted.graph.edges[corrupted.is_outlier]
    pairs = {tuple(pair) for pair in false.tolist()}
    # Each false loop (a, b) has its group mates (a - 1, b - 1) or (a + 1, b + 1), except singles.
    grouped = [(a - 1, b - 1) in pairs or (a + 1, b + 1) in pairs for a, b in pairs]
    count = len(false)
    in_groups = count if variant == "group" else count // 2
    # Only the last group may be cut short to hit the exact count, possibly down to one member.
    cut_to_one = int(in_groups % 4 == 1)
    assert sum(grouped) >= in_groups - cut_to_one
    if variant == "mixed":
        assert sum(grouped) < count


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("variant", VARIANTS)
def test_false_loops_never_duplicate_an_edge_even_when_pairs_are_scarce(dim, variant):
    # 40 poses, 70 % false: before the rule, seed 3 drew a repeated pair in both dimensions.
    small = grid_world(dim, 40, seed=7)
    assert not small.graph.is_duplicate.any()
    for seed in range(5):
        corrupted = add_false_loops(
            small.graph, 70, seed=seed, reference_poses=small.ground_truth, variant=variant, close_radius=5.0
        )
        assert corrupted.is_outlier.sum() == false_loop_count(int(small.graph.is_loop_closure.sum()), 70)
        assert not corrupted.graph.is_duplicate.any(), (variant, seed)


def test_false_loops_are_reproducible_and_seed_dependent(world):
    first, again, other = (
        add_false_loops(world.graph, 30, seed=seed, reference_poses=world.ground_truth) for seed in (1, 1, 2)
    )
    np.testing.assert_array_equal(first.graph.edges, again.graph.edges)
    np.testing.assert_array_equal(first.is_outlier, again.is_outlier)
    assert not np.array_equal(first.graph.edges, other.graph.edges)


def test_false_loops_reject_bad_input(world):
    graph, reference = world.graph, world.ground_truth
    for percent in (-1, 100, 150):
        with pytest.raises(EgncError, match="percent"):
            add_false_loops(graph, percent, seed=0, reference_poses=reference)
    no_loops = graph.subgraph_edges(graph.is_odometry)
    with pytest.raises(EgncError, match="no loop closures"):
        add_false_loops(no_loops, 10, seed=0, reference_poses=reference)
    with pytest.raises(EgncError, match="variant"):
        add_false_loops(graph, 10, seed=0, reference_poses=reference, variant="nearby")
    with pytest.raises(EgncError, match="reference_poses"):
        add_false_loops(graph, 10, seed=0, reference_poses=reference[:-1])
    # With every reference pose equal no identity measurement is an outlier: the search gives up.
    collapsed = np.broadcast_to(reference[0], reference.shape)
    with pytest.raises(EgncError, match="placed only 0 of"):
        add_false_loops(graph, 10, seed=0, reference_poses=collapsed)


# --- labels -----------------------------------------------------------------------------------


def test_labels_round_trip_and_match_the_written_graph(tmp_path, world):
    corrupted = add_false_loops(world.graph, 30, seed=4, reference_poses=world.ground_truth)
    write_g2o(corrupted.graph, tmp_path / "g.g2o")
    meta = {"percent": 30, "seed": 4, "nested": {"variant": "random"}}
    write_labels(tmp_path / "g.labels.json", corrupted.is_outlier, meta)

    is_outlier, read_meta = read_labels(tmp_path / "g.labels.json")
    np.testing.assert_array_equal(is_outlier, corrupted.is_outlier)
    assert read_meta == meta
    raw = json.loads((tmp_path / "g.labels.json").read_text())
    assert raw["format"] == "egnc-labels-1"
    assert raw["num_edges"] == corrupted.graph.num_edges

    # The labels index the edges as read back from the file.
    graph = read_g2o(tmp_path / "g.g2o")
    assert graph.num_edges == len(is_outlier)
    np.testing.assert_array_equal(graph.edges, corrupted.graph.edges)
    np.testing.assert_array_equal(graph.edges[~is_outlier], world.graph.edges)
    # The g2o file carries no labels and no trace of the generator.
    text = (tmp_path / "g.g2o").read_text()
    assert "OUTLIER" not in text.upper() and "#" not in text


def test_labels_reject_bad_files(tmp_path):
    path = tmp_path / "labels.json"
    with pytest.raises(EgncError, match="cannot read"):
        read_labels(path)
    for content in (
        "not json",
        '{"format": "other", "num_edges": 3, "outlier_edges": []}',
        '{"format": "egnc-labels-1", "num_edges": 3, "outlier_edges": [3]}',
        '{"format": "egnc-labels-1", "num_edges": 3, "outlier_edges": [1, 1]}',
        '{"format": "egnc-labels-1", "num_edges": -1, "outlier_edges": []}',
        '{"format": "egnc-labels-1", "num_edges": 3, "outlier_edges": [true]}',
    ):
        path.write_text(content)
        with pytest.raises(EgncError, match=str(path)):
            read_labels(path)
    with pytest.raises(EgncError, match="reserved"):
        write_labels(path, np.zeros(3, dtype=bool), {"num_edges": 4})
    with pytest.raises(EgncError, match="bool"):
        write_labels(path, np.zeros(3, dtype=int))


# --- shipped files ------------------------------------------------------------------------------


def test_shipped_datasets_are_what_generate_py_writes(tmp_path):
    subprocess.run(
        [sys.executable, str(SHIPPED / "generate.py"), "--out", str(tmp_path)], check=True, capture_output=True
    )
    generated = sorted(path.name for path in tmp_path.iterdir())
    shipped = sorted(path.name for path in SHIPPED.iterdir() if path.name not in ("generate.py", "README.md"))
    assert generated == shipped
    for name in generated:
        assert (tmp_path / name).read_bytes() == (SHIPPED / name).read_bytes(), name
        assert (SHIPPED / name).stat().st_size < 300_000, name


def test_shipped_labels_describe_the_shipped_graphs():
    for name in ("grid2d", "grid3d"):
        clean = read_g2o(SHIPPED / f"{name}.g2o")
        corrupted = read_g2o(SHIPPED / f"{name}_outliers.g2o")
        is_outlier, meta = read_labels(SHIPPED / f"{name}_outliers.labels.json")
        assert meta["graph"] == f"{name}_outliers.g2o"
        assert len(is_outlier) == corrupted.num_edges
        np.testing.assert_array_equal(corrupted.edges[~is_outlier], clean.edges)
        num_loops = int(clean.is_loop_closure.sum())
        assert is_outlier.sum() == false_loop_count(num_loops, meta["percent"])


@pytest.mark.parametrize("name", ["grid2d", "grid3d", "grid2d_outliers", "grid3d_outliers"])
def test_shipped_graphs_read_without_any_warning(name):
    # The README's first command solves one: a warning about the project's own data reads as a fault.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        graph = read_g2o(SHIPPED / f"{name}.g2o")
    assert not graph.is_duplicate.any()  # egnc-solve would warn about duplicate edges


def test_readme_first_command_prints_no_warning(tmp_path):
    command = ["-m", "egnc.cli.solve", str(SHIPPED / "grid2d_outliers.g2o"), "-o", str(tmp_path / "solved.g2o")]
    run = subprocess.run(
        [sys.executable, *command],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert [line for line in run.stderr.splitlines() if line.startswith("warning")] == []
