"""The regrouped start: rejected runs of true loops go back in together and close a torn map."""

from __future__ import annotations

import numpy as np

import egnc
from egnc.api import solve
from egnc.bench.cases import least_squares_optimum
from egnc.datasets import add_false_loops, grid_world
from egnc.graph import PoseGraph
from egnc.graph.connectivity import connected_components
from egnc.nonlinear.chordal import chordal_initialization
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import SolverOptions
from egnc.robust.decision import Decision, StartContext, truncated_cost
from egnc.robust.gnc import START_NAMES, GncOptions
from egnc.robust.kernels import chi2_quantile
from egnc.robust.regroup import (
    MIN_RUN,
    RunsStart,
    consistent_pairs,
    loop_runs,
    neighbouring_pairs,
    regrouped_decision,
    runs_start,
)


def test_neighbouring_pairs_link_loops_whose_both_ends_are_near():
    edges = np.array(
        [
            [100, 500],  # linked to the next two
            [502, 103],  # the other orientation
            [106, 509],  # 6 and 9 poses from the first, 3 and 6 from the second
            [100, 700],  # near the first's first end, far at the other
            [300, 900],
            [311, 900],  # 11 poses from the one before
        ]
    )
    pairs = {tuple(sorted(pair)) for pair in neighbouring_pairs(edges, window=10).tolist()}
    assert pairs == {(0, 1), (0, 2), (1, 2)}
    assert neighbouring_pairs(np.zeros((0, 2), dtype=np.int64)).shape == (0, 2)


def test_neighbouring_true_loops_agree_and_a_false_one_does_not():
    graph = grid_world(2, 600, seed=3).graph
    factors = BetweenFactors.from_graph(graph)
    poses = to_matrices(2, solve(graph, "l2").graph.poses)
    loops = factors.subset(np.flatnonzero(graph.is_loop_closure))
    pairs = neighbouring_pairs(loops.edges)
    threshold = chi2_quantile(0.9999, 3)
    assert len(pairs) > 10 and consistent_pairs(loops, poses, pairs, threshold).all()
    # One loop's measurement off by a metre: no pair with it agrees, the others still do.
    k = pairs[0, 0]
    Z_inv = loops.Z_inv.copy()
    Z_inv[k, 0, 2] += 1.0
    shifted = BetweenFactors(2, loops.edges, Z_inv, loops.information)
    with_k = (pairs == k).any(axis=1)
    agree = consistent_pairs(shifted, poses, pairs, threshold)
    assert not agree[with_k].any() and agree[~with_k].all()
    # A loop and its reversed copy (the inverse measurement) agree.
    copy = BetweenFactors(
        2,
        np.vstack([loops.edges[k], loops.edges[k, ::-1]]),
        np.stack([loops.Z_inv[k], np.linalg.inv(loops.Z_inv[k])]),
        loops.information[[k, k]],
    )
    assert consistent_pairs(copy, poses, np.array([[0, 1]]), threshold).all()


def test_a_rejected_run_goes_back_in_together():
    # A decision that rejected a run of true loops, on the map solved without them: the start
    # puts the run back, and the truncated cost falls.
    graph = grid_world(2, 600, seed=3).graph
    robust = graph.is_loop_closure
    factors = BetweenFactors.from_graph(graph)
    loops = np.flatnonzero(robust)
    optimum = to_matrices(2, solve(graph, "l2").graph.poses)
    labels = loop_runs(factors.subset(loops), optimum, chi2_quantile(0.9999, 3))
    run = loops[labels == np.argmax(np.bincount(labels))]
    assert len(run) >= MIN_RUN
    without = np.ones(graph.num_edges, dtype=bool)
    without[run] = False
    poses = to_matrices(2, solve(graph.subgraph_edges(without), "l2").graph.poses)
    r = factors.whitened_norms(factors.residuals(poses))
    rejected = Decision(poses, without, (), True, truncated_cost(r, robust, 3, 0.99))
    context = StartContext(graph, robust, factors, SolverOptions(), GncOptions(), "scipy")
    regrouped, reports = regrouped_decision(context, rejected)
    assert regrouped is not None and reports and all(report.start == "regrouped" for report in reports)
    assert regrouped.inliers[run].all()
    assert regrouped.truncated_cost < rejected.truncated_cost
    nothing_rejected = Decision(poses, np.ones(graph.num_edges, dtype=bool), (), True, 0.0)
    assert regrouped_decision(context, nothing_rejected) == (
        None,
        (),
    )


def test_false_loops_side_by_side_by_chance_are_not_a_run():
    # At 50 % on a small grid, random false loops lie side by side by chance; they do not agree,
    # so the result is the one without the start.
    world = grid_world(2, 2000, seed=1)
    reference = solve(world.graph, "l2").graph.poses
    corrupted = add_false_loops(world.graph, 50, seed=2, reference_poses=reference)
    false = np.flatnonzero(corrupted.is_outlier)
    by_position = connected_components(len(false), neighbouring_pairs(corrupted.graph.edges[false]))[1]
    assert np.bincount(by_position).max() >= MIN_RUN
    result = solve(corrupted.graph)
    assert result.start != "regrouped"
    without = solve(corrupted.graph, gnc_options=GncOptions(starts=("runs", "chordal", "chordal-all", "elimination")))
    np.testing.assert_array_equal(result.inliers, without.inliers)
    assert np.count_nonzero(result.inliers[corrupted.is_outlier]) == 0


def _context(graph: PoseGraph) -> StartContext:
    """The start context of `graph` with its odometry known inliers, default options, SciPy."""
    factors = BetweenFactors.from_graph(graph)
    return StartContext(graph, ~graph.is_odometry, factors, SolverOptions(), GncOptions(), "scipy")


def test_the_gnc_stage_starts_from_the_chordal_map_of_the_loops_in_runs():
    # 30 % false loops on a grid whose guess is chained odometry: the runs at the guess hold true
    # loops only, their chordal map fits better than the guess, and the GNC stage starts there.
    world = grid_world(2, 2000, seed=1)
    reference = solve(world.graph, "l2", init="chordal").graph.poses
    corrupted = add_false_loops(world.graph, 30, seed=2, reference_poses=reference)
    graph = corrupted.graph
    context = _context(graph)
    guess = to_matrices(2, graph.poses)
    start = runs_start(context, guess)
    loops = np.flatnonzero(context.robust)
    labels = loop_runs(context.factors.subset(loops), guess, chi2_quantile(0.9999, 3))
    in_run = loops[np.bincount(labels)[labels] >= MIN_RUN]
    assert len(in_run) > 100 and not corrupted.is_outlier[in_run].any()
    keep = graph.is_odometry.copy()
    keep[in_run] = True
    expected = chordal_initialization(graph.subgraph_edges(keep), linear_solver="scipy")
    assert start is not None
    np.testing.assert_array_equal(start.poses, to_matrices(2, expected))
    np.testing.assert_array_equal(np.flatnonzero(start.runs >= 0), np.sort(in_run))

    def cost(poses: np.ndarray) -> float:
        return truncated_cost(context.factors.whitened_norms(context.factors.residuals(poses)), context.robust, 3, 0.99)

    assert cost(start.poses) < cost(guess)
    result = solve(graph)
    assert result.start == "runs" and result.stages[0].kind == "gnc" and result.stages[0].start == "runs"
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_a_guess_without_runs_or_better_than_their_map_is_kept(dataset_path):
    # MIT's 20 loops form no run: nothing changes, bit for bit.
    mit = egnc.read_g2o(dataset_path("MIT.g2o"))
    assert runs_start(_context(mit), to_matrices(2, mit.poses)) is None
    result, without = solve(mit), solve(mit, gnc_options=GncOptions(starts=START_NAMES[1:]))
    assert result.start == without.start == "guess" and result.stages[0].start == "guess"
    np.testing.assert_array_equal(result.graph.poses, without.graph.poses)
    # A grid whose guess is its least-squares optimum has runs, but no map of fewer edges fits better.
    grid = grid_world(2, 600, seed=3).graph
    optimum = solve(grid, "l2").graph
    assert runs_start(_context(optimum), to_matrices(2, optimum.poses)) is None
    assert solve(optimum).start == "guess"


def test_a_run_rejected_whole_contradicts_the_start():
    runs = np.array([-1, 0, 0, 0, 1, 1, 1, -1])
    start = RunsStart(np.eye(3)[None], runs)
    inliers = np.ones(8, dtype=bool)
    assert not start.contradicted(inliers)
    inliers[[0, 7]] = False  # loops outside the runs
    inliers[[1, 4, 5]] = False  # one or two loops of each run: honest false alarms
    assert not start.contradicted(inliers)
    inliers[6] = False  # all of run 1
    assert start.contradicted(inliers)


def test_runs_of_false_loops_send_the_decision_back_to_the_guess(dataset_path):
    # riSAM's "group" variant: false loops drawn in groups that agree with each other form runs,
    # and their chordal map is bent. Its decision rejects whole runs it had assumed true, so the
    # GNC stage runs from the guess as well, and that decision (every false loop out, nothing
    # else) has the lower truncated cost.
    graph = egnc.read_g2o(dataset_path("manhattanOlson3500.g2o"))
    reference = least_squares_optimum(graph, "auto").graph.poses
    corrupted = add_false_loops(graph, 10, seed=1, reference_poses=reference, variant="group")
    result = solve(corrupted.graph)
    assert [stage.start for stage in result.stages if stage.kind == "gnc"] == ["runs", "guess"]
    assert result.start == "guess" and "from the initial guess" in result.message
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
