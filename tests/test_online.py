"""The online solver (`egnc.online`) and the replay of whole graphs through it (`egnc.online.replay`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

import egnc
import egnc.online.result
from egnc.datasets import add_false_loops
from egnc.errors import EgncError, GraphError, OptionError
from egnc.io.labels import read_labels
from egnc.linalg.linear_solvers import cholmod_available
from egnc.metrics import precision_recall
from egnc.nonlinear.factors import from_matrices, group_of, to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.online import OnlineOptions, OnlineSolver
from egnc.online.replay import replay, replay_plan, replay_steps
from egnc.robust.decision import Decision, truncated_cost
from egnc.robust.kernels import make_kernel
from egnc.robust.losses import KernelLoss
from egnc.robust.mu_star import mu_star

DATA = Path(__file__).parents[1] / "datasets"
RISAM_SEQUENCE = [0.0, 0.12, 0.384, 0.9648, 1.0]


def _square(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Odometry of a unit square walked counter-clockwise (4 steps back to the start), and its information."""
    if dim == 2:
        step = np.array([1.0, 0.0, np.pi / 2])
        return np.tile(step, (4, 1)), np.diag([100.0, 100.0, 400.0])
    # A quarter turn about the axis n = (1, 1, 1) / sqrt(3) with a translation orthogonal to n:
    # four such steps compose to the identity, in a loop that is not planar in any frame axis.
    axis = np.ones(3) / np.sqrt(3.0)
    step = np.concatenate(([1.0, -1.0, 0.0], axis * np.sin(np.pi / 4), [np.cos(np.pi / 4)]))
    return np.tile(step, (4, 1)), np.diag([100.0, 100.0, 100.0, 400.0, 400.0, 400.0])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("method", ["egnc", "risam"])
def test_consistent_loop_is_kept_and_the_map_is_the_composed_odometry(dim, method):
    odometry, information = _square(dim)
    solver = OnlineSolver(dim, method)
    solver.add_prior(0, from_matrices(dim, np.eye(dim + 1)))
    for k in range(3):
        solver.add_odometry(k, k + 1, odometry[k], information)
    solver.update()
    # The loop 3 -> 0 measures exactly the fourth step: every residual is zero at the composed map.
    loop = solver.add_loop(3, 0, odometry[3], information)
    report = solver.update()
    T = to_matrices(dim, solver.poses)
    Z = to_matrices(dim, odometry[0])
    expected = np.stack([np.linalg.matrix_power(Z, k) for k in range(4)])
    np.testing.assert_allclose(T, expected, atol=1e-12)
    assert solver.residual_norms[loop] < 1e-9
    assert loop not in solver.rejected
    assert report.new_loops.tolist() == [loop]
    assert report.mu_history[0, 0] == 0.0 and report.mu_history[-1, 0] == 1.0
    result = solver.result()
    assert isinstance(result, egnc.Result)
    assert result.inliers.all() and result.graph.num_poses == 4 and result.graph.num_edges == 4


@pytest.mark.parametrize("dim", [2, 3])
def test_an_update_with_only_new_odometry_solves_nothing(dim):
    odometry, information = _square(dim)
    solver = OnlineSolver(dim, "egnc")
    solver.add_prior(0, from_matrices(dim, np.eye(dim + 1)))
    solver.add_odometry(0, 1, odometry[0], information)
    solver.add_odometry(1, 2, odometry[1], information)
    solver.add_loop(2, 0, odometry[0], information)  # a wrong loop, so the map is not trivially exact
    first = solver.update()
    assert first.iterations > 0 and first.reanalysed
    before = solver.poses
    solver.add_odometry(2, 3, odometry[2], information)
    report = solver.update()
    assert report.stages == () and report.iterations == 0 and not report.reanalysed and report.status == -1
    assert report.new_poses == 1 and report.new_loops.size == 0
    np.testing.assert_array_equal(solver.poses[:3], before)
    group = group_of(dim)
    T = to_matrices(dim, solver.poses)
    np.testing.assert_allclose(group.between(T[2], T[3]), to_matrices(dim, odometry[2]), atol=1e-12)


def test_odometry_between_known_poses_is_solved_without_graduation():
    odometry, information = _square(2)
    solver = OnlineSolver(2, "egnc")
    solver.add_prior(0, [0.0, 0.0, 0.0])
    for k in range(3):
        solver.add_odometry(k, k + 1, odometry[k], information)
    solver.update()
    solver.add_odometry(3, 0, odometry[3] + [0.2, 0.0, 0.0], information)  # a known inlier that disagrees a bit
    report = solver.update()
    assert len(report.stages) == 1 and report.iterations > 0 and report.graduated == 0
    assert solver.residual_norms[-1] > 0.1 and solver.rejected.size == 0


def _chain(
    method: str, linear_solver: str = "auto", regraduate: str = "reference", decide_at_arrival: bool = False
) -> tuple[OnlineSolver, np.ndarray]:
    """Eleven poses along x, 1 m apart; the x variance between pose 0 and 10 is 0.01 m^2 by odometry."""
    options = OnlineOptions(regraduate=regraduate, decide_at_arrival=decide_at_arrival)  # type: ignore[arg-type]
    solver = OnlineSolver(2, method, linear_solver=linear_solver, online_options=options)
    solver.add_prior(0, [0.0, 0.0, 0.0])
    for k in range(10):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], np.diag([1000.0, 1e4, 1e4]))
    solver.update()
    return solver, np.diag([100.0, 1e4, 1e4])  # loops: x standard deviation 0.1 m


@pytest.mark.parametrize("regraduate", ["reference", "new"])
@pytest.mark.parametrize("method", ["egnc", "risam"])
def test_a_loop_rejected_early_comes_back_when_later_loops_support_it(method, regraduate):
    solver, information = _chain(method, regraduate=regraduate)
    first = solver.add_loop(0, 10, [10.85, 0.0, 0.0], information)
    solver.update()
    assert first in solver.rejected  # alone it disagrees with the odometry: r^2 about 70
    comeback = None
    for k in range(10):
        solver.add_loop(0, 10, [10.85, 0.0, 0.0], information)
        report = solver.update()
        if first not in solver.rejected:
            comeback = k
            break
    assert comeback is not None and comeback >= 1, "the loop must come back, and not at the very next one"
    assert not report.restarted  # the map bent towards the agreeing loops costs less than the one before
    assert solver.rejected.size == 0
    assert solver.poses[10, 0] > 10.6  # the map followed the loops
    assert solver.result().inliers.all()


@pytest.mark.parametrize("regraduate", ["reference", "new"])
@pytest.mark.parametrize("method", ["egnc", "risam"])
def test_a_false_loop_accepted_early_leaves_when_true_loops_arrive(method, regraduate):
    # The odometry says pose 10 is at x = 10 m; the truth (and the true loops) say 9.8 m.
    solver, true_information = _chain(method, regraduate=regraduate)
    false_information = np.diag([400.0, 1e4, 1e4])  # x standard deviation 0.05 m
    false = solver.add_loop(0, 10, [10.1, 0.0, 0.0], false_information)
    solver.update()
    assert false not in solver.rejected  # at arrival it fits the odometry (r^2 = 4)
    left = None
    for k in range(8):
        solver.add_loop(0, 10, [9.8, 0.0, 0.0], true_information)
        solver.update()
        if left is None and false in solver.rejected:
            left = k
    assert left is not None and left >= 1, "the false loop must leave, and not at the first true loop"
    assert solver.rejected.tolist() == [false]
    assert solver.result().rejected_edges.tolist() == [false]
    assert abs(solver.poses[10, 0] - 9.8) < 0.05


@pytest.mark.parametrize("method", ["egnc", "risam"])
def test_the_last_stage_starts_from_the_map_before_a_loop_that_only_bends_it(method):
    solver, information = _chain(method)
    solver.add_loop(0, 10, [10.05, 0.0, 0.0], information)
    assert not solver.update().restarted  # a loop that fits: the map its first stage bent costs less
    before = solver.poses
    gross = solver.add_loop(0, 10, [13.0, 0.0, 0.0], information)
    report = solver.update()
    # Quadratic at mu = 0 the gross loop pulls pose 10 about 1 m towards itself (r 30 -> 20);
    # weighed at mu = 1 that map costs more than the one before the update, where the last stage
    # starts and stays.
    assert report.residual_history[0, 0] < 0.75 * report.residual_history[-1, 0]
    assert report.restarted and gross in solver.rejected
    assert report.stages[-1].iterations == 1  # from the bent map: 3 (egnc) and 2 (risam)
    np.testing.assert_allclose(solver.poses, before, atol=1e-3)  # the gross loop's Geman-McClure pull


def test_schedules_graduate_new_loops_by_their_own_rule():
    solver, information = _chain("risam")
    solver.add_loop(0, 10, [10.05, 0.0, 0.0], information)
    report = solver.update()
    np.testing.assert_allclose(report.mu_history[:, 0], RISAM_SEQUENCE, atol=1e-12)

    solver, information = _chain("egnc")
    gross = solver.add_loop(0, 10, [13.0, 0.0, 0.0], information)
    report = solver.update()
    assert report.mu_history[:, 0].tolist() == [0.0, 1.0]  # strong after its first stage: skips mu*
    assert gross in solver.rejected

    solver = OnlineSolver(2, "egnc", online_options=OnlineOptions(strong_at_arrival=True))
    solver.add_prior(0, [0.0, 0.0, 0.0])
    for k in range(10):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], np.diag([1000.0, 1e4, 1e4]))
    gross = solver.add_loop(0, 10, [13.0, 0.0, 0.0], information)
    report = solver.update()
    assert report.mu_history[:, 0].tolist() == [1.0]  # strong at arrival: no mu = 0 stage
    assert gross in solver.rejected

    # Stiff odometry (x variance 1e-4 m^2 from pose 0 to 10): the loop's residual hardly shrinks at
    # mu = 0, and r = 2.2 lies between c / sqrt(3) = 1.73 and the strong threshold sqrt(6.25) = 2.5.
    solver = OnlineSolver(2, "egnc")
    solver.add_prior(0, [0.0, 0.0, 0.0])
    for k in range(10):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], np.diag([1e5, 1e4, 1e4]))
    solver.add_loop(0, 10, [10.22, 0.0, 0.0], information)
    report = solver.update()
    # Inside the band: 0, then mu*(r) at the first stage's residual (in (1/2, 1) above c / sqrt(3)), then 1.
    history = report.mu_history[:, 0]
    assert history.shape == (3,) and history[0] == 0.0 and history[2] == 1.0
    assert 0.5 < history[1] < 1.0
    # mu* is the convexity boundary at the residual the first stage left (residual_history).
    assert report.residual_history.shape == report.mu_history.shape
    assert history[1] == pytest.approx(float(mu_star(report.residual_history[0, :1], 3.0)[0]), rel=1e-12)


def _first_stage_residual(solver: OnlineSolver, loop: int) -> float:
    """The residual `r` of `loop` after the pending update's first stage, solved (not predicted)."""
    report = solver.update()
    assert not report.decided_at_arrival and report.new_loops.tolist() == [loop]
    return float(report.residual_history[0, 0])


@pytest.mark.parametrize("linear_solver", ["scipy", "auto"])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_predicted_first_stage_is_the_solved_one(dim, linear_solver):
    """A loop to a pose added after the last solve (hung from the map by its odometry): the first
    stage predicted from the map factorized at the end of that solve equals the solved stage."""
    odometry, information = _square(dim)
    runs = {}
    for decide in (True, False):
        options = OnlineOptions(decide_at_arrival=decide)
        solver = OnlineSolver(dim, "egnc", linear_solver=linear_solver, online_options=options)
        solver.add_prior(0, from_matrices(dim, np.eye(dim + 1)))
        for k in range(3):
            solver.add_odometry(k, k + 1, odometry[k], information)
        solver.add_loop(3, 0, odometry[3], information)
        solver.update()  # solved: the map is factorized at its end
        for k in range(3, 6):  # three poses hung from pose 3 by odometry
            solver.add_odometry(k, k + 1, odometry[k % 4], information)
        solver.update()
        T = to_matrices(dim, solver.poses)
        wrong = np.linalg.inv(T[2]) @ T[6] @ group_of(dim).exp(np.full((1, len(information)), 0.05))[0]
        loop = solver.add_loop(2, 6, from_matrices(dim, wrong[None])[0], information)
        runs[decide] = (solver, loop)
    solver, loop = runs[True]
    predicted = []
    predict = solver._arrival.first_stage
    solver._arrival.first_stage = lambda *args: predicted.append(predict(*args)) or predicted[-1]  # type: ignore[method-assign]
    assert not solver.update().decided_at_arrival
    first = predicted[0]
    assert first is not None
    # To 2 %: the stage re-graduates the older loop to mu = 0 (weight 0.9), the factorized map holds
    # it at its Geman-McClure weight (1 at r = 0).
    assert first.residual_norms[loop] == pytest.approx(_first_stage_residual(*runs[False]), rel=2e-2)
    offset = np.full(len(information), 0.05)
    assert first.residual_norms[loop] < 0.8 * np.sqrt(offset @ information @ offset)  # the stage moved it


def test_a_gross_loop_is_decided_at_arrival_without_a_solve():
    solver, information = _chain("egnc", decide_at_arrival=True)
    solver.add_loop(0, 10, [10.05, 0.0, 0.0], information)
    assert not solver.update().decided_at_arrival  # a loop that fits is graduated
    before = solver.poses
    gross = solver.add_loop(0, 10, [13.0, 0.0, 0.0], information)
    report = solver.update()
    assert report.decided_at_arrival and report.stages == () and report.iterations == 0
    np.testing.assert_array_equal(solver.poses, before)
    assert gross in solver.rejected and solver.mu[gross] == 1.0
    # The same update solved reaches the same map, to the last stage's tolerance.
    solved, _ = _chain("egnc", decide_at_arrival=False)
    solved.add_loop(0, 10, [10.05, 0.0, 0.0], information)
    solved.update()
    solved.add_loop(0, 10, [13.0, 0.0, 0.0], information)
    assert solved.update().iterations > 0 and gross in solved.rejected
    np.testing.assert_allclose(solved.poses, before, atol=1e-3)

    for option in ("decide_at_arrival", "strong_at_arrival"):  # riSAM's schedule has no strong-outlier rule
        with pytest.raises(EgncError, match=f"{option} applies to the egnc schedule"):
            OnlineSolver(2, "risam", online_options=OnlineOptions(**{option: True}))


@pytest.mark.parametrize(("count", "measured", "kept"), [(3, 10.5, True), (1, 11.0, False)])
def test_the_predicted_last_stage_keeps_the_loops_the_solve_keeps(count, measured, kept):
    """Loops strong after their first stage can still hold the map together (three agreeing loops
    3.5 sigma off): the last stage predicted from the first keeps them, as the solve does."""
    solver, information = _chain("egnc", decide_at_arrival=True)
    loops = [solver.add_loop(0, 10, [measured, 0.0, 0.0], information) for _ in range(count)]
    predicted = []
    predict = solver._arrival.first_stage
    solver._arrival.first_stage = lambda *args: predicted.append(predict(*args)) or predicted[-1]  # type: ignore[method-assign]
    report = solver.update()
    first = predicted[0]
    assert report.mu_history[:, 0].tolist() == [0.0, 1.0]  # strong after the first stage
    assert not report.decided_at_arrival
    kernel = solver._settings.kernel
    each = information[None].repeat(count, 0)
    settled = first.last_stage(each, lambda r: kernel.weight(r, np.ones_like(r)), first.residual_norms[loops])
    assert bool(np.all(settled**2 < 6.25)) == kept
    assert bool(np.isin(loops, solver.rejected).any()) != kept


def test_egnc_schedule_takes_fewer_iterations_than_risam_on_the_same_updates():
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(200)
    iterations = {method: int(replay(graph, method).update_iterations.sum()) for method in ("egnc", "risam")}
    assert iterations["egnc"] < iterations["risam"]


@pytest.mark.parametrize(("name", "method"), [("grid2d_outliers", "egnc"), ("grid3d_outliers", "risam")])
def test_replay_decides_like_batch_on_the_shipped_graphs(name, method):
    graph = egnc.read_g2o(DATA / f"{name}.g2o")
    labels, _ = read_labels(DATA / f"{name}.labels.json")
    outcome = replay(graph, method)
    precision, recall = precision_recall(~outcome.result.inliers, labels)
    assert precision == 1.0 and recall == 1.0
    batch = egnc.solve(graph, method)
    np.testing.assert_array_equal(outcome.result.inliers, batch.inliers)
    np.testing.assert_allclose(outcome.result.graph.poses, batch.graph.poses, atol=1e-8)
    # Edges come back in file order: the result's graph is the input's.
    np.testing.assert_array_equal(outcome.result.graph.edges, graph.edges)
    assert outcome.steps == len(replay_steps(graph, graph.is_odometry))
    assert outcome.update_ms.shape == (outcome.steps,)


def test_replay_of_csail_with_30_percent_false_loops(dataset_path):
    graph = egnc.read_g2o(dataset_path("csail.g2o"))
    reference = egnc.solve(graph, "l2").graph.poses
    corrupted = add_false_loops(graph, 30, seed=0, reference_poses=reference)
    outcome = replay(corrupted.graph, "egnc")
    precision, recall = precision_recall(~outcome.result.inliers, corrupted.is_outlier)
    assert precision >= 0.99 and recall >= 0.99
    # Most updates only extend the trajectory and cost nothing.
    assert np.count_nonzero(outcome.update_iterations == 0) > 0.5 * outcome.steps


@pytest.mark.skipif(not cholmod_available(), reason="scikit-sparse (CHOLMOD) not installed")
def test_both_linear_backends_give_the_same_online_estimate():
    estimates = []
    for backend in ("cholmod", "scipy"):
        solver, information = _chain("egnc", backend)
        assert solver.linear_solver == backend
        solver.add_loop(0, 10, [10.2, 0.0, 0.0], information)
        solver.add_loop(2, 9, [7.5, 0.0, 0.0], information)
        solver.update()
        estimates.append(solver.poses)
    np.testing.assert_allclose(estimates[0], estimates[1], atol=1e-9)


@pytest.mark.parametrize("decide_at_arrival", [False, True])
def test_checkpoint_and_resume_give_the_uninterrupted_result(tmp_path, decide_at_arrival):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(150)
    options = OnlineOptions(decide_at_arrival=decide_at_arrival)
    whole = replay(graph, "egnc", online_options=options)
    path = tmp_path / "state.npz"
    first = replay(graph, "egnc", checkpoint=path, checkpoint_every=7, stop_after=60, online_options=options)
    assert first.steps == 60 and path.exists()
    decided: list[bool] = []
    resumed = replay(
        graph,
        "egnc",
        checkpoint=path,
        checkpoint_every=7,
        online_options=options,
        on_step=lambda step, total, report: decided.append(report.decided_at_arrival),
    )
    assert resumed.resumed_from == 60 and resumed.steps == whole.steps
    assert any(decided) == decide_at_arrival  # updates decided at arrival after the resume
    np.testing.assert_allclose(resumed.result.graph.poses, whole.result.graph.poses, atol=1e-9, rtol=0)
    np.testing.assert_array_equal(resumed.result.inliers, whole.result.inliers)
    np.testing.assert_array_equal(resumed.update_iterations, whole.update_iterations)
    with pytest.raises(EgncError, match="another graph"):
        replay(graph.first_poses(149), "egnc", checkpoint=path, online_options=options)
    with pytest.raises(EgncError, match=r"method 'egnc' \(this run: 'risam'\)"):
        replay(graph, "risam", checkpoint=path, online_options=options)
    with pytest.raises(EgncError, match=r"region_hops 8 \(this run: None\)"):
        replay(graph, "egnc", checkpoint=path, online_options=replace(options, region_hops=None))
    with pytest.raises(EgncError, match="decide_at_arrival"):
        replay(graph, "egnc", checkpoint=path, online_options=replace(options, decide_at_arrival=not decide_at_arrival))


def test_a_checkpoint_from_before_decide_at_arrival_and_boundary_share_resumes(tmp_path):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(60)
    path = tmp_path / "old.npz"
    first = replay(graph, "egnc", checkpoint=path, stop_after=30)
    solver, meta = OnlineSolver.load(path)
    del meta["decide_at_arrival"], meta["boundary_share"]  # as written before the options existed
    solver.save(path, meta=meta)
    resumed = replay(graph, "egnc", checkpoint=path)
    assert first.steps == 30 and resumed.resumed_from == 30
    np.testing.assert_array_equal(resumed.result.inliers, replay(graph, "egnc").result.inliers)


def test_save_and_load_keep_every_number(tmp_path):
    solver, information = _chain("risam")
    solver.add_loop(0, 10, [10.3, 0.0, 0.0], information)
    solver.update()
    solver.save(tmp_path / "s.npz", meta={"note": "x"})
    loaded, meta = OnlineSolver.load(tmp_path / "s.npz")
    assert meta == {"note": "x"} and loaded.method == "risam" and loaded.steps == solver.steps
    np.testing.assert_array_equal(loaded.poses, solver.poses)
    np.testing.assert_array_equal(loaded.mu, solver.mu)
    for s in (solver, loaded):
        s.add_loop(1, 8, [7.2, 0.0, 0.0], information)
        s.update()
    np.testing.assert_array_equal(loaded.poses, solver.poses)
    with pytest.raises(EgncError, match="cannot read the checkpoint"):
        OnlineSolver.load(tmp_path / "missing.npz")


def test_the_loop_indices_follow_the_loop_closures_through_growth_and_a_checkpoint(tmp_path):
    # Updates test and reset the loops by their indices (MapState.loops): they must be
    # exactly the loop closures, however edges arrive and after a load.
    solver, information = _chain("egnc")
    for k in range(10, 120):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], information)
        if k % 7 == 0:
            solver.add_loops([[k + 1, k - 5], [k + 1, 3]], [[-6.0, 0.0, 0.0], [2.0, 1.0, 0.0]], [information] * 2)
        solver.update()
        np.testing.assert_array_equal(solver._map.loops, np.flatnonzero(solver.is_loop_closure))
    solver.save(tmp_path / "s.npz")
    loaded, _ = OnlineSolver.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(loaded._map.loops, solver._map.loops)
    for s in (solver, loaded):
        s.add_odometry(120, 121, [1.0, 0.0, 0.0], information)
        s.add_loop(121, 110, [11.0, 0.0, 0.0], information)
        s.update()
    np.testing.assert_array_equal(loaded._map.loops, np.flatnonzero(loaded.is_loop_closure))
    np.testing.assert_array_equal(loaded.poses, solver.poses)


def test_a_loaded_solver_predicts_from_the_same_factorized_map(tmp_path):
    solver, information = _chain("egnc", decide_at_arrival=True)
    solver.add_loop(0, 10, [10.05, 0.0, 0.0], information)
    solver.update()
    for k in range(10, 13):  # poses hung from the factorized map
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], np.diag([1000.0, 1e4, 1e4]))
    solver.update()
    solver.save(tmp_path / "s.npz")
    loaded, _ = OnlineSolver.load(tmp_path / "s.npz")
    predictions = []
    for s in (solver, loaded):
        predict = s._arrival.first_stage
        s._arrival.first_stage = lambda *args, predict=predict: predictions.append(predict(*args)) or predictions[-1]  # type: ignore[method-assign]
        s.add_loop(2, 13, [14.0, 0.0, 0.0], information)
        assert s.update().decided_at_arrival
    np.testing.assert_array_equal(predictions[0].residual_norms, predictions[1].residual_norms)
    np.testing.assert_array_equal(predictions[0].map_covariance, predictions[1].map_covariance)
    np.testing.assert_array_equal(loaded.poses, solver.poses)


def test_poses_may_arrive_in_any_id_order():
    """A front-end's ids need not grow (several robots, re-used numbering): nothing assumes it."""
    information = np.diag([100.0, 100.0, 400.0])
    solver = OnlineSolver(2, "egnc")
    solver.add_prior(10, [0.0, 0.0, 0.0])
    solver.add_odometry(10, 5, [1.0, 0.0, 0.0], information)
    solver.add_odometry(5, 7, [1.0, 0.0, 0.0], information)
    solver.add_loop(10, 7, [2.1, 0.0, 0.0], information)
    report = solver.update()
    assert report.iterations > 0 and solver.vertex_ids.tolist() == [10, 5, 7]
    assert 2.0 < solver.poses[2, 0] < 2.1  # pose 7, pulled towards the loop
    result = solver.result()
    assert result.graph.vertex_ids.tolist() == [5, 7, 10] and result.inliers.all()
    np.testing.assert_allclose(result.graph.poses[:, 0], [2.1 / 2.0, 2.1, 0.0], atol=0.05)


@pytest.mark.parametrize("decide_at_arrival", [False, True])
def test_an_update_may_bring_poses_without_edges(decide_at_arrival):
    solver = OnlineSolver(2, "egnc", online_options=OnlineOptions(decide_at_arrival=decide_at_arrival))
    solver.add_prior(3, [0.0, 0.0, 0.0])
    solver.add_pose(4, [1.0, 0.0, 0.0])
    report = solver.update()  # nothing joins them yet: nothing to solve
    assert report.stages == () and solver.num_edges == 0
    np.testing.assert_array_equal(solver.poses[:, 0], [0.0, 1.0])
    loop = solver.add_loop(3, 4, [1.2, 0.0, 0.0], np.diag([100.0, 100.0, 400.0]))
    solver.update()  # the only edge: pose 4 moves onto it
    assert loop not in solver.rejected and solver.poses[1, 0] == pytest.approx(1.2, abs=1e-6)


def test_inputs_are_checked():
    solver = OnlineSolver(2, "egnc")
    solver.add_prior(0, [0.0, 0.0, 0.0])
    with pytest.raises(GraphError, match="not known"):
        solver.add_loop(0, 5, [1.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(GraphError, match="two unknown"):
        solver.add_odometry(4, 5, [1.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(GraphError, match="positive definite"):
        solver.add_odometry(0, 1, [1.0, 0.0, 0.0], -np.eye(3))
    with pytest.raises(GraphError, match="second prior"):
        solver.add_prior(0, [0.0, 0.0, 0.0])
    solver.add_odometry(0, 1, [1.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(EgncError, match="update"):
        solver.result()
    with pytest.raises(EgncError, match="online method"):
        OnlineSolver(2, "gnc-gm")
    with pytest.raises(EgncError, match="rel_cost_tol"):
        OnlineOptions(rel_cost_tol=1.0)


def test_odometry_updates_append_to_the_map_in_place():
    # An update that only extends the trajectory writes its rows into room kept at the end of
    # each array: the map is not copied, so its cost does not grow with the map.
    solver, information = _chain("egnc")
    buffers = set()
    for k in range(10, 400):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.001], information)
        assert solver.update().iterations == 0
        buffers.add(solver._map.T.__array_interface__["data"][0])
        assert np.shares_memory(solver._map.edges, solver._map.buffers["edges"])
    # 390 updates, arrays grown by an eighth when full: a new buffer every few dozen updates.
    assert len(buffers) <= 30
    # The poses are those of the composed odometry: pose k turned 0.001 rad per step after pose 10.
    np.testing.assert_allclose(solver.poses[10:, 2], 0.001 * np.arange(391), atol=1e-12)
    # A loop closure after them still solves, and fits.
    T = to_matrices(2, solver.poses)
    measurement = from_matrices(2, (np.linalg.inv(T[400]) @ T[395])[None])[0] + [0.01, 0.0, 0.0]
    solver.add_loop(400, 395, measurement, information)
    assert solver.update().iterations > 0 and not len(solver.rejected)


def test_options_and_arguments_of_the_wrong_kind_fail_at_once_naming_them(tmp_path):
    with pytest.raises(OptionError, match=r"OnlineOptions.region_hops must be an integer, got 2.5"):
        OnlineOptions(region_hops=2.5)  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="OnlineOptions.strong_at_arrival must be True or False"):
        OnlineOptions(strong_at_arrival=1)  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="low_quantile < OnlineOptions.high_quantile"):
        OnlineOptions(high_quantile=0.1)
    with pytest.raises(OptionError, match="options must be a SolverOptions, got int"):
        OnlineSolver(2, options=0)  # type: ignore[arg-type]
    with pytest.raises(OptionError, match=r"dim must be 2 or 3, got an array of dtype float64 and shape \(2, 2\)"):
        OnlineSolver(np.zeros((2, 2)))  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="linear_solver must be a backend name"):
        OnlineSolver(2, linear_solver=np.zeros(3))  # type: ignore[arg-type]
    solver = OnlineSolver(np.int64(2))  # type: ignore[arg-type]
    assert type(solver.dim) is int and solver.dim == 2
    solver.add_prior(np.int32(0), [0.0, 0.0, 0.0])  # type: ignore[arg-type]
    with pytest.raises(GraphError, match=r"measurements must be numbers of shape \(1, 3\)"):
        solver.add_odometry(0, 1, "x", np.eye(3))  # type: ignore[arg-type]
    with pytest.raises(GraphError, match="vertex ids must be integers"):
        solver.add_odometry([0, 1], 2, [1.0, 0.0, 0.0], np.eye(3))  # type: ignore[arg-type]
    with pytest.raises(GraphError, match="edge ids come in pairs, got 3"):
        solver.add_loops([0, 1, 2], [[1.0, 0.0, 0.0]], [np.eye(3)])
    solver.add_odometry(0, 1, [1.0, 0.0, 0.0], np.eye(3))
    solver.update()
    with pytest.raises(OptionError, match="decide must be True or False"):
        solver.result(decide="no")  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="meta must hold only JSON data"):
        solver.save(tmp_path / "state.npz", meta={"a": object()})
    assert not (tmp_path / "state.npz").exists()
    with pytest.raises(OptionError, match="path must be a file path, got int"):
        OnlineSolver.load(3)  # type: ignore[arg-type]


def test_quaternions_that_do_not_normalize_are_refused_when_added():
    solver = OnlineSolver(3, "egnc")
    zero, identity = [0.0] * 7, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    with pytest.raises(GraphError, match="prior pose: quaternion"):
        solver.add_prior(0, zero)
    solver.add_prior(0, identity)
    with pytest.raises(GraphError, match="poses row 1: quaternion"):
        solver.add_poses([1, 2], [identity, zero])
    with pytest.raises(GraphError, match="measurements: quaternion"):
        solver.add_odometry(0, 1, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], np.eye(6))
    # Nothing of the refused calls was taken in: the next update holds the prior's pose alone.
    solver.update()
    assert solver.num_poses == 1 and solver.num_edges == 0


def test_result_keeps_the_decision_of_lower_truncated_cost(monkeypatch):
    # The decision from the online estimate is replaced by one that keeps a false loop and drops the
    # true one (what a map bent early can give on large graphs); the batch solve from odometry sees
    # both loops at once, its truncated cost is lower, and result() keeps it.
    solver, information = _chain("egnc")
    false = solver.add_loop(0, 10, [7.0, 0.0, 0.0], information)
    true = solver.add_loop(0, 10, [10.0, 0.0, 0.0], information)
    solver.update()
    factors, robust = solver._map.factors(), solver.is_loop_closure
    wrong = np.ones(solver.num_edges, dtype=bool)
    wrong[true] = False
    bent = solver.result(decide=False).graph.poses.copy()
    bent[:, 0] *= 0.7  # the map the false loop alone explains
    bent_T = to_matrices(2, bent)
    r = factors.whitened_norms(factors.residuals(bent_T))
    bent_cost = truncated_cost(r, robust, 3, solver.gnc_options.outlier_quantile)
    monkeypatch.setattr(
        egnc.online.result, "decide_outliers", lambda *args, **kwargs: Decision(bent_T, wrong, (), True, bent_cost)
    )
    result = solver.result()
    assert "batch solve" in result.message and result.start in ("guess", "chordal")
    assert result.rejected_edges.tolist() == [false]
    assert result.truncated_cost < bent_cost
    assert abs(result.graph.poses[10, 0] - 10.0) < 0.05

    monkeypatch.undo()  # the real decision from the online estimate is right here: it is kept
    kept = solver.result()
    assert kept.start == "online" and kept.rejected_edges.tolist() == [false]


def test_result_keeps_the_online_decision_where_the_batch_one_is_lower_by_rounding_only(monkeypatch):
    # Both starts reach the same decision; the online one is made to cost a relative 1e-12 more
    # (rounding), and it stays.
    solver, information = _chain("egnc")
    false = solver.add_loop(0, 10, [7.0, 0.0, 0.0], information)
    solver.add_loop(0, 10, [10.0, 0.0, 0.0], information)
    solver.update()
    decide = egnc.online.result.decide_outliers

    def a_rounding_above(*args, **kwargs):
        decision = decide(*args, **kwargs)
        return replace(decision, truncated_cost=decision.truncated_cost * (1 + 1e-12))

    monkeypatch.setattr(egnc.online.result, "decide_outliers", a_rounding_above)
    kept = solver.result()
    assert kept.start == "online" and kept.rejected_edges.tolist() == [false]


def test_local_updates_reach_the_whole_map_estimate_and_solve_less():
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o")
    outcomes, loop_updates = {}, []
    for hops in (8, None):

        def on_step(step, total, report, hops=hops):
            if hops is not None and len(report.new_loops):
                loop_updates.append((report.region_poses, report.whole_map, report.stages[0].active_edges))

        outcomes[hops] = replay(graph, "egnc", online_options=OnlineOptions(region_hops=hops), on_step=on_step)
    local, whole = outcomes[8].solver, outcomes[None].solver
    # Loop updates start on a region of the 500 poses; on this small lattice most are then judged
    # on the whole map (a loop crossed the strong-outlier line, or the boundary pulled), and more
    # than a fifth finish in their region alone.
    region_poses, whole_map, first_edges = np.array(loop_updates).T
    assert np.median(region_poses) < 0.2 * graph.num_poses and np.median(first_edges) < 0.3 * graph.num_edges
    assert 0.2 * len(whole_map) < np.count_nonzero(whole_map == 0) < len(whole_map)
    # Both end each update at the last stage's tolerance (rel_cost_tol), from starts a region
    # and the whole map choose apart (the map before the update, or the bent one): with the same
    # mu, each is within that tolerance of the optimum both reach when converged.
    np.testing.assert_array_equal(local.mu, whole.mu)
    np.testing.assert_array_equal(local.inliers, whole.inliers)
    loss = KernelLoss(make_kernel("sig", c=3.0), local.mu, local.is_loop_closure)
    graph_now = whole.result(decide=False).graph
    optimum = solve_least_squares(
        Problem.from_graph(graph_now), to_matrices(2, whole.poses), loss, SolverOptions(rel_cost_tol=1e-12)
    )
    for solver in (local, whole):
        cost = float(np.sum(loss.cost(solver.residual_norms)))
        assert optimum.cost <= cost <= (1 + OnlineOptions().rel_cost_tol) * optimum.cost
    np.testing.assert_allclose(to_matrices(2, local.poses), to_matrices(2, whole.poses), atol=2e-3)
    np.testing.assert_array_equal(outcomes[8].result.inliers, outcomes[None].result.inliers)


def test_a_larger_boundary_share_finishes_more_updates_in_their_region_with_the_same_decision(tmp_path):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o")
    outcomes, pulled = {}, {}
    for share in (OnlineOptions().boundary_share, 0.5):
        reports: list = []
        options = OnlineOptions(boundary_share=share)
        keep = reports.append
        outcomes[share] = replay(graph, "egnc", online_options=options, on_step=lambda *step, keep=keep: keep(step[2]))
        # Updates that started in a region and went on to the whole map (the boundary pulled, or a crossing).
        pulled[share] = sum(report.region_poses > 0 and report.whole_map for report in reports)
    default, loose = outcomes[OnlineOptions().boundary_share], outcomes[0.5]
    assert pulled[0.5] < pulled[OnlineOptions().boundary_share]
    np.testing.assert_array_equal(loose.result.inliers, default.result.inliers)
    with pytest.raises(OptionError, match="OnlineOptions.boundary_share"):
        OnlineOptions(boundary_share=1.5)
    # A checkpoint keeps its share: a run asked to resume with another is refused.
    path = tmp_path / "state.npz"
    replay(graph, "egnc", checkpoint=path, stop_after=20, online_options=OnlineOptions(boundary_share=0.5))
    with pytest.raises(EgncError, match=r"boundary_share 0.5 \(this run: 0.001\)"):
        replay(graph, "egnc", checkpoint=path)


def test_region_hops_is_checked():
    with pytest.raises(EgncError, match="region_hops"):
        OnlineOptions(region_hops=0)


def _chain_of_60(hops: int | None, odometry_information: float, loop_length: float = 18.0) -> OnlineSolver:
    """Sixty poses 1 m apart along x, and a loop 22 -> 40 measuring `loop_length` m (true at 18 m);
    each update solved around its change."""
    solver = OnlineSolver(2, "egnc", online_options=OnlineOptions(region_hops=hops))
    solver.add_prior(0, [0.0, 0.0, 0.0])
    for k in range(59):
        solver.add_odometry(k, k + 1, [1.0, 0.0, 0.0], np.diag([1.0, 1.0, 10.0]) * odometry_information)
    solver.update()
    solver.add_loop(22, 40, [loop_length, 0.0, 0.0], np.diag([100.0, 100.0, 400.0]))
    solver.update()
    return solver


def _loop_22_59(hops: int | None, odometry_information: float, measured: float, loop_information: float):
    """`_chain_of_60`, then a loop 22 -> 59 measuring `measured` m: its update's report and the poses after it."""
    solver = _chain_of_60(hops, odometry_information)
    solver.add_loop(22, 59, [measured, 0.0, 0.0], np.diag([1.0, 1.0, 4.0]) * loop_information)
    return solver.update(), to_matrices(2, solver.poses)


def test_a_region_that_would_strain_the_map_falls_back_to_the_whole_map():
    # A loop 22 -> 59 that disagrees a little with the odometry (37 m): one hop around its ends cannot take it.
    (local, local_poses), (whole, whole_poses) = (_loop_22_59(hops, 1000.0, 36.8, 100.0) for hops in (1, None))
    assert whole.region_poses == 0 and whole.whole_map and all(stage.active_edges == 61 for stage in whole.stages)
    # One trusted hop from 22 and 59: 21, 23, 40 (by the true loop) and 58.
    assert local.region_poses == 6 and local.whole_map and local.stages[0].active_edges == 10
    # The boundary still pulled on the rest: the whole map took the last stage on from the region's optimum.
    whole_map_stages = [stage for stage in local.stages if stage.active_edges == 61]
    assert len(whole_map_stages) == 1 and local.stages[-1].active_edges == 61
    np.testing.assert_allclose(local_poses, whole_poses, atol=1e-3)


def test_a_region_update_reports_the_whole_map_cost_where_loops_outside_it_regraduate():
    # A loop 2 -> 10 that fits (8.5 m against 8 m of odometry) has mu_init = 0, so the update of
    # a new loop 22 -> 59 graduates it too (regraduate="reference"): its mu moves 0 -> mu* -> 1
    # while the region, one hop around 22 and 59, leaves its poses where they are. The stages
    # write only the region's rows and keep the whole map's costs current where they change;
    # the last stage's cost is the whole map's at the end, the loop 2 -> 10 at mu = 1 included.
    solver = _chain_of_60(1, 100.0)
    solver.add_loop(2, 10, [8.5, 0.0, 0.0], np.diag([100.0, 100.0, 400.0]))
    solver.update()
    poses_before = solver.poses
    solver.add_loop(22, 59, [35.0, 0.0, 0.0], np.diag([1.0, 1.0, 4.0]) * 1e4)
    report = solver.update()
    assert report.region_poses == 6 and not report.whole_map and report.restarted
    outside = int(np.flatnonzero((solver.edge_ids == [2, 10]).all(axis=1))[0])
    assert report.graduated == 3 and solver.mu[outside] == 1.0 and solver.residual_norms[outside] > 0.3
    np.testing.assert_array_equal(solver.poses[:20], poses_before[:20])  # outside the region
    loss = KernelLoss(make_kernel("sig", c=3.0), solver.mu, solver.is_loop_closure)
    np.testing.assert_allclose(report.stages[-1].cost, loss.cost(solver.residual_norms).sum(), rtol=1e-12)


def test_a_new_loop_past_the_strong_outlier_line_on_arrival_is_decided_in_its_region():
    # The loop disagrees by 2 m at 0.01 m: r = 200 before anything is solved. Its mu = 0 stage bends
    # the region, the last stage starts from the map before the update, and it ends past the line
    # where it arrived: no loop changed sides, and the region alone decides.
    (local, local_poses), (whole, whole_poses) = (_loop_22_59(hops, 100.0, 35.0, 1e4) for hops in (1, None))
    assert local.region_poses == 6 and not local.whole_map
    assert [stage.active_edges for stage in local.stages] == [10, 10]
    assert local.restarted and whole.restarted
    line = chi2.ppf(OnlineOptions().high_quantile, 3)
    assert local.residual_history[-1, 0] ** 2 > line and whole.residual_history[-1, 0] ** 2 > line
    # What is left of the loop's Geman-McClure pull moves six poses or all of them, by a fraction of a millimetre.
    np.testing.assert_allclose(local_poses, whole_poses, atol=1e-3)


def test_an_older_loop_a_region_pushes_past_the_line_sends_the_update_to_the_whole_map(tmp_path):
    # The loop 22 -> 40 measures 18.4 m against 18 m of stiff odometry: it sits just inside the
    # strong-outlier line. A new loop 22 -> 59, 0.3 m shorter than the map, pulls 22 towards 59;
    # held one hop around its ends, the region takes that from the loop 22 -> 40 and pushes it past.
    solver = _chain_of_60(1, 1000.0, loop_length=18.4)
    line = chi2.ppf(OnlineOptions().high_quantile, 3)
    assert solver.residual_norms[59] ** 2 < line
    solver.save(tmp_path / "state.npz")
    local, _ = OnlineSolver.load(tmp_path / "state.npz")
    whole, _ = OnlineSolver.load(tmp_path / "state.npz")
    whole.online_options = replace(whole.online_options, region_hops=None)
    span = solver.poses[59, 0] - solver.poses[22, 0]
    for each in (local, whole):
        each.add_loop(22, 59, [span - 0.3, 0.0, 0.0], np.diag([1.0, 1.0, 4.0]) * 100.0)
    local_report, whole_report = local.update(), whole.update()
    # Three stages in the region, then the update redone on the whole map from its start, exactly
    # as the whole map solves it.
    assert local_report.region_poses == 6 and local_report.whole_map
    edges = [stage.active_edges for stage in local_report.stages]
    assert edges[:3] == [10, 10, 10] and edges[3:] == [stage.active_edges for stage in whole_report.stages]
    np.testing.assert_array_equal(local.poses, whole.poses)
    assert local.residual_norms[59] ** 2 > line


def started_2d() -> OnlineSolver:
    """A 2D solver with a prior on pose 0 and odometry to poses 1 and 2, updated."""
    solver = OnlineSolver(2)
    solver.add_prior(0, [0.0, 0.0, 0.0])
    solver.add_odometry_batch([[0, 1], [1, 2]], [[1.0, 0.0, 0.0]] * 2, [np.eye(3)] * 2)
    solver.update()
    return solver


def test_empty_batches_add_nothing():
    """Issue 56: `add_loops([], [], [])` was refused as "vertex ids must be integers, got float64"."""
    solver = started_2d()
    assert solver.add_loops([], [], []).tolist() == []
    assert solver.add_odometry_batch(np.zeros((0, 2), dtype=int), np.zeros((0, 3)), np.zeros((0, 3, 3))).tolist() == []
    solver.add_poses([], [])
    solver.add_poses([])
    report = solver.update()
    assert (report.new_poses, len(report.new_edges), solver.num_poses, solver.num_edges) == (0, 0, 3, 2)
    assert solver.add_loop(0, 2, [2.0, 0.0, 0.0], np.eye(3)) == 2


def test_ids_outside_int64_are_named_so():
    """Issue 56: `add_loop(2**63, ...)` was refused as "vertex ids must be integers, got float64"."""
    solver = started_2d()
    calls = (
        lambda: solver.add_loop(2**63, 0, [1.0, 0.0, 0.0], np.eye(3)),
        lambda: solver.add_pose(2**64),
        lambda: solver.add_loops(np.array([[2**63, 0]], dtype=np.uint64), [[1.0, 0.0, 0.0]], [np.eye(3)]),
    )
    for call in calls:
        with pytest.raises(GraphError, match=r"^vertex ids?: \d+ is outside int64"):
            call()
    with pytest.raises(GraphError, match="^vertex ids must be integers, got float64"):
        solver.add_loops([[0.0, 2.0]], [[1.0, 0.0, 0.0]], [np.eye(3)])


@pytest.mark.parametrize(
    "entry",
    ["loop measurement", "loop information", "odometry measurement", "odometry information", "far pose"],
)
def test_an_absurd_but_finite_entry_is_refused_at_add_not_in_update(entry):
    """Issue 56: a measurement of 1e300 or information of 1e300 I was taken in, and the update failed."""
    solver = started_2d()
    far, sure = [1e300, 0.0, 0.0], 1e300 * np.eye(3)
    with pytest.raises(egnc.NumericalError, match="cannot be represented in double precision"):
        if entry == "loop measurement":
            solver.add_loop(0, 2, far, np.eye(3))
        elif entry == "loop information":
            solver.add_loop(0, 2, [2.0, 0.0, 0.0], sure)
        elif entry == "odometry measurement":
            solver.add_odometry(2, 3, far, np.eye(3))
        elif entry == "odometry information":
            solver.add_odometry(2, 3, [1.0, 0.0, 0.0], sure)
        else:
            solver.add_pose(3, far)
            solver.add_odometry(2, 3, [1.0, 0.0, 0.0], np.eye(3))
    solver.add_odometry(2, 4, [1.0, 0.0, 0.0], np.eye(3))  # what was refused left nothing behind
    solver.add_loop(4, 0, [-3.0, 0.0, 0.0], np.eye(3))
    report = solver.update()
    assert report.status in (1, 2, 3) and np.isfinite(solver.poses).all()


def test_a_prior_that_moves_the_map_out_of_double_precision_is_refused():
    solver = OnlineSolver(2)
    solver.add_pose(0, [0.0, 0.0, 0.0])
    solver.add_odometry(0, 1, [1.0, 0.0, 0.0], np.eye(3))
    solver.update()
    with pytest.raises(egnc.NumericalError, match="^prior on pose 0: moved onto it, the map cannot be represented"):
        solver.add_prior(0, [1e300, 0.0, 0.0])
    solver.add_prior(0, [5.0, 0.0, 0.0])
    solver.update()
    np.testing.assert_allclose(solver.poses[:, 0], [5.0, 6.0])


def _graph_from(edges: list[tuple[int, int]], num_poses: int, fixed: int | None = None) -> egnc.PoseGraph:
    """A 2D graph on poses `0..num_poses-1` along the x axis, with unit steps measured exactly."""
    ids = np.array(edges)
    measurements = np.zeros((len(edges), 3))
    measurements[:, 0] = ids[:, 1] - ids[:, 0]
    is_fixed = np.zeros(num_poses, dtype=bool)
    if fixed is not None:
        is_fixed[fixed] = True
    return egnc.PoseGraph(
        dim=2,
        vertex_ids=np.arange(num_poses),
        poses=np.column_stack((np.arange(num_poses, dtype=float), np.zeros((num_poses, 2)))),
        edges=ids,
        measurements=measurements,
        information=np.tile(np.eye(3), (len(edges), 1, 1)),
        fixed=is_fixed,
        edge_lines=np.arange(len(edges)) + 4,
    )


@pytest.mark.parametrize(
    ("edges", "fixed"),
    [
        ([(0, 2), (2, 1)], None),  # pose 2 first reached by a loop closure, pose 1 then by odometry from it
        ([(0, 1), (1, 2)], 2),  # the gauge (a prior) on the last pose
        ([(0, 1), (2, 3), (1, 4), (3, 4)], None),  # edge (2, 3) waits until loop (1, 4) places pose 4
        ([(1, 0), (0, 3), (3, 2), (2, 1)], 3),  # odometry in an order that reaches pose 1 last
    ],
)
def test_a_replay_places_poses_from_whatever_edge_reaches_a_known_one(edges, fixed):
    graph = _graph_from(edges, 1 + max(max(edge) for edge in edges), fixed)
    outcome = replay(graph, "egnc")
    batch = egnc.solve(graph, "egnc")
    np.testing.assert_array_equal(outcome.result.inliers, batch.inliers)
    np.testing.assert_allclose(outcome.result.graph.poses, batch.graph.poses, atol=1e-9)
    # Loop closures stay loop closures, whichever edge placed a pose.
    assert outcome.solver.is_loop_closure.sum() == (~graph.is_odometry).sum()
    assert outcome.steps == len(replay_steps(graph, graph.is_odometry))


def test_a_replay_of_edges_that_reach_their_poses_in_order_keeps_one_step_per_later_pose():
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o")
    known = graph.is_odometry
    later = graph.edges.max(axis=1)
    order = np.lexsort((np.arange(graph.num_edges), ~known, later))
    expected = np.split(order, np.flatnonzero(np.diff(later[order])) + 1)
    plan = replay_plan(graph, known)
    assert len(plan) == len(expected)
    for step, edges in zip(plan, expected):
        np.testing.assert_array_equal(step.edges, edges)
        assert not len(step.loop_placed)


def test_a_replay_refuses_edges_no_path_joins_to_the_gauge_naming_their_line():
    graph = _graph_from([(0, 1), (2, 3)], 4)
    with pytest.raises(GraphError, match=r"line 5: edge \(2, 3\) has no path of edges to the gauge pose 0"):
        replay(graph, "egnc")


def test_a_pose_added_without_a_value_is_placed_along_a_loop_when_no_odometry_reaches_it():
    solver, information = _chain("egnc")
    solver.add_pose(100)
    solver.add_loop(3, 100, [0.5, 0.0, 0.0], information)
    solver.add_odometry(100, 101, [1.0, 0.0, 0.0], information)
    solver.update()
    poses = dict(zip(solver.vertex_ids.tolist(), solver.poses))
    np.testing.assert_allclose(poses[100], poses[3] + [0.5, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(poses[101], poses[3] + [1.5, 0.0, 0.0], atol=1e-12)
    assert solver.is_loop_closure.sum() == 1


def test_on_update_sees_every_update_and_changes_nothing():
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(60)
    seen = []
    watched = replay(graph, on_update=lambda solver, report: seen.append((solver.num_poses, report.step)))
    plain = replay(graph)
    assert [step for _, step in seen] == list(range(1, plain.steps + 1))
    assert seen[-1][0] == 60
    np.testing.assert_array_equal(watched.result.graph.poses, plain.result.graph.poses)
    np.testing.assert_array_equal(watched.solver.positions, plain.solver.poses[:, :2])
    with pytest.raises(OptionError, match="on_update"):
        OnlineSolver(2, on_update=3)
