"""The outlier decision: clean maps stay whole, re-admission, marginals, warnings, stage protocol."""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pytest

import egnc
import egnc.nonlinear.marginals as marginals_module
import egnc.robust.decision as decision_module
import egnc.robust.readmission as readmission_module
import egnc.robust.rounds as rounds_module
from egnc.api import marginal_covariances, solve
from egnc.datasets import add_false_loops, grid_world
from egnc.graph import PoseGraph
from egnc.io import read_irl
from egnc.linalg.linear_solvers import cholmod_available
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.nonlinear.marginals import innovations, pose_covariances, relative_covariances
from egnc.robust.decision import (
    MAX_ROUNDS,
    REUSED_DAMPING,
    ROUND_TOLERANCE,
    RoundProblem,
    decide_outliers,
    readmit_quantile,
    round_information,
    sequentially_consistent,
    truncated_cost,
)
from egnc.robust.gnc import GncOptions
from egnc.robust.kernels import chi2_quantile

GUESS_ONLY = GncOptions(starts=())
"""The decision from the initial guess alone."""

FACTOR_BACKENDS = [
    "scipy",
    pytest.param("cholmod", marks=pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")),
]
"""Backends the covariance tests run on."""

OLD_RULE = GncOptions(outlier_quantile=0.95, readmit=False, starts=("runs", "chordal-all", "regrouped"))
"""The decision before re-admission and the other starts: the Geman-McClure classification at
chi2.ppf(0.95), re-checked by r^2."""


def test_drifted_guess_with_few_loops_keeps_every_loop():
    # The MIT pattern: heading noise makes the odometry guess drift, and the few loops have
    # residuals in the hundreds there. The robust optimum lets some go; re-admission brings them back.
    world = grid_world(2, 400, seed=5, loop_probability=0.03, odometry_sigma=(0.05, 0.02))
    graph = world.graph
    factors = BetweenFactors.from_graph(graph)
    initial_r = factors.whitened_norms(factors.residuals(to_matrices(2, graph.poses)))
    assert np.max(initial_r[graph.is_loop_closure] ** 2) > 100  # the guess is far off
    assert len(solve(graph, gnc_options=OLD_RULE).rejected_edges) > 0  # the case the old rule failed
    result = solve(graph)
    assert len(result.rejected_edges) == 0
    l2 = solve(graph, "l2")
    assert result.cost <= l2.cost * (1 + 1e-9)
    assert result.warnings == ()


@pytest.mark.parametrize(("dim", "num_poses"), [(2, 10000), (3, 2000)])
def test_honest_noise_rejects_fewer_than_one_percent_of_loops(dim, num_poses):
    # Noise drawn exactly as the information matrices state: about 5% of the true loops exceed
    # chi2.ppf(0.95, d) at the ground truth, and the old rule rejected 8% of them in 2D.
    graph = grid_world(dim, num_poses, seed=1).graph
    loops = int(graph.is_loop_closure.sum())
    result = solve(graph)
    assert len(result.rejected_edges) < 0.01 * loops


def test_false_loops_stay_rejected_after_readmission():
    world = grid_world(2, 300, seed=3, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 50, seed=4, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_a_5000_pose_grid_with_30_percent_false_loops_keeps_every_true_loop():
    # Before re-admission credited the map up to a loop's own uncertainty, three true loops whose
    # relative pose the map knew slightly less well than they measure it stayed out here.
    graph = grid_world(2, 5000, seed=1).graph
    clean = solve(graph, "l2", init="chordal")
    corrupted = add_false_loops(graph, 30, seed=1, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_readmission_quantile_is_raised_only_on_graphs_of_many_loops():
    options = GncOptions()  # readmit_quantile 0.9999, readmit_false_alarms 1
    robust = np.zeros(50_000, dtype=bool)
    robust[:10_000] = True  # 1 / 10 000 = 1e-4: the per-loop quantile still rules
    assert readmit_quantile(options, robust) == 0.9999
    robust[:40_000] = True
    assert readmit_quantile(options, robust) == pytest.approx(1 - 1 / 40_000, abs=1e-15)
    assert readmit_quantile(dataclasses.replace(options, readmit_false_alarms=0.1), robust[:4000]) == pytest.approx(
        1 - 0.1 / 4000, abs=1e-15
    )
    assert readmit_quantile(dataclasses.replace(options, readmit_false_alarms=None), robust) == 0.9999
    assert readmit_quantile(options, np.zeros(10, dtype=bool)) == 0.9999


def test_a_bound_on_false_alarms_per_graph_keeps_an_honest_loop_the_per_loop_rate_loses():
    # 5123 loops with noise drawn as their information states: at a per-loop false-alarm rate of
    # 1e-4, 0.5 honest loops are expected to fail re-admission, and here one does. (The default
    # bound, 1 per graph, raises the quantile only past 10 000 loops; 0.1 does here.)
    graph = grid_world(2, 10_000, seed=3).graph
    per_loop = solve(graph, gnc_options=GncOptions(readmit_false_alarms=None))
    assert np.count_nonzero(~per_loop.inliers) == 1
    assert solve(graph, gnc_options=GncOptions(readmit_false_alarms=0.1)).inliers.all()


def test_a_stage_at_its_iteration_limit_is_a_warning_not_converged():
    graph = grid_world(2, 300, seed=2, odometry_sigma=(0.05, 0.02)).graph
    # (from the guess alone: here the chordal start converges within the limit and is kept)
    result = solve(graph, options=SolverOptions(max_iterations=2), gnc_options=GUESS_ONLY)
    assert not result.converged
    assert any("iteration limit" in warning for warning in result.warnings)
    # no stage is run twice: at most the three EGNC stages and the decision rounds
    assert len(result.stages) <= 3 + MAX_ROUNDS


def test_most_loops_rejected_is_a_warning():
    world = grid_world(2, 200, seed=6, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    # 80% false loops: still rejected exactly, but the user is told most loops were dropped
    corrupted = add_false_loops(world.graph, 80, seed=7, reference_poses=clean.graph.poses)
    result = solve(corrupted.graph)
    assert any("more than half" in warning for warning in result.warnings)


def _dense_covariance(problem: Problem, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`H^-1` of the free pose tangents from a dense Jacobian, and each pose's block index."""
    lin = problem.factors.linearize(poses)
    d = lin.residuals.shape[1]
    free_index = problem.pattern.free_index
    J = np.zeros((len(lin.residuals) * d, problem.pattern.size))
    for k, (i, j) in enumerate(problem.factors.edges):
        for var, block in ((free_index[i], lin.J_e_xi[k]), (free_index[j], lin.J_e_xj[k])):
            if var >= 0:
                J[k * d : (k + 1) * d, var * d : (var + 1) * d] = block
    W = np.zeros((J.shape[0], J.shape[0]))
    for k, information in enumerate(problem.factors.information):
        W[k * d : (k + 1) * d, k * d : (k + 1) * d] = information
    return np.linalg.inv(J.T @ W @ J), free_index


@pytest.mark.parametrize("backend", FACTOR_BACKENDS)
def test_innovations_and_pose_covariances_match_a_dense_inverse(backend):
    world = grid_world(3, 40, seed=8, noise_scale=0.5)
    graph = world.graph
    loop_rows = np.flatnonzero(graph.is_loop_closure)[:3]
    kept = np.ones(graph.num_edges, dtype=bool)
    kept[loop_rows] = False
    poses = to_matrices(3, solve(graph.subgraph_edges(kept), "l2").graph.poses)
    problem = Problem.from_graph(graph.subgraph_edges(kept), backend)
    covariance, free_index = _dense_covariance(problem, poses)
    d = 6

    rows = np.array([3, 17, 39])
    blocks = pose_covariances(problem, poses, rows)
    for k, row in enumerate(rows):
        var = slice(free_index[row] * d, (free_index[row] + 1) * d)
        np.testing.assert_allclose(blocks[k], covariance[var, var], rtol=1e-8, atol=1e-14)

    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[loop_rows] = True
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    e, S = innovations(problem, poses, loops)
    lin = loops.linearize(poses)
    A = np.zeros((len(loop_rows) * d, problem.pattern.size))
    for k, (i, j) in enumerate(loops.edges):
        for var, block in ((free_index[i], lin.J_e_xi[k]), (free_index[j], lin.J_e_xj[k])):
            if var >= 0:
                A[k * d : (k + 1) * d, var * d : (var + 1) * d] = block
    expected = A @ covariance @ A.T
    for k, information in enumerate(loops.information):
        expected[k * d : (k + 1) * d, k * d : (k + 1) * d] += np.linalg.inv(information)
    np.testing.assert_allclose(S, expected, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(e, lin.residuals)


def test_sequential_consistency_admits_supporting_groups_and_never_hides_a_false_loop():
    d = 3
    threshold = chi2_quantile(0.9999, d)
    # Two loops that each look off alone (statistic 25 > 21.1) but are perfectly correlated:
    # once one is in, the other adds nothing. A third, independent, is far off (100).
    S = np.eye(3 * d)
    S[0:d, d : 2 * d] = S[d : 2 * d, 0:d] = 0.999 * np.eye(d)
    e = np.array([[5.0, 0, 0], [5.0, 0, 0], [10.0, 0, 0]])
    assert e[0] @ e[0] > threshold
    admitted = sequentially_consistent(e, S, threshold)
    np.testing.assert_array_equal(admitted, [False, False, False])  # the first alone already fails
    e[0, 0] = e[1, 0] = 4.0  # 16 alone: admitted; the twin adds ~0 given it
    np.testing.assert_array_equal(sequentially_consistent(e, S, threshold), [True, True, False])


def test_marginal_covariances_match_gtsam_marginals(dataset_path):
    gtsam = pytest.importorskip("gtsam")
    path = dataset_path("tinyGrid3D.g2o")
    result = solve(path, "l2")
    ids = [1, 4, 8]
    ours = marginal_covariances(result, ids)
    with tempfile.TemporaryDirectory() as folder:
        solved = f"{folder}/solved.g2o"
        egnc.write_g2o(result.graph, solved)
        graph, values = gtsam.readG2o(solved, True)
    graph.add(gtsam.PriorFactorPose3(0, values.atPose3(0), gtsam.noiseModel.Isotropic.Sigma(6, 1e-9)))
    marginals = gtsam.Marginals(graph, values)
    swap = np.r_[3:6, 0:3]  # GTSAM's Pose3 tangent is [omega, v]
    for k, vertex in enumerate(ids):
        reference = marginals.marginalCovariance(vertex)[np.ix_(swap, swap)]
        np.testing.assert_allclose(ours[k], reference, rtol=1e-6, atol=1e-12 * np.abs(reference).max())
    assert np.all(marginal_covariances(result, [0]) == 0)  # the gauge pose is fixed
    with pytest.raises(egnc.GraphError, match="no vertex with id"):
        marginal_covariances(result, [99])


def test_a_corrupted_odometry_edge_is_reported_not_hidden():
    world = grid_world(2, 300, seed=9, noise_scale=0.3)
    graph = world.graph
    measurements = graph.measurements.copy()
    k = np.flatnonzero(graph.is_odometry)[40]
    measurements[k, 0] += 1000.0  # a wheel-odometry glitch of a kilometre
    corrupted = dataclasses.replace(graph, measurements=measurements)
    result = solve(corrupted, gnc_options=GUESS_ONLY)
    assert any("known-inlier edges (odometry) disagree" in warning for warning in result.warnings)
    assert len(result.stages) <= 3 + MAX_ROUNDS
    # From the chordal start the odometry is honoured, kilometre and all, and the loops across
    # the glitch are rejected: the lower truncated cost with the odometry a known inlier, and
    # the message says which start the decision came from. The GNC stage from the chordal map
    # of the loops in runs (the default) reaches the same decision.
    first = solve(corrupted)
    result = solve(corrupted, gnc_options=GncOptions(starts=("chordal", "chordal-all", "regrouped", "elimination")))
    assert result.start == "chordal" and "chordal initialization" in result.message
    assert first.start == "runs" and "loop closures in runs" in first.message
    np.testing.assert_array_equal(first.inliers, result.inliers)
    assert first.truncated_cost == pytest.approx(result.truncated_cost, rel=1e-9)
    assert result.residual_norms[k] < 1.0 and 0 < len(result.rejected_edges) < 0.1 * graph.is_loop_closure.sum()
    # The elimination start cannot beat it and stops at its step bound (egnc.robust.elimination).
    steps = [stage.kind for stage in result.stages].count("elimination")
    assert steps <= int(2 * result.truncated_cost / chi2_quantile(0.99, 3)) + 1
    assert len(result.stages) <= 3 + 1 + 2 * MAX_ROUNDS + steps


def test_a_weak_map_does_not_absorb_gross_outliers(dataset_path):
    # manhattan_noisy.irl: noisy odometry leaves the map weak where 223 gross outliers sit; the map
    # "agrees" with some of them only within its own large uncertainty. Re-admitting those
    # (recall 0.89, ATE 8.8 m) is what the well-determined gate prevents.
    log = read_irl(dataset_path("manhattan_noisy.irl"))
    result = solve(log.graph, known_inliers=log.is_odometry)
    np.testing.assert_array_equal(~result.inliers, log.is_outlier)


def test_vertices_without_edges_do_not_switch_the_decision_off(tmp_path):
    shipped = Path(__file__).parents[1] / "datasets"
    text = (shipped / "grid2d_outliers.g2o").read_text()
    path = tmp_path / "with_isolated.g2o"
    path.write_text(text + "VERTEX_SE2 100000 0 0 0\nVERTEX_SE2 100001 5 5 0\n")
    is_outlier, _ = egnc.datasets.read_labels(shipped / "grid2d_outliers.labels.json")
    with pytest.warns(egnc.EgncWarning, match="no edge touches"):
        graph = egnc.read_g2o(path)
    result = solve(graph)
    assert np.isnan(result.stages[-1].mu_min)  # the decision rounds ran
    np.testing.assert_array_equal(~result.inliers, is_outlier)


@pytest.fixture(scope="module")
def alternating_grid():
    """A 2000-pose grid with 10 % false loops whose rounds from the guess used to alternate
    (`CorruptedGraph`): the tests of the rounds' stopping share it."""
    graph = grid_world(2, 2000, seed=2).graph
    clean = solve(graph, "l2")
    return add_false_loops(graph, 10, seed=2, reference_poses=clean.graph.poses)


def test_decision_rounds_reach_a_fixed_point_where_they_used_to_alternate(alternating_grid):
    # A 2000-pose grid whose rounds from the guess alternated between two classifications until
    # the round limit: true loops rejected at chi2.ppf(0.99) on one map came back through the
    # innovation test on the next. Held to the readmission quantile, they stay.
    corrupted = alternating_grid
    result = solve(corrupted.graph, gnc_options=GUESS_ONLY)
    rounds = [stage for stage in result.stages if stage.kind == "decision"]
    assert len(rounds) < MAX_ROUNDS
    assert result.warnings == ()
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_rounds_stop_early_until_their_classification_holds(monkeypatch, alternating_grid):
    # Every round's least squares stops at ROUND_TOLERANCE; the one whose classification holds
    # goes on to the caller's tolerance, so the decision's map is the least-squares optimum of
    # the accepted edges.
    corrupted = alternating_grid
    tolerances = []
    solve_round = RoundProblem.solve

    def recorded(self, poses, inliers, options, on_iteration):
        tolerances.append(options.rel_cost_tol)
        return solve_round(self, poses, inliers, options, on_iteration)

    monkeypatch.setattr(RoundProblem, "solve", recorded)
    result = solve(corrupted.graph, gnc_options=GUESS_ONLY)
    rounds = [stage for stage in result.stages if stage.kind == "decision"]
    full = SolverOptions().rel_cost_tol
    assert len(rounds) >= 2
    assert tolerances[: len(rounds)] == [ROUND_TOLERANCE] * len(rounds)  # the rounds before the last one solved
    assert tolerances[len(rounds) :] == [full]  # the last round's continuation
    refit = solve(corrupted.graph.subgraph_edges(result.inliers), "l2", known_inliers="none")
    np.testing.assert_allclose(result.graph.poses, refit.graph.poses, atol=1e-6)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)


def test_a_rounds_iteration_limit_counts_its_continuation_too(alternating_grid):
    corrupted = alternating_grid
    unlimited = solve(corrupted.graph, gnc_options=GUESS_ONLY)
    last = [stage for stage in unlimited.stages if stage.kind == "decision"][-1]
    assert last.iterations >= 3  # a loose solve and its continuation
    limit = SolverOptions(max_iterations=last.iterations - 1)
    limited = solve(corrupted.graph, options=limit, gnc_options=GUESS_ONLY)
    rounds = [stage for stage in limited.stages if stage.kind == "decision"]
    assert max(stage.iterations for stage in rounds) <= limit.max_iterations
    assert rounds[-1].status == 0 and not limited.converged  # the limit is reported, as for any stage


def test_a_cycle_of_classifications_ends_at_the_lower_truncated_cost(monkeypatch):
    # Force a cycle: every rejected loop is re-admitted, and the false ones fail again on the
    # next map. The rounds stop at the repeat and keep the classification of lowest truncated
    # cost in the cycle, with its least-squares map.
    world = grid_world(2, 300, seed=3, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 20, seed=4, reference_poses=clean.graph.poses)
    graph, robust = corrupted.graph, corrupted.graph.is_loop_closure
    solved = []  # (classification, truncated cost at its least-squares map) of every round

    def readmit_all(problem, poses, factors, rejected, r, quantile, information=None, weights=None, estimate=None):
        solved.append((~rejected, truncated_cost(r, robust, 3, 0.99)))
        return rejected

    monkeypatch.setattr(rounds_module, "readmitted", readmit_all)
    factors = BetweenFactors.from_graph(graph)
    inliers = ~corrupted.is_outlier
    decision = decide_outliers(
        graph, to_matrices(2, graph.poses), robust, SolverOptions(), GncOptions(), "auto", factors, inliers=inliers
    )
    assert len(decision.reports) == len(solved) < MAX_ROUNDS  # stopped at the repeat, not at the limit
    assert np.array_equal(solved[0][0], inliers) and not np.array_equal(solved[1][0], inliers)
    # a classification the rounds solved, no costlier than the last one (which is in the cycle)
    # (the rounds stop at `ROUND_TOLERANCE`; the kept one is then solved to the full tolerance)
    best, cost = next(pair for pair in solved if np.array_equal(pair[0], decision.inliers))
    assert cost <= solved[-1][1]
    assert decision.truncated_cost == pytest.approx(cost, rel=1e-6)
    assert cost < max(pair[1] for pair in solved[1:])  # the cycle did offer a choice
    refit = solve(graph.subgraph_edges(best), "l2", known_inliers="none")
    np.testing.assert_allclose(decision.poses, to_matrices(2, refit.graph.poses), atol=1e-6)


def test_covariances_solved_in_column_groups_equal_one_solve(monkeypatch):
    # The right-hand sides are solved a few columns at a time to bound memory on large maps.
    world = grid_world(2, 200, seed=8, noise_scale=0.5)
    graph = world.graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[:5]] = True
    problem = Problem.from_graph(graph.subgraph_edges(~left_out))
    poses = to_matrices(2, solve(graph.subgraph_edges(~left_out), "l2").graph.poses)
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    rows = np.arange(0, 200, 7)
    whole = innovations(problem, poses, loops), pose_covariances(problem, poses, rows)
    monkeypatch.setattr(marginals_module, "_MAX_RHS_VALUES", 2 * problem.pattern.size * 3)  # 2 blocks of 3
    grouped = innovations(problem, poses, loops), pose_covariances(problem, poses, rows)
    for a, b in zip((*whole[0], whole[1]), (*grouped[0], grouped[1]), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("backend", FACTOR_BACKENDS)
def test_a_rounds_last_step_factorization_gives_the_innovations_at_its_solution(backend):
    # Re-admission reads the information's factorization off the round's last least-squares step,
    # taken one tolerance-sized step before the solution with a tiny damping: the innovation
    # covariances match those of the information factorized at the solution.
    world = grid_world(2, 300, seed=8, noise_scale=0.5)
    graph = world.graph
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.flatnonzero(graph.is_loop_closure)[:6]] = True
    problem = Problem.from_graph(graph.subgraph_edges(~left_out), backend)
    refined = solve_least_squares(problem, to_matrices(2, graph.poses), None, SolverOptions())
    assert refined.status == 1 and refined.step_damping <= REUSED_DAMPING
    information = round_information(problem, refined)
    assert information is not None
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    e, reused = innovations(problem, refined.poses, loops, information)
    _, fresh = innovations(problem, refined.poses, loops)  # factorizes at the solution, in place
    np.testing.assert_allclose(reused, fresh, rtol=0, atol=1e-7 * np.abs(fresh).max())
    joint = [float(e.ravel() @ np.linalg.solve(S, e.ravel())) for S in (reused, fresh)]
    assert joint[0] == pytest.approx(joint[1], rel=1e-6)  # the statistic re-admission tests


@pytest.mark.parametrize("backend", FACTOR_BACKENDS)
def test_a_round_problem_over_more_edges_solves_and_covaries_as_its_accepted_edges_alone(backend):
    # The rounds solve on a superset of their accepted edges, the others weighted 0: the same
    # least-squares map, the same information factorization and the same innovations as a problem
    # built from the accepted edges only.
    world = grid_world(2, 300, seed=8, noise_scale=0.5)
    graph = add_false_loops(world.graph, 10, seed=3, reference_poses=world.graph.poses).graph
    accepted = np.ones(graph.num_edges, dtype=bool)
    accepted[np.flatnonzero(graph.is_loop_closure)[-16:]] = False  # the false loops and some true ones
    factors = BetweenFactors.from_graph(graph)
    start = to_matrices(2, graph.poses)
    alone = Problem.from_graph(graph.subgraph_edges(accepted), backend)
    expected = solve_least_squares(alone, start, None, SolverOptions())
    system = RoundProblem.over(graph, factors, np.ones(graph.num_edges, dtype=bool), backend)
    solved = system.solve(start, accepted, SolverOptions(), None)
    assert solved.iterations == expected.iterations and solved.status == expected.status == 1
    np.testing.assert_allclose(solved.poses, expected.poses, rtol=0, atol=1e-9)
    assert solved.cost == pytest.approx(expected.cost, rel=1e-12)
    information = round_information(system.problem, solved)
    assert information is not None
    loops = factors.subset(~accepted)
    reused = innovations(system.problem, solved.poses, loops, information)[1]
    weighted = marginals_module.covariance_solver(system.problem, solved.poses, system.weights(accepted))
    fresh = innovations(alone, expected.poses, loops)[1]
    np.testing.assert_allclose(reused, fresh, rtol=0, atol=1e-6 * np.abs(fresh).max())
    np.testing.assert_allclose(
        innovations(system.problem, solved.poses, loops, weighted)[1], fresh, rtol=0, atol=1e-7 * np.abs(fresh).max()
    )


@pytest.mark.parametrize("shared", [True, False])
def test_rounds_that_readmit_loops_share_one_analysis_on_large_systems(monkeypatch, shared):
    # On a large system the rounds' problem holds every rejected loop re-admission could take
    # back at their start, so a loop re-admitted later is in its pattern already: one problem (and
    # one symbolic analysis) serves every round. On a small one each round's problem holds its
    # accepted edges only.
    if shared:  # this grid's 1200 unknowns stand for a large system
        monkeypatch.setattr(rounds_module, "SHARED_ANALYSIS_MIN_UNKNOWNS", 1200)
    world = grid_world(2, 400, seed=2, noise_scale=0.5)
    corrupted = add_false_loops(world.graph, 20, seed=4, reference_poses=solve(world.graph, "l2").graph.poses)
    graph, robust = corrupted.graph, corrupted.graph.is_loop_closure
    start = solve(graph.subgraph_edges(~corrupted.is_outlier), "l2").graph.poses  # the outlier-free map
    factors = BetweenFactors.from_graph(graph)
    inliers = ~corrupted.is_outlier
    inliers[np.flatnonzero(robust & ~corrupted.is_outlier)[:30]] = False  # true loops the first round lacks
    built, estimated = [], []
    over = decision_module.RoundProblem.over
    monkeypatch.setattr(decision_module.RoundProblem, "over", lambda *args: built.append(args) or over(*args))
    estimate = rounds_module.ReachEstimate.of
    counted = classmethod(lambda cls, problem: estimated.append(problem) or estimate(problem))
    monkeypatch.setattr(rounds_module.ReachEstimate, "of", counted)
    decision = decide_outliers(
        graph, to_matrices(2, start), robust, SolverOptions(), GncOptions(), "auto", factors, inliers=inliers
    )
    assert len(decision.reports) >= 2 and decision.settled
    assert np.array_equal(decision.inliers, ~corrupted.is_outlier)  # the 30 came back, no false loop did
    assert len(estimated) == len(built)  # re-admission's reach estimated once per problem, not per round
    if shared:
        assert len(built) == 1
    else:
        assert len(built) == len(decision.reports)
        assert np.array_equal(built[0][2], inliers) and np.array_equal(built[-1][2], decision.inliers)


def test_a_round_that_did_not_stop_on_its_cost_test_factorizes_afresh():
    world = grid_world(2, 100, seed=8, noise_scale=0.5)
    problem = Problem.from_graph(world.graph)
    start = to_matrices(2, world.graph.poses)
    limited = solve_least_squares(problem, start, None, SolverOptions(max_iterations=1))
    assert limited.status == 0 and round_information(problem, limited) is None
    converged = solve_least_squares(problem, start, None, SolverOptions())
    assert round_information(problem, converged) is problem.step_solver.last_direct_factorization() is not None
    damped = dataclasses.replace(converged, step_damping=10 * REUSED_DAMPING)
    assert round_information(problem, damped) is None
    problem.step_solver.discard_factorization()
    assert problem.step_solver.last_direct_factorization() is None


def test_the_bounds_that_spare_covariance_solves_hold():
    # Readmission skips the covariance of a loop with r^2 below the threshold (its credited
    # statistic is at most r^2) and of a batch whose credited statistics all exceed a floor.
    # Both bounds, on loops left out of a map, true and false, weakly determined ones included.
    world = grid_world(2, 300, seed=11, noise_scale=0.5)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 20, seed=12, reference_poses=clean.graph.poses)
    graph = corrupted.graph
    left_out = corrupted.is_outlier.copy()
    left_out[np.flatnonzero(graph.is_loop_closure & ~corrupted.is_outlier)[::10]] = True
    problem = Problem.from_graph(graph.subgraph_edges(~left_out))
    poses = to_matrices(2, solve(graph.subgraph_edges(~left_out), "l2").graph.poses)
    loops = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    e, S = innovations(problem, poses, loops)
    d = 3
    blocks = np.arange(len(e))[:, None] * d + np.arange(d)
    S_kk = S[blocks[:, :, None], blocks[:, None, :]]
    own = np.linalg.inv(loops.information)
    credited = decision_module.credited_covariance(S, own)[blocks[:, :, None], blocks[:, None, :]]
    alone = np.einsum("ki,ki->k", e, np.linalg.solve(credited, e[:, :, None])[:, :, 0])
    r = loops.whitened_norms(e)
    assert np.all(alone <= r * r * (1 + 1e-12))
    well_determined = np.trace(S_kk - own, axis1=1, axis2=2) <= np.trace(own, axis1=1, axis2=2)
    assert 10 < well_determined.sum() < len(e)  # both kinds
    floor = readmission_module.statistic_floor(loops, poses)
    assert np.all(floor <= alone * (1 + 1e-12))
    assert np.any(floor > chi2_quantile(0.9999, d))  # the floor does spare false loops


@pytest.mark.parametrize(
    ("excess", "solved"), [(3.0, [(1, True), (1, False)]), (1.3, [(1, True), (3, False), (64, True)])]
)
def test_a_batch_whose_only_possible_loops_fail_alone_is_not_solved(monkeypatch, excess, solved):
    # Three true loops moved sideways to r^2 = `excess` x the threshold, left out with 50 % gross
    # false loops: they lead the first batch, the only loops of it the covariance-free floor lets
    # through. At 3x one of them is let through and fails alone, so the 64-loop batch is never
    # solved; at 1.3x two pass alone and the batch is solved as before. The same loops come back
    # either way as without the scout. The scout's query never exports the factor (the batch's,
    # and the all-agree test's loop before it, may).
    world = grid_world(2, 300, seed=11, noise_scale=0.5)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 50, seed=12, reference_poses=clean.graph.poses)
    moved = np.flatnonzero(corrupted.graph.is_loop_closure & ~corrupted.is_outlier)[[3, 9, 15]]
    left_out = corrupted.is_outlier.copy()
    left_out[moved] = True
    kept = corrupted.graph.subgraph_edges(~left_out)
    poses = to_matrices(2, solve(kept, "l2").graph.poses)
    threshold = chi2_quantile(0.9999, 3)
    g = corrupted.graph
    measurements = g.measurements.copy()
    measurements[moved, 1] += np.sqrt(excess * threshold / g.information[moved, 1, 1])
    factors = BetweenFactors.from_graph(PoseGraph(2, g.vertex_ids, g.poses, g.edges, measurements, g.information))
    r = factors.whitened_norms(factors.residuals(poses))
    assert np.all(r[moved] ** 2 > threshold)  # none fits without its covariance
    problem = Problem.from_graph(kept)
    solved_loops: list[tuple[int, bool]] = []
    batch_innovations = readmission_module._batch_innovations

    def counted(problem, poses, factors, batch, covariance, export=True):
        solved_loops.append((len(batch), export))
        return batch_innovations(problem, poses, factors, batch, covariance, export)

    monkeypatch.setattr(readmission_module, "_batch_innovations", counted)
    scouted = decision_module.readmitted(problem, poses, factors, left_out, r, 0.9999)
    assert solved_loops == solved
    monkeypatch.setattr(readmission_module, "SCOUT_LOOPS", 0)
    solved_loops.clear()
    unscouted = decision_module.readmitted(problem, poses, factors, left_out, r, 0.9999)
    assert solved_loops == [(1, True), (64, True)]
    np.testing.assert_array_equal(scouted, unscouted)
    assert not np.any(scouted & corrupted.is_outlier)
    assert np.count_nonzero(scouted) == (0 if excess == 3.0 else 2)


def _chain_with_loops(
    scales: dict[tuple[int, int], float], errors: dict[tuple[int, int], float]
) -> tuple[PoseGraph, BetweenFactors, Problem, np.ndarray]:
    """A 2D chain of 41 poses (1 m steps, odometry information 100) and loops `(i, j)` whose covariance
    is the chain's covariance of their relative pose divided by `scales[(i, j)]`, measured off the
    truth by a sideways error giving `r^2 = errors[(i, j)]`. Returns `(graph, factors, problem, poses)`,
    the problem being the odometry's least squares (solved at the truth, the measurements being exact)."""
    num = 41
    truth = np.stack([np.arange(num, dtype=float), np.zeros(num), np.zeros(num)], axis=1)
    odometry = np.stack([np.arange(num - 1), np.arange(1, num)], axis=1)
    loops = np.array(list(scales), dtype=np.int64)
    edges = np.concatenate([odometry, loops])
    measurements = np.zeros((len(edges), 3))
    measurements[:, 0] = edges[:, 1] - edges[:, 0]
    information = np.tile(100.0 * np.eye(3), (len(edges), 1, 1))
    chain = np.arange(len(edges)) < num - 1
    poses = to_matrices(2, truth)
    for _ in range(4):  # a loop's Jacobian, so the map's covariance of its residual, depends on its measurement
        graph = PoseGraph(2, np.arange(num), truth, edges, measurements, information)
        factors = BetweenFactors.from_graph(graph)
        problem = Problem.from_graph(graph.subgraph_edges(chain), "auto", factors.subset(chain))
        relative = relative_covariances(problem, poses, factors.subset(~chain))
        for k, pair in enumerate(scales):
            information[num - 1 + k] = np.linalg.inv(relative[k] / scales[pair])
            measurements[num - 1 + k, 1] = np.sqrt(errors[pair] / information[num - 1 + k, 1, 1])  # r^2 = y^2 Omega_yy
    graph = PoseGraph(2, np.arange(num), truth, edges, measurements, information)
    factors = BetweenFactors.from_graph(graph)
    return graph, factors, Problem.from_graph(graph.subgraph_edges(chain), "auto", factors.subset(chain)), poses


def test_readmission_credits_the_map_with_no_more_uncertainty_than_the_loops_own():
    # (0, 20): the chain's covariance of its relative pose is twice the loop's own, r^2 = 30;
    # (0, 40): twenty times, r^2 = 300 (a gross error that a weak map would absorb);
    # (10, 30): a gross error the chain knows well, so that not every rejected loop agrees.
    scales = {(0, 20): 2.0, (0, 40): 20.0, (10, 30): 0.25}
    graph, factors, problem, poses = _chain_with_loops(scales, {(0, 20): 30.0, (0, 40): 300.0, (10, 30): 200.0})
    loops = np.flatnonzero(graph.is_loop_closure)
    r = factors.whitened_norms(factors.residuals(poses))
    np.testing.assert_allclose(r[loops] ** 2, [30.0, 300.0, 200.0])
    threshold = chi2_quantile(0.9999, 3)
    e, S = innovations(problem, poses, factors.subset(loops), readmission_module.covariance_solver(problem, poses))
    own = np.linalg.inv(factors.information[loops])
    block = np.arange(3)[:, None] * 3 + np.arange(3)
    ratios = np.trace(S[block[:, :, None], block[:, None, :]] - own, axis1=1, axis2=2) / np.trace(own, axis1=1, axis2=2)
    np.testing.assert_allclose(ratios, list(scales.values()), rtol=0.05)
    credited = decision_module.credited_covariance(S, own)
    alone = [
        [e[k] @ np.linalg.solve(M[3 * k : 3 * k + 3, 3 * k : 3 * k + 3], e[k]) for k in range(3)] for M in (S, credited)
    ]
    # the uncredited statistic lets both weak-map loops pass; credited, only the first
    assert alone[0][0] < threshold and alone[0][1] < threshold < alone[0][2]
    assert alone[1][0] < threshold < alone[1][1]
    np.testing.assert_allclose(alone[0][2], alone[1][2])  # a well-determined loop is tested as before
    rejected = np.zeros(graph.num_edges, dtype=bool)
    rejected[loops] = True
    back = decision_module.readmitted(problem, poses, factors, rejected, r, 0.9999)
    np.testing.assert_array_equal(np.flatnonzero(back), loops[:1])


def test_credited_covariance_scales_the_map_share_of_weak_loops_to_their_own_size():
    rng = np.random.default_rng(0)
    own = np.stack([np.diag(rng.uniform(0.5, 2.0, 3)) for _ in range(3)])
    root = rng.normal(size=(9, 9))
    relative = root @ root.T  # the map's joint covariance: blocks of trace about 27 against own's 3-6
    relative[:3, :] *= 0.05
    relative[:, :3] *= 0.05  # the first loop well determined
    block = np.arange(3)[:, None] * 3 + np.arange(3)
    S = relative.copy()
    S[block[:, :, None], block[:, None, :]] += own
    credited = decision_module.credited_covariance(S, own)
    np.linalg.cholesky(credited)  # positive definite
    map_part = credited.copy()
    map_part[block[:, :, None], block[:, None, :]] -= own
    np.testing.assert_allclose(credited[:3, :3], S[:3, :3])
    for k in (1, 2):
        assert np.trace(relative[3 * k : 3 * k + 3, 3 * k : 3 * k + 3]) > np.trace(own[k])
        np.testing.assert_allclose(np.trace(map_part[3 * k : 3 * k + 3, 3 * k : 3 * k + 3]), np.trace(own[k]))


def test_map_credit_of_a_loop_the_map_fixes_exactly_is_one_without_overflow():
    # A loop between two fixed poses: the map's covariance of its relative pose is zero.
    own = np.stack([np.eye(3) * 4.0, np.eye(3) * 0.5, np.eye(3)])
    relative = np.stack([np.zeros((3, 3)), np.eye(3) * 0.1, np.eye(3) * 2.0])
    with np.errstate(all="raise"):
        credit = decision_module.map_credit(relative, own)
    np.testing.assert_allclose(credit, [1.0, 1.0, 0.5])
