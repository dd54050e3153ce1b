"""Robust solves: schedules step by step, and outlier rejection on generated grid worlds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from egnc.api import solve
from egnc.datasets import add_false_loops, grid_world
from egnc.errors import EgncError
from egnc.robust.gnc import (
    CHAINED_STAGE_TOL,
    RESTARTED_STAGE_TOL,
    GncOptions,
    classify_inliers,
    known_inlier_mask,
    stage_tolerance,
)
from egnc.robust.kernels import gnc_barc2
from egnc.robust.mu_star import mu_star
from egnc.robust.schedules import (
    FIXED_LAST_STAGE_METHODS,
    GRADUATED_METHODS,
    METHODS,
    EgncSchedule,
    RisamSchedule,
    YangGncSchedule,
    make_schedule,
)


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def corrupted_world(request):
    """A grid world with 30% false loop closures and its clean least-squares optimum."""
    dim = request.param
    world = grid_world(dim, 200, seed=11, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    corrupted = add_false_loops(world.graph, 30, seed=12, reference_poses=clean.graph.poses)
    return dim, clean, corrupted


@pytest.mark.parametrize("method", ["egnc", "risam", "gnc-tls"])
def test_graduated_methods_recover_the_clean_optimum(corrupted_world, method):
    dim, clean, corrupted = corrupted_world
    result = solve(corrupted.graph, method)
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
    error = np.abs(result.graph.poses[:, :dim] - clean.graph.poses[:, :dim]).max()
    assert error < 1e-6


def test_least_squares_is_corrupted_by_false_loops(corrupted_world):
    dim, clean, corrupted = corrupted_world
    result = solve(corrupted.graph, "l2")
    error = np.abs(result.graph.poses[:, :dim] - clean.graph.poses[:, :dim]).max()
    assert error > 0.1
    assert result.inliers.all()  # plain least squares rejects nothing


@pytest.mark.parametrize("d", [3, 6])
def test_outlier_report_conventions(d):
    q = chi2.ppf(0.95, d)
    r = np.array([0.5 * np.sqrt(q), 0.5 * (np.sqrt(q) + q), 2.0 * q, 2.0 * q])
    robust = np.array([True, True, True, False])
    squared = classify_inliers(r, robust, d, GncOptions())  # the default: DESIGN.md section 4
    distance = classify_inliers(r, robust, d, GncOptions(outlier_threshold="distance"))
    np.testing.assert_array_equal(squared, [True, False, False, True])
    np.testing.assert_array_equal(distance, [True, True, False, True])


def test_result_reports_per_edge_diagnostics(corrupted_world):
    _, _, corrupted = corrupted_world
    result = solve(corrupted.graph, "egnc")
    graph = corrupted.graph
    assert result.residual_norms.shape == result.weights.shape == result.mu.shape == (graph.num_edges,)
    np.testing.assert_array_equal(result.known_inliers, graph.is_odometry)
    assert np.all(result.inliers[graph.is_odometry])
    assert np.all(np.isnan(result.mu[graph.is_odometry]))
    np.testing.assert_array_equal(result.mu[graph.is_loop_closure], 1.0)  # egnc ends at mu = 1
    assert np.all((result.weights >= 0) & (result.weights <= 1))
    np.testing.assert_array_equal(result.rejected_edges, np.flatnonzero(corrupted.is_outlier))
    # Restarted stages: only the last (mu = 1) is solved, then the least-squares refinement.
    # The GNC stage and one decision round (the start kept is the GNC stage's own), then the
    # chordal start's probe.
    assert [stage.kind for stage in result.stages][:2] == ["gnc", "decision"] and result.start == result.stages[0].start
    assert result.stages[0].mu_min == 1.0 and np.isnan(result.stages[1].mu_min)


def test_warm_started_egnc_solves_every_stage(corrupted_world):
    _, _, corrupted = corrupted_world
    result = solve(corrupted.graph, "egnc", gnc_options=GncOptions(warm_start=True, refine=False))
    # Three graduated stages: mu = 0, mu*, 1.
    assert len(result.stages) == 3
    assert result.stages[0].mu_max == 0.0 and result.stages[1].mu_min < 1.0 and result.stages[2].mu_min == 1.0


@pytest.mark.parametrize("method", ["egnc", "risam"])
def test_restarted_stages_before_the_fixed_last_one_cannot_change_the_result(corrupted_world, method):
    _, _, corrupted = corrupted_world
    skipped = solve(corrupted.graph, method)
    every_stage = solve(corrupted.graph, method, gnc_options=GncOptions(every_stage=True))
    assert len(every_stage.stages) > len(skipped.stages)
    np.testing.assert_array_equal(every_stage.graph.poses, skipped.graph.poses)
    np.testing.assert_array_equal(every_stage.inliers, skipped.inliers)


@pytest.mark.parametrize("method", GRADUATED_METHODS)
def test_fixed_last_stage_methods_are_those_whose_schedule_has_one(method):
    robust = np.ones(6, dtype=bool)
    schedule = make_schedule(method, robust, 3)
    schedule.first_stage(np.linspace(0.5, 20.0, 6))
    assert (schedule.fixed_last_stage() is not None) == (method in FIXED_LAST_STAGE_METHODS)


def test_stage_tolerance_follows_the_stage_protocol():
    assert stage_tolerance("egnc", GncOptions()) == RESTARTED_STAGE_TOL
    assert stage_tolerance("risam", GncOptions(every_stage=True)) == RESTARTED_STAGE_TOL
    assert stage_tolerance("egnc", GncOptions(warm_start=True)) == CHAINED_STAGE_TOL
    assert stage_tolerance("gnc-gm", GncOptions()) == CHAINED_STAGE_TOL
    assert stage_tolerance("gnc-tls", GncOptions(stage_rel_cost_tol=1e-3)) == 1e-3
    assert RESTARTED_STAGE_TOL > CHAINED_STAGE_TOL


@pytest.mark.parametrize("dim", [2, 3])
def test_restarted_stage_stops_at_its_own_tolerance_with_the_same_decision(dim):
    # A noisier guess than corrupted_world's, so that the stage converges slowly.
    world = grid_world(dim, 300, seed=11, noise_scale=1.0)
    clean = solve(world.graph, "l2", init="chordal")
    corrupted = add_false_loops(world.graph, 30, seed=12, reference_poses=clean.graph.poses)
    default = solve(corrupted.graph, "egnc")
    explicit = solve(corrupted.graph, "egnc", gnc_options=GncOptions(stage_rel_cost_tol=RESTARTED_STAGE_TOL))
    tight = solve(corrupted.graph, "egnc", gnc_options=GncOptions(stage_rel_cost_tol=CHAINED_STAGE_TOL))
    np.testing.assert_array_equal(default.graph.poses, explicit.graph.poses)
    assert default.stages[0].iterations < tight.stages[0].iterations
    np.testing.assert_array_equal(~default.inliers, corrupted.is_outlier)
    np.testing.assert_array_equal(default.inliers, tight.inliers)
    np.testing.assert_allclose(default.graph.poses, tight.graph.poses, atol=1e-6)


def test_refinement_can_be_turned_off(corrupted_world):
    dim, clean, corrupted = corrupted_world
    result = solve(corrupted.graph, "egnc", gnc_options=GncOptions(refine=False))
    assert len(result.stages) == 1
    np.testing.assert_array_equal(~result.inliers, corrupted.is_outlier)
    # Geman-McClure's optimum is close to, but not exactly, the clean least-squares one.
    error = np.abs(result.graph.poses[:, :dim] - clean.graph.poses[:, :dim]).max()
    assert 0 < error < 0.05


def test_l2_is_never_refined(corrupted_world):
    _, _, corrupted = corrupted_world
    assert len(solve(corrupted.graph, "l2").stages) == 1


def test_egnc_schedule_stage_by_stage():
    robust = np.array([False, True, True, True, True])
    schedule = EgncSchedule(robust, d=3, c=3.0)
    first = schedule.first_stage(np.zeros(5))
    np.testing.assert_array_equal(first.mu[robust], 0.0)
    assert np.isnan(first.mu[0])
    strong = np.sqrt(chi2.ppf(0.9, 3)) + 0.1
    r = np.array([5.0, 0.5, 2.0, 2.4, strong])
    second = schedule.next_stage(r, converged=True)
    assert second is not None
    np.testing.assert_allclose(second.mu[1:], [1.0, mu_star(2.0), mu_star(2.4), 1.0], rtol=1e-12)
    third = schedule.next_stage(r, converged=True)
    assert third is not None
    np.testing.assert_array_equal(third.mu[robust], 1.0)
    assert schedule.next_stage(r, converged=False) is not None  # mu = 1 but not converged: repeat
    assert schedule.next_stage(r, converged=True) is None


def test_egnc_distance_convention_flags_fewer_strong_outliers():
    robust = np.ones(1, dtype=bool)
    r = np.array([4.0])  # r^2 = 16 > chi2(0.9, 3) = 6.25, but r = 4 < 6.25
    for threshold, expected in (("squared", 1.0), ("distance", mu_star(4.0)[()])):
        schedule = EgncSchedule(robust, d=3, threshold=threshold)  # type: ignore[arg-type]
        schedule.first_stage(r)
        assert schedule.next_stage(r, converged=True).mu[0] == pytest.approx(expected, rel=1e-12)


def test_risam_schedule_follows_the_published_sequence():
    robust = np.ones(3, dtype=bool)
    schedule = RisamSchedule(robust)
    mus = [schedule.first_stage(np.zeros(3)).mu[0]]
    while (stage := schedule.next_stage(np.zeros(3), converged=True)) is not None:
        mus.append(stage.mu[0])
    np.testing.assert_allclose(mus, [0.0, 0.12, 0.384, 0.9648, 1.0], atol=1e-12)


@pytest.mark.parametrize("kind", ["gm", "tls"])
def test_yang_schedule_initial_mu(kind):
    robust = np.array([False, True, True])
    barc2 = gnc_barc2(3)
    r = np.array([100.0, 1.0, 4.0])  # the known inlier's residual must not count
    schedule = YangGncSchedule(robust, d=3, kind=kind)
    schedule.first_stage(r)
    stage = schedule.next_stage(r, converged=True)
    f = 0.5 * r**2
    expected = 2 * f[2] / barc2 if kind == "gm" else barc2 / (2 * f[2] - barc2)
    assert stage.mu[2] == pytest.approx(expected, rel=1e-12)
    assert stage.loss.weight(r)[0] == 1.0


def test_known_inliers_choices(corrupted_world):
    _, _, corrupted = corrupted_world
    graph = corrupted.graph
    assert not known_inlier_mask(graph, "none").any()
    mask = np.zeros(graph.num_edges, dtype=bool)
    mask[:5] = True
    np.testing.assert_array_equal(solve(graph, "gm", known_inliers=mask).known_inliers, mask)
    with pytest.raises(EgncError, match="known_inliers"):
        known_inlier_mask(graph, "everything")
    with pytest.raises(EgncError, match="shape"):
        known_inlier_mask(graph, mask[:-1])


def test_unknown_method_is_a_clear_error(corrupted_world):
    with pytest.raises(EgncError, match="unknown method 'gnc'.*egnc, risam"):
        solve(corrupted_world[2].graph, "gnc")


@pytest.mark.parametrize("method", METHODS)
def test_every_method_runs_and_reports(corrupted_world, method):
    _, _, corrupted = corrupted_world
    result = solve(corrupted.graph, method)
    assert result.method == method
    assert np.isfinite(result.cost) and len(result.stages) >= 1
    assert result.iterations == sum(stage.iterations for stage in result.stages)
