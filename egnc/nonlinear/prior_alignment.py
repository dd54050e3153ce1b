"""A start in the priors' frame: the rigid motion that puts a map on its fixes, robust to wrong ones.

A guess chained from odometry or built by the chordal relaxation holds its gauge pose where the
file put it; the priors say where the map is (a GNSS fix's frame). Moved rigidly onto the
priors' positions, the guess needs no alignment afterwards, and the robust stages start with
every honest fix near its pose: a guess in another frame would put every fix far off, and the
kernel would let all of them go.

A wrong fix (multipath, tens of metres) must not drag the motion: it is fitted (Kabsch, proper
rotation) to every prior's position, then fitted again to the priors within `TRIM_FACTOR` times
the median distance, `TRIM_ROUNDS` times (a trimmed fit: with fewer wrong fixes than right ones,
the median is an honest fix's). Where the priors cannot fix a rotation (fewer than `dim`
distinct poses hold one) only the translation is fitted, by the median offset.
"""

from __future__ import annotations

import numpy as np

from egnc.graph import PoseGraph
from egnc.graph.priors import Priors
from egnc.nonlinear.factors import from_matrices, to_matrices

TRIM_FACTOR = 3.0
"""A prior counts in the next fit when its distance is within this many median distances."""

TRIM_ROUNDS = 3
"""Fits after the first, each on the priors the previous one kept."""


def align_to_priors(graph: PoseGraph, poses: np.ndarray) -> np.ndarray:
    """`(N, P)` poses moved rigidly so that the priors' poses lie on their measured positions.

    Args:
        graph: the graph; its priors (pose and position priors alike give a position).
        poses: `(N, P)` a guess of its poses, in any frame.

    Returns:
        `poses` moved by the trimmed rigid fit (module docstring); `poses` itself without priors.
    """
    priors = graph.priors
    if not len(priors):
        return poses
    M = frame_motion(priors, poses[priors.rows, : graph.dim])
    return from_matrices(graph.dim, M @ to_matrices(graph.dim, poses))  # a motion of the world frame


def frame_motion(priors: Priors, positions: np.ndarray) -> np.ndarray:
    """`(n, n)` the rigid motion of the world frame that puts the priors' poses, at `positions`
    `(K, dim)` (metres), onto the priors' measured positions: the trimmed fit (module docstring).

    Args:
        priors: at least one prior (pose and position priors alike give a position).
        positions: `(K, dim)` the current positions of the priors' poses, one row per prior.
    """
    dim = priors.dim
    p = positions
    q = priors.measurements[:, :dim]
    keep = np.ones(len(p), dtype=bool)
    rotate = len(np.unique(priors.rows)) >= dim
    for _ in range(TRIM_ROUNDS + 1):
        R, t = _fit(p[keep], q[keep], rotate)
        distance = np.linalg.norm(p @ R.T + t - q, axis=1)
        keep = distance <= TRIM_FACTOR * np.median(distance) + 1e-9
    M = np.eye(dim + 1)
    M[:dim, :dim], M[:dim, dim] = R, t
    return M


def _fit(p: np.ndarray, q: np.ndarray, rotate: bool) -> tuple[np.ndarray, np.ndarray]:
    """`rigid_fit` of `p` onto `q` `(k, dim)`, or the median offset without `rotate`."""
    if not rotate:
        return np.eye(p.shape[1]), np.median(q - p, axis=0)
    return rigid_fit(p, q)


def rigid_fit(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation `(k, k)` and translation `(k,)` minimizing `sum |R p_i + t - q_i|^2`.

    Umeyama (1991) without scale (Kabsch): with the cross-covariance
    `H = sum (p_i - p_mean) (q_i - q_mean)^T = U S V^T`, `R = V diag(1, ..., 1, det(V U^T)) U^T`;
    the last sign turns the best orthogonal fit into the best rotation when the former is a
    reflection.
    """
    dim = p.shape[1]
    p_mean, q_mean = p.mean(axis=0), q.mean(axis=0)
    U, _, Vt = np.linalg.svd((p - p_mean).T @ (q - q_mean))
    signs = np.ones(dim)
    signs[-1] = 1.0 if np.linalg.det(Vt.T @ U.T) > 0.0 else -1.0
    R = (Vt.T * signs) @ U.T
    return R, q_mean - R @ p_mean
