"""Priors as candidates for rejection: the known-inlier kinds, mixed-dimension thresholds, the
decision on GNSS-like priors with multipath jumps, and nothing rejected on clean priors."""

import numpy as np
import pytest

import egnc
from egnc.datasets import add_multipath_outliers, add_position_priors, grid_world
from egnc.errors import OptionError
from egnc.robust.gnc import GncOptions, classify_inliers, known_inlier_mask
from egnc.robust.kernels import chi2_quantile


def gnss_graph(dim: int, num_poses: int = 300, seed: int = 3):
    """A grid world with a position prior every 5th pose (sigma 1 m) around its least-squares optimum."""
    world = grid_world(dim, num_poses, seed=seed)
    optimum = egnc.solve(world.graph, "l2").graph.poses
    return add_position_priors(world.graph, optimum, every=5, sigma=1.0, seed=seed), optimum


def test_known_inliers_name_kinds_and_masks_cover_edges_then_priors():
    graph, _ = gnss_graph(2, 60)
    E, K = graph.num_edges, graph.num_priors
    assert known_inlier_mask(graph, "odometry").shape == (E + K,)
    np.testing.assert_array_equal(known_inlier_mask(graph, "odometry,priors"), graph.is_odometry)
    np.testing.assert_array_equal(known_inlier_mask(graph, ("odometry", "priors")), graph.is_odometry)
    both = known_inlier_mask(graph, "odometry, loops")
    assert both[:E].all() and not both[E:].any()
    assert not known_inlier_mask(graph, "none").any()
    mask = known_inlier_mask(graph, graph.is_odometry)
    assert mask.shape == (E + K,) and not mask[E:].any()
    np.testing.assert_array_equal(known_inlier_mask(graph, np.ones(E + K, dtype=bool)), np.ones(E, dtype=bool))
    with pytest.raises(OptionError, match="unknown known_inliers 'gnss'"):
        known_inlier_mask(graph, "odometry,gnss")
    with pytest.raises(OptionError, match=rf"shape \({E},\) or \({E + K},\)"):
        known_inlier_mask(graph, np.ones(3, dtype=bool))


def test_outlier_test_takes_each_factor_at_its_own_dimension():
    r = np.full(3, np.sqrt(10.0))  # above chi2.ppf(0.99, 2) = 9.21, below chi2.ppf(0.99, 3) = 11.34
    inliers = classify_inliers(r, np.ones(3, dtype=bool), np.array([3, 2, 6]), GncOptions())
    np.testing.assert_array_equal(inliers, [True, False, True])
    np.testing.assert_allclose(
        chi2_quantile(0.99, np.array([3, 2, 3])), [11.344866730144373, 9.21034, 11.344866730144373], rtol=1e-6
    )


@pytest.mark.parametrize("dim", [2, 3])
def test_clean_priors_reject_nothing_and_reach_the_least_squares_optimum(dim):
    graph, _ = gnss_graph(dim)
    robust = egnc.solve(graph)
    plain = egnc.solve(graph, "l2")
    assert robust.rejected_priors.shape == (0,) and robust.rejected_edges.shape == (0,)
    assert robust.prior_inliers is not None and robust.prior_inliers.all()
    np.testing.assert_allclose(robust.graph.poses, plain.graph.poses, atol=1e-4)  # both to rel_cost_tol
    assert robust.cost == pytest.approx(plain.cost, rel=1e-9)


@pytest.mark.parametrize(("dim", "bursts"), [(2, False), (2, True), (3, False), (3, True)])
def test_multipath_jumps_are_rejected_and_held_priors_are_not(dim, bursts):
    graph, _ = gnss_graph(dim)
    corrupted = add_multipath_outliers(graph, 20, seed=5, bursts=bursts, burst_size=(3, 6))
    assert corrupted.is_outlier.sum() == round(0.2 * graph.num_priors)
    result = egnc.solve(corrupted.graph)
    expected = corrupted.graph.prior_factor_index[corrupted.is_outlier]
    np.testing.assert_array_equal(np.sort(result.rejected_priors), np.sort(expected))
    assert result.rejected_edges.shape == (0,)
    held = egnc.solve(corrupted.graph, known_inliers="odometry,priors")
    assert held.rejected_priors.shape == (0,) and held.prior_inliers is None


def test_gnc_tls_rejects_multipath_jumps_at_mixed_dimensions():
    graph, _ = gnss_graph(2)
    corrupted = add_multipath_outliers(graph, 10, seed=2)
    result = egnc.solve(corrupted.graph, "gnc-tls")
    expected = corrupted.graph.prior_factor_index[corrupted.is_outlier]
    np.testing.assert_array_equal(np.sort(result.rejected_priors), np.sort(expected))


def test_multipath_generator_is_seeded_and_checks_its_arguments():
    graph, _ = gnss_graph(2, 100)
    a = add_multipath_outliers(graph, 30, seed=1, bursts=True, burst_size=(2, 4))
    b = add_multipath_outliers(graph, 30, seed=1, bursts=True, burst_size=(2, 4))
    np.testing.assert_array_equal(a.is_outlier, b.is_outlier)
    np.testing.assert_array_equal(a.graph.priors.measurements, b.graph.priors.measurements)
    jumps = np.linalg.norm(a.graph.priors.measurements[:, :2] - graph.priors.measurements[:, :2], axis=1)
    assert np.all((jumps[a.is_outlier] >= 10) & (jumps[a.is_outlier] <= 50)) and not jumps[~a.is_outlier].any()
    _, optimum = gnss_graph(2, 100)
    c = add_multipath_outliers(graph, 30, seed=1, reference_poses=optimum)
    off = np.linalg.norm(c.graph.priors.measurements[:, :2] - optimum[graph.priors.rows, :2], axis=1)
    assert np.all((off[c.is_outlier] >= 10 - 1e-9) & (off[c.is_outlier] <= 50 + 1e-9))  # off by the jump itself
    with pytest.raises(OptionError, match="no position prior"):
        add_multipath_outliers(grid_world(2, 20, seed=0).graph, 10)


def test_labels_keep_prior_outliers_apart_and_old_files_read_as_before(tmp_path):
    from egnc.io.labels import read_labels, read_prior_labels, write_labels

    edges, priors = np.array([False, True, False]), np.array([True, False, False, True])
    write_labels(tmp_path / "a.labels.json", edges, {"seed": 1}, priors)
    is_outlier, meta = read_labels(tmp_path / "a.labels.json")
    np.testing.assert_array_equal(is_outlier, edges)
    assert meta == {"seed": 1}
    np.testing.assert_array_equal(read_prior_labels(tmp_path / "a.labels.json"), priors)
    write_labels(tmp_path / "b.labels.json", edges)
    assert read_prior_labels(tmp_path / "b.labels.json") is None


def test_egnc_corrupt_adds_labelled_gnss_fixes_that_the_solve_rejects(tmp_path):
    from egnc.cli.corrupt import main
    from egnc.io.g2o import read_g2o
    from egnc.io.labels import read_labels, read_prior_labels
    from egnc.metrics import precision_recall_by_kind

    out = tmp_path / "gnss.g2o"
    source = "datasets/grid2d.g2o"
    argv = [source, "--percent", "10", "--seed", "4", "--gnss-every", "5", "--gnss-sigma", "1"]
    assert main([*argv, "--gnss-outliers", "20", "--gnss-bursts", "-q", "-o", str(out)]) == 0
    graph = read_g2o(out)
    false_edges, _ = read_labels(tmp_path / "gnss.labels.json")
    false_priors = read_prior_labels(tmp_path / "gnss.labels.json")
    assert graph.num_priors == 100 and false_priors is not None and false_priors.sum() == 20
    result = egnc.solve(graph)
    rejected_priors = np.isin(graph.prior_factor_index, result.rejected_priors)
    scores = precision_recall_by_kind(~result.inliers, false_edges, rejected_priors, false_priors)
    assert scores == {"loops": (1.0, 1.0), "priors": (1.0, 1.0)}


def test_ate_without_alignment_sees_a_shifted_map():
    from egnc.metrics import ate

    reference = np.zeros((4, 3))
    reference[:, 0] = np.arange(4)
    shifted = reference + [1.0, 0.0, 0.0]
    assert ate(shifted, reference, 2) == pytest.approx(0.0, abs=1e-12)
    assert ate(shifted, reference, 2, align=False) == pytest.approx(1.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_alignment_to_priors_ignores_multipath_fixes(dim):
    from egnc.nonlinear.factors import from_matrices, group_of, to_matrices
    from egnc.nonlinear.prior_alignment import align_to_priors

    graph, optimum = gnss_graph(dim, 200)
    corrupted = add_multipath_outliers(graph, 20, seed=4, bursts=True, burst_size=(3, 6)).graph
    d = 3 if dim == 2 else 6
    motion = group_of(dim).exp(np.linspace(0.3, 0.9, d) * 5)  # a world-frame motion, metres and radians
    moved = from_matrices(dim, motion @ to_matrices(dim, optimum))
    aligned = align_to_priors(corrupted, moved)
    assert np.max(np.abs(aligned[:, :dim] - optimum[:, :dim])) < 1.0  # fixes have sigma 1 m


@pytest.mark.parametrize("init", ["odometry", "chordal"])
def test_odometry_and_chordal_starts_are_in_the_priors_frame(init):
    from egnc.nonlinear.factors import from_matrices, group_of, to_matrices

    graph, _ = gnss_graph(2)
    corrupted = add_multipath_outliers(graph, 20, seed=5, bursts=True, burst_size=(3, 6))
    turned = from_matrices(2, group_of(2).exp(np.array([30.0, -20.0, 2.0])) @ to_matrices(2, graph.poses))
    result = egnc.solve(corrupted.graph.with_poses(turned), init=init)
    expected = corrupted.graph.prior_factor_index[corrupted.is_outlier]
    np.testing.assert_array_equal(np.sort(result.rejected_priors), np.sort(expected))


def test_online_replay_of_a_graph_with_priors_runs_on_its_edges():
    from egnc.online.replay import replay

    graph, _ = gnss_graph(2, 120)
    outcome = replay(graph)
    assert outcome.result.rejected_edges.shape == (0,)


def heading_drifted(graph, sigma: float, seed: int):
    """`graph` with its guess chained from odometry whose headings carry extra `N(0, sigma)` rad per step."""
    from egnc.nonlinear.factors import from_matrices, to_matrices
    from egnc.nonlinear.initialize import initialize_poses

    Z = to_matrices(2, graph.measurements[graph.is_odometry])
    angle = np.random.default_rng(seed).normal(0.0, sigma, size=len(Z))
    c, s = np.cos(angle), np.sin(angle)
    Z[:, :2, :2] = Z[:, :2, :2] @ np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    known = np.arange(graph.num_poses) == 0
    odometry = graph.edges[graph.is_odometry]
    return graph.with_poses(initialize_poses(2, odometry, from_matrices(2, Z), poses=graph.poses, known=known))


def test_chordal_starts_in_the_fixes_frame_win_back_a_drifted_guess():
    # Chained over 1000 poses with 0.5 rad of heading noise a step, the guess is far from every
    # fix; the GNC stage from it (moved onto the fixes) rejects honest fixes. The chordal starts,
    # moved onto the fixes too, do not read the guess and decide exactly.
    world = grid_world(2, 1000, seed=2)
    optimum = egnc.solve(world.graph, "l2").graph.poses
    fixed = add_position_priors(world.graph, optimum, every=20, sigma=1.0, seed=2)
    corrupted = add_multipath_outliers(fixed, 20, seed=5, bursts=True, burst_size=(3, 6))
    drifted = heading_drifted(corrupted.graph, 0.5, seed=2)
    result = egnc.solve(drifted)
    expected = corrupted.graph.prior_factor_index[corrupted.is_outlier]
    np.testing.assert_array_equal(np.sort(result.rejected_priors), np.sort(expected))
    assert result.rejected_edges.shape == (0,)
    assert result.start != "guess"
    guess_only = egnc.solve(drifted, gnc_options=GncOptions(starts=()))
    assert len(guess_only.rejected_priors) > len(expected)  # the guess alone does not get there


def test_with_candidate_priors_the_loop_only_starts_do_not_run(monkeypatch):
    from egnc.robust import pipeline

    proposed: list[str] = []
    for name in pipeline.LOOPS_ONLY:
        monkeypatch.setattr(
            pipeline.STARTS[name], "propose", lambda search, name=name: proposed.append(name) or (None, ())
        )
    graph, _ = gnss_graph(2, 120)
    corrupted = add_multipath_outliers(graph, 20, seed=5).graph
    egnc.solve(corrupted)
    assert proposed == []
    egnc.solve(corrupted, known_inliers="odometry,priors")  # priors held: every start runs
    assert proposed == list(pipeline.LOOPS_ONLY)
