"""Evaluation metrics: outlier precision/recall, absolute trajectory error, relative pose error.

Conventions (DESIGN.md section 5):

- Outlier detection is scored with **outliers as the positive class**: a true positive is a false
  loop closure the method rejected. `precision = TP / predicted outliers` is 1 when nothing was
  rejected (no false alarm was raised); `recall = TP / true outliers` is 1 when the graph has no
  outliers (nothing could be missed). `success` means both are exactly 1, as in the EGNC paper's
  noisy-Manhattan experiment.
- Poses are given in the stored parametrization of `egnc.graph`: `(N, 3)` `(x, y, theta)` in 2D
  or `(N, 7)` `(x, y, z, qx, qy, qz, qw)` in 3D, metres and radians, row k of the estimate
  matching row k of the reference.
- ATE is the RMSE of the positions after the rigid motion (rotation + translation, no scale) that
  best aligns the estimate with the reference in the least-squares sense (Kabsch/Umeyama, with
  the determinant correction so the rotation is never a reflection).
- RPE compares the relative motions `Q_k^-1 Q_{k+delta}` (reference) and `P_k^-1 P_{k+delta}`
  (estimate) through `E_k = (Q_k^-1 Q_{k+delta})^-1 (P_k^-1 P_{k+delta})`: the translational
  RPE is the RMSE of `|t(E_k)|` in metres, the rotational RPE the RMSE of the rotation angle of
  `E_k` in radians, and the percentage form is the translational RPE divided by the mean
  reference step length `mean_k |t(Q_k^-1 Q_{k+delta})|`, times 100 (so "RPE 3.2 %" means the
  relative motions are off by 3.2 % of a typical step). RPE needs no alignment: it is invariant
  to a rigid motion of either trajectory.

References:
    S. Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns", IEEE TPAMI 13(4), 1991.
    J. Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012 (ATE, RPE).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.errors import EgncError
from egnc.graph import POSE_SIZE
from egnc.nonlinear.factors import group_of, to_matrices
from egnc.nonlinear.prior_alignment import rigid_fit

__all__ = ["RelativePoseError", "ate", "precision_recall", "precision_recall_by_kind", "rpe", "success"]


def precision_recall(predicted_outlier: np.ndarray, true_outlier: np.ndarray) -> tuple[float, float]:
    """Precision and recall of outlier detection, outliers being the positive class.

    Args:
        predicted_outlier: `(E,)` bool, edges a method rejected.
        true_outlier: `(E,)` bool, ground-truth outliers.

    Returns:
        `(precision, recall)` in [0, 1]: precision is 1 when nothing is predicted outlier, recall
        is 1 when there is no true outlier.

    Raises:
        EgncError: the two arrays differ in shape or are not one-dimensional.
    """
    predicted = np.asarray(predicted_outlier, dtype=bool)
    truth = np.asarray(true_outlier, dtype=bool)
    if predicted.ndim != 1 or predicted.shape != truth.shape:
        raise EgncError(
            f"precision_recall needs two (E,) masks of equal length, got {predicted.shape} and {truth.shape}"
        )
    true_positives = np.count_nonzero(predicted & truth)
    num_predicted, num_true = np.count_nonzero(predicted), np.count_nonzero(truth)
    precision = true_positives / num_predicted if num_predicted else 1.0
    recall = true_positives / num_true if num_true else 1.0
    return float(precision), float(recall)


def precision_recall_by_kind(
    rejected_edges: np.ndarray,
    false_edges: np.ndarray,
    rejected_priors: np.ndarray | None = None,
    false_priors: np.ndarray | None = None,
) -> dict[str, tuple[float, float]]:
    """`precision_recall` of the loop closures and, where labelled, of the priors, each apart.

    A method that keeps the priors as they are and one that rejects them are scored on the loops
    alike; a prior decision is not diluted among the loops (or the reverse).

    Args:
        rejected_edges, false_edges: `(E,)` bool, edges rejected and false ones.
        rejected_priors, false_priors: `(K,)` bool, priors rejected and false ones (None: no
            priors' entry; `rejected_priors` None with labels: none rejected).

    Returns:
        `{"loops": (precision, recall)}`, with `"priors"` where `false_priors` is given.
    """
    scores = {"loops": precision_recall(rejected_edges, false_edges)}
    if false_priors is not None:
        rejected = np.zeros(len(false_priors), dtype=bool) if rejected_priors is None else rejected_priors
        scores["priors"] = precision_recall(rejected, false_priors)
    return scores


def success(precision: float, recall: float) -> bool:
    """Whether outlier detection was perfect: precision and recall both exactly 1."""
    return bool(precision == 1.0 and recall == 1.0)


def ate(poses: np.ndarray, reference: np.ndarray, dim: int, *, align: bool = True) -> float:
    """Absolute trajectory error: position RMSE after the best rigid alignment (no scale).

    Args:
        poses: `(N, P)` estimated poses (`P` = 3 in 2D, 7 in 3D).
        reference: `(N, P)` reference poses, same rows.
        dim: 2 or 3.
        align: False compares the positions as they are: where priors (GNSS fixes) fix the
            frame, a map that needs an alignment is wrong where it stands.

    Returns:
        `sqrt(mean_k |R p_k + t - q_k|^2)` in metres, with `(R, t)` the proper rigid motion
        (`det R = +1`) that minimizes it (the identity without `align`).
    """
    p = _positions(poses, dim, "poses")
    q = _positions(reference, dim, "reference")
    if p.shape != q.shape:
        raise EgncError(f"ate: poses has {len(p)} rows but reference has {len(q)}")
    R, t = rigid_fit(p, q) if align else (np.eye(dim), np.zeros(dim))
    error = p @ R.T + t - q
    return float(np.sqrt(np.mean(np.sum(error * error, axis=1))))


@dataclass(frozen=True)
class RelativePoseError:
    """Relative pose error between two trajectories (see the module docstring).

    Attributes:
        translation: RMSE of the translation of the relative-motion errors, metres.
        rotation: RMSE of their rotation angles, radians.
        percent: `100 * translation / mean reference step length` (nan when the reference
            does not move).
        pairs: number of pose pairs `(k, k + delta)` compared.
    """

    translation: float
    rotation: float
    percent: float
    pairs: int


def rpe(poses: np.ndarray, reference: np.ndarray, dim: int, delta: int = 1) -> RelativePoseError:
    """Relative pose error over the pose pairs `(k, k + delta)`.

    Args:
        poses: `(N, P)` estimated poses (`P` = 3 in 2D, 7 in 3D).
        reference: `(N, P)` reference poses, same rows.
        dim: 2 or 3.
        delta: pose offset of the compared pairs, `1 <= delta < N`.

    Returns:
        The `RelativePoseError` (translation in metres, rotation in radians, percentage).
    """
    P_world = _matrices(poses, dim, "poses")
    Q_world = _matrices(reference, dim, "reference")
    if len(P_world) != len(Q_world):
        raise EgncError(f"rpe: poses has {len(P_world)} rows but reference has {len(Q_world)}")
    if not 1 <= delta < len(P_world):
        raise EgncError(f"rpe: delta must lie in [1, N = {len(P_world)}), got {delta}")
    group = group_of(dim)
    P_step = group.between(P_world[:-delta], P_world[delta:])  # P_k^-1 P_{k+delta}
    Q_step = group.between(Q_world[:-delta], Q_world[delta:])
    E = group.between(Q_step, P_step)
    translation = np.linalg.norm(E[:, :dim, dim], axis=1)
    # The rotation part of the group log is the rotation angle (SE(2)) or axis-angle (SE(3)).
    angle = np.linalg.norm(group.log(E)[:, dim:], axis=1)
    translation_rmse = float(np.sqrt(np.mean(translation * translation)))
    mean_step = float(np.mean(np.linalg.norm(Q_step[:, :dim, dim], axis=1)))
    return RelativePoseError(
        translation=translation_rmse,
        rotation=float(np.sqrt(np.mean(angle * angle))),
        percent=100.0 * translation_rmse / mean_step if mean_step > 0.0 else float("nan"),
        pairs=len(E),
    )


def _checked(poses: np.ndarray, dim: int, name: str) -> np.ndarray:
    """`poses` as a finite `(N, P)` float array with N >= 1, or an `EgncError`."""
    if dim not in POSE_SIZE:
        raise EgncError(f"dim must be 2 or 3, got {dim}")
    array = np.asarray(poses, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != POSE_SIZE[dim] or len(array) == 0:
        raise EgncError(f"{name} must have shape (N, {POSE_SIZE[dim]}) with N >= 1 for {dim}D, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise EgncError(f"{name} holds NaN or infinite values")
    return array


def _positions(poses: np.ndarray, dim: int, name: str) -> np.ndarray:
    """`(N, dim)` positions of `(N, P)` poses."""
    return _checked(poses, dim, name)[:, :dim]


def _matrices(poses: np.ndarray, dim: int, name: str) -> np.ndarray:
    """`(N, n, n)` homogeneous matrices of `(N, P)` poses."""
    return to_matrices(dim, _checked(poses, dim, name))
