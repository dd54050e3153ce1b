"""The chordal start: a drifted guess no longer decides the result, and false loops never bend it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import egnc
from egnc.api import marginal_covariances, solve
from egnc.bench.cases import least_squares_optimum
from egnc.cli.report import summary
from egnc.datasets import add_false_loops, grid_world
from egnc.graph import PoseGraph
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.initialize import initialize_poses
from egnc.nonlinear.least_squares import Problem, SolverOptions
from egnc.nonlinear.marginals import pose_covariances
from egnc.robust.decision import Decision, StartContext, truncated_cost
from egnc.robust.diagnostics import solve_warnings
from egnc.robust.gnc import START_NAMES, START_OPTIONS, GncOptions, StageStart, run_gnc
from egnc.robust.kernels import chi2_quantile
from egnc.robust.pipeline import GUESS, STARTS
from egnc.robust.schedules import make_schedule
from egnc.robust.starts import ALL_EDGES_SHARE, all_edges_decision

GUESS_ONLY = GncOptions(starts=())
"""The default before the chordal start: decide from the GNC solve of the initial guess alone."""

WITHOUT_RUNS = GncOptions(starts=START_NAMES[1:])
"""The default without the runs start: the GNC stage starts from the guess."""


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


def test_a_drifted_guess_no_longer_decides_the_result(dataset_path):
    # manhattanOlson3500 re-chained with 0.1 rad of heading noise per step: from that guess the
    # GNC stage settles in a folded map and the decision from it confirms the fold
    graph = drifted_guess(egnc.read_g2o(dataset_path("manhattanOlson3500.g2o")), seed=2, heading_sigma=0.1)
    guess_only = solve(graph, gnc_options=GUESS_ONLY)
    result = solve(graph)
    chordal = solve(graph, gnc_options=WITHOUT_RUNS)
    least_squares = solve(graph, "l2", init="chordal")
    assert len(guess_only.rejected_edges) > 100
    # The GNC stage starts from the chordal map of the loops in runs; without that start, the
    # chordal start's decision wins.
    assert result.start == "runs" and "loop closures in runs" in result.message
    assert chordal.start == "chordal" and "chordal initialization" in chordal.message
    for decided in (result, chordal):
        assert len(decided.rejected_edges) == 0 and decided.truncated_cost < guess_only.truncated_cost
        assert decided.cost == pytest.approx(least_squares.cost, rel=1e-6)  # the least-squares optimum


def test_false_loops_keep_the_decision_of_the_first_start():
    world = grid_world(2, 300, seed=3, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 30, seed=4, reference_poses=clean.graph.poses)
    for first in ("runs", "guess"):
        options = GncOptions() if first == "runs" else WITHOUT_RUNS
        result = solve(corrupted.graph, gnc_options=options)
        np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
        assert result.start == first
        # the chordal map accepts no loop the decision rejects: the chordal start stops before its probe
        assert "probe" not in [stage.kind for stage in result.stages]
        first_only = GncOptions(starts=options.starts[:1] if first == "runs" else ())
        np.testing.assert_array_equal(result.graph.poses, solve(corrupted.graph, gnc_options=first_only).graph.poses)


def test_the_chordal_start_wins_back_a_true_loop_after_the_runs_start(dataset_path):
    # kitti_00 with 10 % false loops (seed 1): the runs start's decision rejects one true loop;
    # the chordal map accepts it, the decision to beat's loops are added, and that decision wins.
    graph = egnc.read_g2o(dataset_path("kitti_00.g2o"))
    reference = least_squares_optimum(graph, "auto").graph.poses
    corrupted = add_false_loops(graph, 10, seed=1, reference_poses=reference)
    robust = corrupted.graph.is_loop_closure
    result = solve(corrupted.graph)
    without_chordal = GncOptions(starts=tuple(name for name in START_NAMES if name != "chordal"))
    without = solve(corrupted.graph, gnc_options=without_chordal)
    assert result.start == "chordal"
    np.testing.assert_array_equal(robust & ~result.inliers, corrupted.is_outlier)
    assert np.count_nonzero(robust & ~without.inliers & ~corrupted.is_outlier) == 1
    assert result.truncated_cost < without.truncated_cost


def test_after_the_runs_start_the_chordal_start_classifies_at_its_map(dataset_path, monkeypatch):
    # The GNC stage began at the runs start's chordal map, and the decision did not contradict
    # its runs: the chordal start classifies there instead of solving a chordal map of its own.
    graph = egnc.read_g2o(dataset_path("kitti_00.g2o"))
    reference = least_squares_optimum(graph, "auto").graph.poses
    corrupted = add_false_loops(graph, 10, seed=1, reference_poses=reference)
    chordal_maps = []
    solved = StartContext.chordal_poses

    def counted(self, keep):
        chordal_maps.append(keep)
        return solved(self, keep)

    monkeypatch.setattr(StartContext, "chordal_poses", counted)
    result = solve(corrupted.graph)
    assert result.stages[0].start == "runs" and result.start == "chordal"
    assert len(chordal_maps) == 1  # the runs start's
    np.testing.assert_array_equal(corrupted.graph.is_loop_closure & ~result.inliers, corrupted.is_outlier)


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
    least_squares = solve(graph, "l2", init="chordal")
    for options, start in ((GncOptions(), "runs"), (WITHOUT_RUNS, "chordal")):
        result = solve(graph, gnc_options=options)
        assert len(result.rejected_edges) == 0 and result.start == start
        assert result.cost == pytest.approx(least_squares.cost, rel=1e-6)
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


def _all_edges_start(graph: PoseGraph, rejected_loops: int):
    """`(context, to_beat, graduate)` for `all_edges_decision` on `graph`: a decision that rejects
    its first `rejected_loops` loop closures, and egnc's GNC stage."""
    robust = ~graph.is_odometry
    factors = BetweenFactors.from_graph(graph)
    context = StartContext(graph, robust, factors, SolverOptions(), GncOptions(), "auto")
    inliers = np.ones(graph.num_edges, dtype=bool)
    inliers[np.flatnonzero(robust)[:rejected_loops]] = False
    to_beat = Decision(to_matrices(2, graph.poses), inliers, (), True, np.inf)

    def graduate(poses: np.ndarray, start: StageStart):
        schedule = make_schedule("egnc", robust, graph.tangent_dim)
        return run_gnc(graph, poses, schedule, robust, SolverOptions(), GncOptions(), "auto", factors, start=start)

    return context, to_beat, graduate


def test_the_all_edges_start_wins_back_loops_from_a_drifted_guess():
    graph = drifted_guess(grid_world(2, 1000, seed=1).graph, seed=2, heading_sigma=0.5)
    context, to_beat, graduate = _all_edges_start(graph, rejected_loops=10)
    decision, reports = all_edges_decision(context, to_beat, graduate)
    assert decision is not None and np.count_nonzero(~decision.inliers) <= 2
    # and it beats the decision it was given, taken at its own least-squares map
    given = solve(graph.subgraph_edges(to_beat.inliers), "l2", init="chordal").graph.poses
    factors = BetweenFactors.from_graph(graph)
    r = factors.whitened_norms(factors.residuals(to_matrices(2, given)))
    assert decision.truncated_cost < truncated_cost(r, ~graph.is_odometry, 3, 0.99)
    assert reports[0].kind == "gnc" and {report.start for report in reports} == {"chordal-all"}


def _never_called(*args, **kwargs):
    raise AssertionError("the start went further than its gate")


def test_the_all_edges_start_does_not_run_without_reason(monkeypatch):
    graph = drifted_guess(grid_world(2, 400, seed=1).graph, seed=2, heading_sigma=0.5)
    loops = int(np.count_nonzero(~graph.is_odometry))
    context, nothing_rejected, _ = _all_edges_start(graph, rejected_loops=0)
    assert all_edges_decision(context, nothing_rejected, _never_called) == (None, ())
    # the guess fits better than the chordal map of every edge: the least-squares optimum
    optimum = graph.with_poses(solve(graph, "l2", init="chordal").graph.poses)
    context, to_beat, _ = _all_edges_start(optimum, rejected_loops=1)
    assert all_edges_decision(context, to_beat, _never_called) == (None, ())
    # too many rejected loops: not even the chordal system of every edge is solved
    monkeypatch.setattr("egnc.robust.decision.chordal_initialization", _never_called)
    context, many_rejected, _ = _all_edges_start(graph, rejected_loops=int(ALL_EDGES_SHARE * loops) + 1)
    assert all_edges_decision(context, many_rejected, _never_called) == (None, ())


def test_no_starts_is_the_old_all_off_configuration():
    world = grid_world(2, 200, seed=5, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 30, seed=6, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph, linear_solver="scipy", gnc_options=GUESS_ONLY)
    with pytest.warns(DeprecationWarning, match="starts=()"):
        all_off = GncOptions(**dict.fromkeys(START_OPTIONS, False))
    old = solve(corrupted.graph, linear_solver="scipy", gnc_options=all_off)
    np.testing.assert_array_equal(result.graph.poses, old.graph.poses)
    assert result.start == old.start == "guess" and len(result.stages) == len(old.stages) == 2
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
    # the cost the five booleans all False gave before `GncOptions.starts` (commit 6ea427b)
    assert result.cost == pytest.approx(213401.54865559706, rel=1e-9)
    assert result.truncated_cost == pytest.approx(179.63764647726347, rel=1e-9)


def test_every_start_is_one_named_strategy_in_the_registry():
    assert tuple(STARTS) == START_NAMES == GncOptions().starts
    for name, start in STARTS.items():
        assert start.name == name and callable(start.propose) and start.description


def test_the_starts_propose_in_the_order_given_after_the_guess(monkeypatch):
    graph = drifted_guess(grid_world(2, 300, seed=1).graph, seed=2, heading_sigma=0.5)
    proposed: list[str] = []

    def recorded(start):
        def propose(search):
            proposed.append(start.name)
            return type(start).propose(start, search)

        return propose

    for start in (GUESS, *STARTS.values()):
        monkeypatch.setattr(start, "propose", recorded(start))
    for starts in (("elimination", "chordal"), ("runs", "regrouped", "chordal-all"), ()):
        proposed.clear()
        result = solve(graph, gnc_options=GncOptions(starts=starts))
        expected = ["guess", *starts] if starts[:1] != ("runs",) else ["runs", "guess", *starts[1:]]
        assert proposed == expected and result.start in ("guess", *starts)
