"""The regrouped start: rejected runs of true loops go back in together and close a torn map."""

from __future__ import annotations

import numpy as np

from egnc.api import solve
from egnc.datasets import add_false_loops, grid_world
from egnc.decision import Decision, truncated_cost
from egnc.factors import BetweenFactors, to_matrices
from egnc.gnc import GncOptions
from egnc.least_squares import SolverOptions
from egnc.regroup import MIN_RUN, loop_runs, regrouped_decision


def test_loop_runs_link_loops_whose_both_ends_are_near():
    edges = np.array(
        [
            [100, 500],  # run A
            [502, 103],  # run A, the other orientation
            [106, 509],  # run A, through its second loop only
            [100, 700],  # near A's first end, far at the other: alone
            [300, 900],  # alone
            [311, 900],  # 11 poses from it: alone
        ]
    )
    labels = loop_runs(edges, window=10)
    assert labels[0] == labels[1] == labels[2]
    assert len(set(labels[[0, 3, 4, 5]].tolist())) == 4
    assert loop_runs(np.zeros((0, 2), dtype=np.int64)).shape == (0,)


def test_a_rejected_run_goes_back_in_together():
    # A decision that rejected a run of true loops, on the map solved without them: the start
    # puts the run back, and the truncated cost falls.
    graph = grid_world(2, 600, seed=3).graph
    robust = graph.is_loop_closure
    factors = BetweenFactors.from_graph(graph)
    loops = np.flatnonzero(robust)
    labels = loop_runs(graph.edges[loops])
    run = loops[labels == np.argmax(np.bincount(labels))]
    assert len(run) >= MIN_RUN
    without = np.ones(graph.num_edges, dtype=bool)
    without[run] = False
    poses = to_matrices(2, solve(graph.subgraph_edges(without), "l2").graph.poses)
    r = factors.whitened_norms(factors.residuals(poses))
    rejected = Decision(poses, without, (), True, truncated_cost(r, robust, 3, 0.99))
    regrouped, reports = regrouped_decision(graph, robust, factors, rejected, SolverOptions(), GncOptions(), "scipy")
    assert regrouped is not None and reports and all(report.start == "regrouped" for report in reports)
    assert regrouped.inliers[run].all()
    assert regrouped.truncated_cost < rejected.truncated_cost
    nothing_rejected = Decision(poses, np.ones(graph.num_edges, dtype=bool), (), True, 0.0)
    assert regrouped_decision(graph, robust, factors, nothing_rejected, SolverOptions(), GncOptions(), "scipy") == (
        None,
        (),
    )


def test_runs_of_false_loops_lose_the_comparison():
    # At 50 % on a small grid, random false loops fall into runs by chance: the start runs and
    # its decision, bent by them, is not kept.
    world = grid_world(2, 2000, seed=1)
    reference = solve(world.graph, "l2").graph.poses
    corrupted = add_false_loops(world.graph, 50, seed=2, reference_poses=reference)
    labels = loop_runs(corrupted.graph.edges[corrupted.is_outlier])
    assert np.bincount(labels).max() >= MIN_RUN
    result = solve(corrupted.graph)
    assert any(stage.start == "regrouped" for stage in result.stages) and result.start != "regrouped"
    without = solve(corrupted.graph, gnc_options=GncOptions(regroup_start=False))
    np.testing.assert_array_equal(result.inliers, without.inliers)
    assert np.count_nonzero(result.inliers[corrupted.is_outlier]) == 0
