"""Metrics on hand-made trajectories whose answers are known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

from egnc.errors import EgncError
from egnc.lie import se2, se3, so3
from egnc.metrics import ate, precision_recall, rpe, success
from egnc.nonlinear.factors import from_matrices, to_matrices


def random_trajectory(dim: int, n: int, seed: int) -> np.ndarray:
    """`(n, P)` poses in the stored parametrization, chained from random steps."""
    rng = np.random.default_rng(seed)
    group = se2 if dim == 2 else se3
    steps = group.exp(rng.normal(scale=0.5, size=(n, 3 if dim == 2 else 6)))
    T = np.empty_like(steps)
    T[0] = steps[0]
    for k in range(1, n):
        T[k] = group.compose(T[k - 1], steps[k])
    return from_matrices(dim, T)


def moved(poses: np.ndarray, dim: int, T_new_old: np.ndarray) -> np.ndarray:
    """The same trajectory seen from another world frame: `T_new_old @ T_old_k` for every k."""
    group = se2 if dim == 2 else se3
    return from_matrices(dim, group.compose(T_new_old, to_matrices(dim, poses)))


def chain(dim: int, step: np.ndarray, n: int) -> np.ndarray:
    """`(n, P)` poses from the identity, composing the same `(n, n)` step matrix each time."""
    group = se2 if dim == 2 else se3
    T = [group.identity()]
    for _ in range(n - 1):
        T.append(group.compose(T[-1], step))
    return from_matrices(dim, np.stack(T))


# --- precision / recall -------------------------------------------------------------------------


def test_precision_recall_counts_outliers_as_positives():
    predicted = np.array([True, True, False, False, False])
    truth = np.array([True, False, True, True, False])
    assert precision_recall(predicted, truth) == (0.5, pytest.approx(1 / 3))


def test_precision_is_one_when_nothing_is_rejected_and_recall_one_without_outliers():
    none = np.zeros(4, dtype=bool)
    some = np.array([False, True, False, False])
    assert precision_recall(none, some) == (1.0, 0.0)
    assert precision_recall(some, none) == (0.0, 1.0)
    assert precision_recall(none, none) == (1.0, 1.0)
    assert precision_recall(some, some) == (1.0, 1.0)


def test_success_needs_both_exactly_one():
    assert success(1.0, 1.0)
    assert not success(1.0, 0.99)
    assert not success(0.999, 1.0)


def test_precision_recall_rejects_mismatched_masks():
    with pytest.raises(EgncError, match="equal length"):
        precision_recall(np.zeros(3, bool), np.zeros(4, bool))


# --- ATE ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("dim", [2, 3])
def test_rigidly_moved_copy_has_zero_ate(dim):
    reference = random_trajectory(dim, 50, seed=dim)
    if dim == 2:
        T = se2.from_xytheta(np.array([12.0, -7.0, 2.5]))
    else:
        T = se3.from_xyz_quat(np.concatenate(([3.0, -4.0, 5.0], so3.to_quaternion(so3.exp([0.3, -1.2, 2.0])))))
    assert ate(moved(reference, dim, T), reference, dim) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_scaled_copy_has_the_known_ate(dim):
    # Positions symmetric about the origin: the best rigid fit of s * q onto q is the identity,
    # which leaves |s - 1| |q_k| per pose.
    rng = np.random.default_rng(7)
    half = rng.normal(size=(10, dim))
    positions = np.concatenate((half, -half))
    reference = np.zeros((20, 3 if dim == 2 else 7))
    reference[:, :dim] = positions
    if dim == 3:
        reference[:, 6] = 1.0
    estimate = reference.copy()
    estimate[:, :dim] *= 1.1
    expected = 0.1 * math.sqrt(np.mean(np.sum(positions**2, axis=1)))
    assert ate(estimate, reference, dim) == pytest.approx(expected, rel=1e-12)


def test_mirror_image_is_aligned_by_a_rotation_not_a_reflection():
    # Mirroring x -> -x: the best orthogonal fit (the reflection) would give 0. Over rotations,
    # sum q_k . R(theta) p_k = 6 cos(theta), so theta = 0 and the cost is 2 sum |q|^2 - 12 = 8.
    reference = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 2.0, 0], [0, -2.0, 0]])
    estimate = reference * [-1.0, 1.0, 1.0]
    assert ate(estimate, reference, 2) == pytest.approx(math.sqrt(2.0), rel=1e-12)


def test_ate_matches_a_brute_force_search_over_rotations():
    rng = np.random.default_rng(3)
    reference = np.column_stack((rng.normal(size=(30, 2)) * [5.0, 1.0], np.zeros(30)))
    estimate = reference * [1.0, -1.0, 1.0] + np.column_stack((rng.normal(scale=0.3, size=(30, 2)), np.zeros(30)))
    p, q = estimate[:, :2], reference[:, :2]

    def rmse(theta: float) -> float:
        R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        r = p @ R.T
        r += (q - r).mean(axis=0)  # the optimal translation for this rotation
        return math.sqrt(np.mean(np.sum((r - q) ** 2, axis=1)))

    grid = np.linspace(-np.pi, np.pi, 3601)
    start = grid[np.argmin([rmse(theta) for theta in grid])]
    bounds = (start - 0.01, start + 0.01)
    best = scipy.optimize.minimize_scalar(rmse, bounds=bounds, method="bounded", options={"xatol": 1e-12}).fun
    assert ate(estimate, reference, 2) == pytest.approx(best, rel=1e-6)


def test_ate_rejects_mismatched_inputs():
    with pytest.raises(EgncError, match="rows"):
        ate(np.zeros((3, 3)), np.zeros((4, 3)), 2)
    with pytest.raises(EgncError, match=r"\(N, 7\)"):
        ate(np.zeros((3, 3)), np.zeros((3, 3)), 3)


# --- RPE ----------------------------------------------------------------------------------------


def test_rpe_of_a_constant_drift_per_step():
    # Reference steps (1, 0, 0); the estimate steps (1 + eps, 0, alpha): every relative-motion
    # error is S^-1 S' = (eps, 0, alpha).
    eps, alpha = 0.05, 0.01
    reference = chain(2, se2.from_xytheta([1.0, 0.0, 0.0]), 40)
    estimate = chain(2, se2.from_xytheta([1.0 + eps, 0.0, alpha]), 40)
    error = rpe(estimate, reference, 2)
    assert error.translation == pytest.approx(eps, rel=1e-12)
    assert error.rotation == pytest.approx(alpha, rel=1e-12)
    assert error.percent == pytest.approx(100 * eps, rel=1e-12)
    assert error.pairs == 39


def test_rpe_percent_of_a_scale_drift_does_not_depend_on_delta():
    reference = chain(2, se2.from_xytheta([1.0, 0.0, 0.0]), 20)
    estimate = chain(2, se2.from_xytheta([1.02, 0.0, 0.0]), 20)
    error = rpe(estimate, reference, 2, delta=3)
    assert error.translation == pytest.approx(3 * 0.02, rel=1e-12)
    assert error.percent == pytest.approx(2.0, rel=1e-12)
    assert error.pairs == 17


def test_rpe_3d_rotation_drift_and_rigid_invariance():
    alpha = 0.02
    step = se3.from_xyz_quat(np.array([1.0, 0, 0, 0, 0, 0, 1.0]))
    drift = se3.from_xyz_quat(np.concatenate(([1.0, 0, 0], so3.to_quaternion(so3.exp([0.0, alpha, 0.0])))))
    reference, estimate = chain(3, step, 30), chain(3, drift, 30)
    error = rpe(estimate, reference, 3)
    assert error.translation == pytest.approx(0.0, abs=1e-12)
    assert error.rotation == pytest.approx(alpha, rel=1e-9)
    T = se3.from_xyz_quat(np.concatenate(([5.0, 6.0, 7.0], so3.to_quaternion(so3.exp([1.0, 2.0, -0.5])))))
    shifted = rpe(moved(estimate, 3, T), reference, 3)
    assert shifted.rotation == pytest.approx(error.rotation, rel=1e-9)
    assert shifted.translation == pytest.approx(0.0, abs=1e-9)


def test_rpe_rejects_a_bad_delta():
    poses = np.zeros((5, 3))
    with pytest.raises(EgncError, match="delta"):
        rpe(poses, poses, 2, delta=5)
