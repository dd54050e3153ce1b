"""Measurement priors in the online solver: GNSS fixes and pose priors arriving at any time,
candidates graduated like new loops or known inliers, the gauge they free, checkpoints and replays."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.datasets import add_false_loops, add_multipath_outliers, add_position_priors, grid_world
from egnc.errors import GraphError, OptionError
from egnc.io.checkpoint import content_digest
from egnc.metrics import ate, precision_recall
from egnc.nonlinear.factors import from_matrices, to_matrices
from egnc.online import OnlineSolver
from egnc.online.replay import replay

DATA = Path(__file__).parents[1] / "datasets"


def world(dim: int, num_poses: int = 120, seed: int = 5):
    """A grid world, its least-squares optimum moved far from the origin (the fixes' frame), and
    the same graph with a position prior every 10th pose (sigma 1 m) around that optimum."""
    generated = grid_world(dim, num_poses, seed=seed)
    optimum = to_matrices(dim, egnc.solve(generated.graph, "l2").graph.poses)
    motion = np.eye(dim + 1)
    motion[:dim, dim] = 300.0
    motion[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]  # a quarter turn: the odometry's frame is not the world's
    optimum = from_matrices(dim, motion @ optimum)
    return generated.graph, optimum, add_position_priors(generated.graph, optimum, every=10, sigma=1.0, seed=seed)


def corrupted(num_poses: int, bursts: bool):
    """`world(2, num_poses)` with 10 % false loops, then its fixes, 20 % of them moved by multipath
    jumps (bursts of 2-3 fixes with `bursts`): the graph, its optimum, and the labels."""
    graph, optimum, _ = world(2, num_poses)
    false = add_false_loops(graph, 10, seed=2, reference_poses=optimum)
    fixes = add_position_priors(false.graph, optimum, every=10, sigma=1.0, seed=5)
    moved = add_multipath_outliers(fixes, 20, seed=4, bursts=bursts, burst_size=(2, 3), reference_poses=optimum)
    return moved.graph, optimum, false.is_outlier, moved.is_outlier


def fed(graph, fixes=None, known_inliers="odometry", until=None, **kwargs) -> OnlineSolver:
    """An online solver given `graph`'s poses before row `until` (default: all), one update each
    (`feed`)."""
    solver = OnlineSolver(graph.dim, known_inliers=known_inliers, **kwargs)
    solver.add_pose(int(graph.vertex_ids[0]))
    feed(solver, graph, fixes, range(1, graph.num_poses if until is None else until))
    return solver


def feed(solver: OnlineSolver, graph, fixes, rows) -> None:
    """One update per pose row of `rows`: `graph`'s edges that reach it (odometry, then loops),
    then the fixes of `fixes` (a graph with priors, or None) on it (and on row 0 with row 1)."""
    fixes_at = {} if fixes is None else {int(row): k for k, row in enumerate(fixes.priors.rows)}
    later = graph.edges.max(axis=1)
    for row in rows:
        for e in np.flatnonzero(later == row):
            i, j = graph.vertex_ids[graph.edges[e]].tolist()
            add = solver.add_odometry if graph.is_odometry[e] else solver.add_loop
            add(i, j, graph.measurements[e], graph.information[e])
        for at in (0, row) if row == 1 else (row,):
            if at in fixes_at:
                k, dim = fixes_at[at], graph.dim
                position, information = fixes.priors.measurements[k, :dim], fixes.priors.information[k, :dim, :dim]
                solver.add_position_prior(at, position, information)
        solver.update()


@pytest.mark.parametrize("dim", [2, 3])
def test_a_fix_arriving_later_pulls_the_map_onto_the_fixes(dim):
    graph, optimum, fixes = world(dim)
    solver = fed(graph)  # odometry and loops only: the map sits in the odometry's frame
    before, rejected = solver.poses, solver.rejected
    assert ate(before, optimum, dim, align=False) > 100.0
    for k, row in enumerate(fixes.priors.rows.tolist()):
        solver.add_position_prior(row, fixes.priors.measurements[k, :dim], fixes.priors.information[k, :dim, :dim])
    report = solver.update()
    assert report.new_priors.tolist() == list(range(fixes.num_priors)) and report.whole_map
    after = solver.poses
    # Moved onto the fixes and freed: in their frame, within a few fix sigmas of the optimum.
    assert ate(after, optimum, dim, align=False) < 1.0
    assert not np.allclose(after[0], before[0])
    assert solver.rejected_priors.shape == (0,)
    np.testing.assert_array_equal(solver.rejected, rejected)  # the loops' decision is the map's shape's
    result = solver.result()
    assert result.rejected_priors.shape == (0,) and result.prior_inliers.all()


def test_the_first_pose_is_held_until_the_fixes_pin_the_map():
    graph, optimum, fixes = world(2)
    solver = fed(graph, until=11)
    held = solver.poses[0].copy()
    solver.add_position_prior(0, fixes.priors.measurements[0, :2], np.eye(2))
    solver.update()
    # One fix leaves the heading free: the map is moved onto it (a translation) and its first pose held.
    np.testing.assert_allclose(solver.poses[0, :2], fixes.priors.measurements[0, :2], atol=1e-9)
    np.testing.assert_allclose(solver.poses[0, 2], held[2], atol=1e-12)
    solver.add_position_prior(10, fixes.priors.measurements[1, :2], np.eye(2))
    solver.update()
    # Two fixes pin it in 2D: the heading now follows them.
    assert abs(solver.poses[0, 2] - optimum[0, 2]) < 0.5 < abs(held[2] - optimum[0, 2])


@pytest.mark.parametrize("dim", [2, 3])
def test_clean_fixes_reject_nothing_and_the_result_is_the_batch_least_squares_optimum(dim):
    graph, _, fixes = world(dim)
    solver = fed(graph, fixes)
    assert solver.num_priors == fixes.num_priors
    result = solver.result()
    assert result.rejected_edges.shape == (0,) and result.rejected_priors.shape == (0,)
    assert result.prior_inliers is not None and result.prior_inliers.all()
    plain = egnc.solve(fixes, "l2")
    np.testing.assert_allclose(result.graph.poses, plain.graph.poses, atol=1e-5)
    assert result.cost == pytest.approx(plain.cost, rel=1e-6)


@pytest.mark.parametrize("bursts", [False, True])
def test_multipath_jumps_are_rejected_and_reported_apart_from_the_loops(bursts):
    graph, optimum, false_loops, false_priors = corrupted(200, bursts)
    solver = fed(graph, graph)
    # Right now and in the batch decision: the jumped fixes out, the false loops out, apart.
    np.testing.assert_array_equal(solver.rejected_priors, np.flatnonzero(false_priors))
    np.testing.assert_array_equal(solver.rejected, np.flatnonzero(false_loops))
    result = solver.result()
    np.testing.assert_array_equal(result.prior_inliers, ~false_priors)
    np.testing.assert_array_equal(result.rejected_edges, np.flatnonzero(false_loops))
    assert len(result.rejected_priors) == false_priors.sum()
    assert ate(result.graph.poses, optimum, 2, align=False) < 1.0


def test_known_inlier_priors_are_never_rejected():
    graph, optimum, fixes = world(2)
    moved = add_multipath_outliers(fixes, 20, seed=4, reference_poses=optimum)
    solver = fed(graph, moved.graph, known_inliers="odometry,priors")
    assert not solver.prior_candidates.any()
    assert solver.prior_inliers.all() and solver.rejected_priors.shape == (0,)
    assert solver.prior_residual_norms[moved.is_outlier].min() > 5.0  # they are far off, and kept
    result = solver.result()
    assert result.prior_inliers is None and result.rejected_priors.shape == (0,)
    # Held quadratic, they bend the map: the batch least squares of the same factors.
    plain = egnc.solve(moved.graph, "l2")
    np.testing.assert_allclose(result.graph.poses, plain.graph.poses, atol=1e-4)
    # Per call, a prior's role may differ from the solver's default.
    candidate = solver.add_position_prior(10, optimum[10, :2] + 40.0, np.eye(2), known_inlier=False)
    solver.update()
    assert solver.rejected_priors.tolist() == [candidate]


def test_a_jumped_pose_prior_is_tested_at_its_own_dimension():
    graph, optimum, fixes = world(2)
    solver = fed(graph, fixes)
    wrong = optimum[60].copy()
    wrong[:2] += 30.0
    k = solver.add_pose_prior(60, wrong, np.diag([1.0, 1.0, 100.0]))
    report = solver.update()
    assert report.graduated >= 1 and report.mu_history.shape[1] == 1
    assert solver.rejected_priors.tolist() == [k]
    assert solver.result().rejected_priors.tolist() == [graph.num_edges + k]


def test_prior_calls_refuse_what_they_cannot_take():
    solver = OnlineSolver(2)
    solver.add_pose(0, [0.0, 0.0, 0.0])
    with pytest.raises(GraphError, match="prior on pose 5: the pose is not known"):
        solver.add_position_prior(5, [1.0, 2.0], np.eye(2))
    with pytest.raises(GraphError, match=r"prior information has shape \(1, 3, 3\), expected \(1, 2, 2\)"):
        solver.add_position_prior(0, [1.0, 2.0], np.eye(3))
    with pytest.raises(GraphError, match="positive definite"):
        solver.add_pose_prior(0, [0.0, 0.0, 0.0], -np.eye(3))
    with pytest.raises(GraphError, match="NaN"):
        solver.add_position_prior(0, [np.nan, 0.0], np.eye(2))
    with pytest.raises(OptionError, match="unknown prior kind"):
        solver.add_priors("gnss", [0], [[0.0, 0.0]], [np.eye(2)])
    with pytest.raises(OptionError, match="loop closures are candidates"):
        OnlineSolver(2, known_inliers="odometry,loops")
    with pytest.raises(OptionError, match="must name kinds"):
        OnlineSolver(2, known_inliers=np.ones(3, dtype=bool))
    assert solver.add_priors("position", [], np.zeros((0, 2)), np.zeros((0, 2, 2))).shape == (0,)
    assert solver.num_priors == 0


def test_checkpoints_keep_the_priors_and_resume_to_the_same_map(tmp_path):
    graph, optimum, fixes = world(2, 160)
    moved = add_multipath_outliers(fixes, 20, seed=4, reference_poses=optimum)
    whole = fed(graph, moved.graph)
    half = fed(graph, moved.graph, until=80)
    half.save(tmp_path / "half.npz")
    loaded, _ = OnlineSolver.load(tmp_path / "half.npz")
    assert loaded.num_priors == half.num_priors > 0
    np.testing.assert_array_equal(loaded.prior_ids, half.prior_ids)
    np.testing.assert_array_equal(loaded.prior_candidates, half.prior_candidates)
    np.testing.assert_array_equal(loaded.poses, half.poses)
    # Fed the rest, the loaded solver ends where the uninterrupted one does.
    feed(loaded, graph, moved.graph, range(80, graph.num_poses))
    np.testing.assert_array_equal(loaded.poses, whole.poses)
    np.testing.assert_array_equal(loaded.rejected_priors, whole.rejected_priors)


def test_a_checkpoint_written_before_priors_still_loads(tmp_path):
    graph, _, _ = world(2, 40)
    solver = fed(graph, known_inliers="odometry,priors")
    path = tmp_path / "old.npz"
    solver.save(path)
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    settings = json.loads(str(arrays.pop("settings")))
    assert not any(name.startswith("prior_") for name in arrays)  # no prior: the arrays as before
    del settings["known_inliers"], settings["digest"]  # as written before priors existed
    settings["digest"] = content_digest(settings, arrays)
    np.savez(path, settings=np.array(json.dumps(settings)), **arrays)
    loaded, _ = OnlineSolver.load(path)
    np.testing.assert_array_equal(loaded.poses, solver.poses)
    loaded.add_position_prior(3, loaded.poses[3, :2], np.eye(2))
    loaded.update()
    assert loaded.prior_candidates.tolist() == [True]  # the default of its time: candidates


def test_replay_of_a_corrupted_gnss_graph_rejects_the_jumps_and_the_false_loops():
    graph, _, false_loops, false_priors = corrupted(200, bursts=True)
    outcome = replay(graph)
    result = outcome.result
    assert outcome.solver.num_priors == graph.num_priors
    np.testing.assert_array_equal(np.sort(result.rejected_priors), graph.prior_factor_index[false_priors])
    np.testing.assert_array_equal(result.rejected_edges, np.flatnonzero(false_loops))
    batch = egnc.solve(graph, init="odometry")  # the file's poses are in the odometry's frame
    np.testing.assert_array_equal(np.sort(batch.rejected_priors), np.sort(result.rejected_priors))
    held = replay(graph, known_inliers="odometry,priors").result
    assert held.rejected_priors.shape == (0,) and held.prior_inliers is None


def test_replayed_priors_in_file_order_and_a_resumed_replay_ends_where_a_whole_one_does(tmp_path):
    graph, optimum, fixes = world(2, 120)
    moved = add_multipath_outliers(fixes, 20, seed=4, reference_poses=optimum)
    whole = replay(moved.graph).result
    path = tmp_path / "run.npz"
    replay(moved.graph, checkpoint=path, stop_after=50)
    resumed = replay(moved.graph, checkpoint=path).result
    np.testing.assert_array_equal(resumed.graph.poses, whole.graph.poses)
    np.testing.assert_array_equal(resumed.prior_inliers, whole.prior_inliers)
    rejected = np.isin(moved.graph.prior_factor_index, whole.rejected_priors)
    assert precision_recall(rejected, moved.is_outlier) == (1.0, 1.0)


def test_egnc_solve_online_replays_an_egnc_corrupt_gnss_file(tmp_path):
    corrupted_file, labels = tmp_path / "gnss.g2o", tmp_path / "gnss.labels.json"
    command = [sys.executable, "-m", "egnc.cli.corrupt", str(DATA / "grid2d.g2o"), "--percent", "10", "--seed", "1"]
    command += ["--gnss-every", "10", "--gnss-outliers", "20", "--gnss-bursts", "-o", str(corrupted_file)]
    subprocess.run([*command, "--labels", str(labels), "-q"], check=True, timeout=300)
    report = tmp_path / "report.json"
    solve = [sys.executable, "-m", "egnc.cli.solve", str(corrupted_file), "--online", "-q", "--report", str(report)]
    subprocess.run(solve, check=True, timeout=300, stdin=subprocess.DEVNULL)
    written, truth = json.loads(report.read_text()), json.loads(labels.read_text())
    graph = egnc.read_g2o(corrupted_file)
    assert written["rejected_edges"] == truth["outlier_edges"]
    expected = graph.prior_factor_index[truth["outlier_priors"]].tolist()
    assert written["rejected_priors"] == expected and written["online"]["steps"] > 0


@pytest.mark.parametrize("bursts", [False, True])
def test_replay_of_manhattan_with_fixes_false_loops_and_multipath_jumps(dataset_path, bursts):
    clean = egnc.read_g2o(dataset_path("manhattanOlson3500.g2o"))
    optimum = egnc.solve(clean, "l2").graph.poses
    false = add_false_loops(clean, 30, seed=1, reference_poses=optimum)
    fixes = add_position_priors(false.graph, optimum, every=10, sigma=2.0, seed=1)
    moved = add_multipath_outliers(fixes, 20, seed=1, bursts=bursts, reference_poses=optimum)
    result = replay(moved.graph).result
    rejected_priors = np.isin(moved.graph.prior_factor_index, result.rejected_priors)
    assert precision_recall(~result.inliers, false.is_outlier) == (1.0, 1.0)
    assert precision_recall(rejected_priors, moved.is_outlier) == (1.0, 1.0)
    reference = egnc.solve(fixes.subgraph_edges(~false.is_outlier), "l2").graph.poses
    assert ate(result.graph.poses, reference, 2, align=False) < 0.5  # in the fixes' frame, unaligned
