"""The regrouped start: rejected runs of true loops go back in together and close a torn map."""

from __future__ import annotations

import numpy as np

from egnc.api import solve
from egnc.connectivity import connected_components
from egnc.datasets import add_false_loops, grid_world
from egnc.decision import Decision, StartContext, truncated_cost
from egnc.factors import BetweenFactors, to_matrices
from egnc.gnc import GncOptions
from egnc.kernels import chi2_quantile
from egnc.least_squares import SolverOptions
from egnc.regroup import MIN_RUN, consistent_pairs, loop_runs, neighbouring_pairs, regrouped_decision


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
    without = solve(corrupted.graph, gnc_options=GncOptions(regroup_start=False))
    np.testing.assert_array_equal(result.inliers, without.inliers)
    assert np.count_nonzero(result.inliers[corrupted.is_outlier]) == 0
