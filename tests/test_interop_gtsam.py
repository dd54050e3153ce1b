"""`egnc.from_gtsam`: GTSAM's factors and values in, `gtsam.Values` and the kept factors out.

Every test here names GTSAM, so all are in the long tier (tests/conftest.py); they skip without
the `gtsam` wheel.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import egnc
from egnc.datasets import add_false_loops, grid_world
from egnc.datasets.two_robots import GROUP_FALSE, TRUE_LOOP, two_robots
from egnc.errors import EgncWarning, GraphError, UnsupportedFactorError
from egnc.interop.gtsam import from_gtsam, gtsam_error, inlier_factor_mask, to_gtsam, to_gtsam_values

gtsam = pytest.importorskip("gtsam")

SHARED_2D = ("MIT", "csail", "intel", "kitti_00", "manhattanOlson3500", "city10000")
SHARED_3D = ("sphere2500", "parking-garage", "smallGrid3D", "tinyGrid3D", "sphere_a")


def _with_priors(factors, values, is_3d: bool) -> None:
    """Add a pose prior on the first key, one on a later key off its value and, in 3D, a GPSFactor."""
    keys = list(values.keys())
    if is_3d:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.01, 0.02, 0.03, 0.1, 0.2, 0.3]))
        factors.add(gtsam.PriorFactorPose3(keys[0], values.atPose3(keys[0]), noise))
        moved = values.atPose3(keys[-1]).compose(gtsam.Pose3(gtsam.Rot3.Rz(0.2), gtsam.Point3(1.0, -2.0, 0.5)))
        factors.add(gtsam.PriorFactorPose3(keys[-1], moved, noise))
        factors.add(
            gtsam.GPSFactor(
                keys[len(keys) // 2], gtsam.Point3(3.0, 1.0, -1.0), gtsam.noiseModel.Isotropic.Sigma(3, 0.5)
            )
        )
    else:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.1, 0.2, 0.03]))
        factors.add(gtsam.PriorFactorPose2(keys[0], values.atPose2(keys[0]), noise))
        factors.add(gtsam.PriorFactorPose2(keys[-1], gtsam.Pose2(1.0, 2.0, 0.3), noise))


@pytest.mark.parametrize("name", SHARED_2D + SHARED_3D)
def test_gtsam_cost_equals_graph_error_on_every_shared_file(name, dataset_path):
    is_3d = name in SHARED_3D
    factors, values = gtsam.readG2o(str(dataset_path(f"{name}.g2o")), is_3d)
    _with_priors(factors, values, is_3d)
    bridge = from_gtsam(factors, values)
    assert bridge.graph.num_priors == (3 if is_3d else 2)
    assert np.array_equal(bridge.factor_index, np.arange(factors.size()))
    expected = factors.error(values)
    assert gtsam_error(bridge.graph) == pytest.approx(expected, rel=1e-9)
    back_factors, back_values = to_gtsam(bridge.graph, bridge.keys)
    assert back_factors.error(back_values) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_gtsam_lm_on_the_kept_factors_reaches_egnc_least_squares_map(dim):
    world = grid_world(dim, 300, seed=3)
    corrupted = add_false_loops(world.graph, 20, seed=1, reference_poses=world.ground_truth).graph
    factors, values = to_gtsam(corrupted)
    first = int(values.keys()[0])
    noise = gtsam.noiseModel.Isotropic.Sigma(3 * (dim - 1), 1e-3)
    prior = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    factors.add(prior(first, values.atPose2(first) if dim == 2 else values.atPose3(first), noise))
    bridge = from_gtsam(factors, values)
    result = egnc.solve(bridge.graph)
    keep = inlier_factor_mask(result, bridge)
    assert keep.sum() < factors.size()  # some false loops were rejected
    kept = gtsam.NonlinearFactorGraph()
    for index in np.flatnonzero(keep):
        kept.add(factors.at(int(index)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(200)
    solved = gtsam.LevenbergMarquardtOptimizer(kept, to_gtsam_values(result, bridge), params).optimize()
    egnc_values = to_gtsam_values(result, bridge)
    assert kept.error(solved) == pytest.approx(kept.error(egnc_values), rel=1e-9)
    for key in solved.keys():
        if dim == 2:
            assert solved.atPose2(key).equals(egnc_values.atPose2(key), 1e-6)
        else:
            assert solved.atPose3(key).equals(egnc_values.atPose3(key), 1e-6)


def test_gtsam_symbol_keys_keep_two_robots_and_a_consistent_false_group_is_rejected_whole():
    world = grid_world(2, 600, seed=5)
    reference = egnc.solve(world.graph, "l2").graph.poses
    robots = two_robots(world.graph, reference, true_loops=30, false_group=12, seed=2)
    factors, values = to_gtsam(robots.graph)
    bridge = from_gtsam(factors, values)
    assert set(bridge.robots()) == {"a", "b"}
    assert gtsam.Symbol(int(bridge.keys[0])).string() == "a0"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EgncWarning)
        result = egnc.solve(bridge.graph)
    keep = inlier_factor_mask(result, bridge)
    assert keep[robots.kinds == TRUE_LOOP].all()
    assert not keep[robots.kinds == GROUP_FALSE].any()
    assert any("groups that disagree" in text for text in result.warnings)
    solved = to_gtsam_values(result, bridge)
    assert sorted(solved.keys()) == sorted(values.keys())
    b0 = int(np.flatnonzero(bridge.keys == gtsam.symbol("b", 0))[0])
    assert solved.atPose2(gtsam.symbol("b", 0)).equals(gtsam.Pose2(*result.graph.poses[b0]), 1e-12)


def test_gtsam_keys_above_int64_become_negative_ids_and_come_back():
    high = gtsam.Symbol(chr(0xC8), 0).key()
    keys = [high, high + 1, gtsam.symbol("x", 0)]
    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    noise = gtsam.noiseModel.Unit.Create(3)
    for k, key in enumerate(keys):
        values.insert(key, gtsam.Pose2(k, 0.0, 0.0))
    factors.add(gtsam.BetweenFactorPose2(keys[0], keys[1], gtsam.Pose2(1.0, 0.0, 0.0), noise))
    factors.add(gtsam.BetweenFactorPose2(keys[1], keys[2], gtsam.Pose2(1.0, 0.0, 0.0), noise))
    bridge = from_gtsam(factors, values)
    assert bridge.graph.vertex_ids[0] < 0
    assert sorted(bridge.keys.tolist()) == sorted(keys)
    assert bridge.graph.is_odometry[0]  # Symbol(c, 0) and Symbol(c, 1) stay consecutive
    back = to_gtsam_values(bridge.graph, bridge)
    assert sorted(back.keys()) == sorted(keys)


def test_gtsam_unsupported_factor_and_noise_are_errors_naming_the_factor():
    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(0, gtsam.Pose2())
    values.insert(1, gtsam.Pose2(1.0, 0.0, 0.0))
    factors.add(gtsam.BetweenFactorPose2(0, 1, gtsam.Pose2(1.0, 0.0, 0.0), gtsam.noiseModel.Unit.Create(3)))
    factors.add(gtsam.PriorFactorPoint2(0, np.zeros(2), gtsam.noiseModel.Unit.Create(2)))
    with pytest.raises(UnsupportedFactorError, match=r"factor 1 \(PriorFactorPoint2\)"):
        from_gtsam(factors, values)
    constrained = gtsam.NonlinearFactorGraph()
    constrained.add(gtsam.BetweenFactorPose2(0, 1, gtsam.Pose2(), gtsam.noiseModel.Constrained.All(3)))
    with pytest.raises(UnsupportedFactorError, match=r"factor 0 \(BetweenFactorPose2\): noise model Constrained"):
        from_gtsam(constrained, values)
    missing = gtsam.NonlinearFactorGraph()
    missing.add(gtsam.BetweenFactorPose2(0, 7, gtsam.Pose2(), gtsam.noiseModel.Unit.Create(3)))
    with pytest.raises(GraphError, match="factor 0: key 7 has no value"):
        from_gtsam(missing, values)


def test_gtsam_robust_noise_is_read_as_its_gaussian_part_with_a_warning():
    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(0, gtsam.Pose2())
    values.insert(1, gtsam.Pose2(1.0, 0.0, 0.0))
    gaussian = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.1, 0.2, 0.05]))
    huber = gtsam.noiseModel.mEstimator.Huber.Create(1.0)
    factors.add(
        gtsam.BetweenFactorPose2(0, 1, gtsam.Pose2(1.1, 0.0, 0.0), gtsam.noiseModel.Robust.Create(huber, gaussian))
    )
    with pytest.warns(EgncWarning, match="robust noise models"):
        bridge = from_gtsam(factors, values)
    assert np.allclose(bridge.graph.information[0], np.diag([100.0, 25.0, 400.0]))


def test_gtsam_empty_slots_are_skipped_and_masked_out():
    world = grid_world(2, 60, seed=1)
    factors, values = to_gtsam(world.graph)
    factors.remove(3)
    bridge = from_gtsam(factors, values)
    assert bridge.factor_index[3] == -1 and bridge.graph.num_edges == world.graph.num_edges - 1
    mask = inlier_factor_mask(egnc.solve(bridge.graph), bridge)
    assert not mask[3] and mask.sum() == bridge.graph.num_edges
