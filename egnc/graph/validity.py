"""The edge invariants that `PoseGraph` and the readers share, with one message each.

A reader names the file line of the first offending record; `PoseGraph` names the edge index.
Both take the wording from here, so a graph built in code is refused for the same reasons and in
the same words as a file.
"""

from __future__ import annotations

import numpy as np

NO_EDGES = "a pose graph needs edges"

MIN_QUATERNION_NORM = 1e-6
"""Quaternions shorter than this are treated as corrupt rather than normalized."""


def not_positive_definite(matrices: np.ndarray) -> np.ndarray:
    """Indices of the `(K, d, d)` symmetric matrices that are not numerically positive definite.

    A matrix fails when an entry is not finite, or its smallest eigenvalue is not above
    `d * eps` times its largest one (below that it is roundoff, not data).
    """
    d = matrices.shape[-1]
    finite = np.isfinite(matrices).all(axis=(1, 2))
    eigenvalues = np.zeros(matrices.shape[:2])
    with np.errstate(all="ignore"):  # entries near the overflow limit give inf/NaN eigenvalues: they fail
        eigenvalues[finite] = np.linalg.eigvalsh(matrices[finite])
        scale = np.abs(eigenvalues).max(axis=1, initial=0.0)
        # Written as "not above" so that a NaN eigenvalue also fails.
        singular = ~(eigenvalues[:, 0] > d * np.finfo(float).eps * scale)
    return np.flatnonzero(~finite | singular)


def not_positive_definite_message(information: np.ndarray, bad: np.ndarray) -> str:
    """Why `information[bad[0]]` `(d, d)` is refused, and how many of the `(E, d, d)` share the fault."""
    diagonal = np.diagonal(information[bad[0]]).tolist()
    return (
        f"information matrix is not positive definite (diagonal {diagonal}); "
        f"{len(bad)} of the {len(information)} edges are affected"
    )


def first_self_edge(edge_ids: np.ndarray) -> tuple[int, str] | None:
    """`(index, message)` of the first `(E, 2)` edge from a vertex to itself (it measures nothing), or None."""
    bad = np.flatnonzero(edge_ids[:, 0] == edge_ids[:, 1])
    if not len(bad):
        return None
    return int(bad[0]), f"edge joins vertex {edge_ids[bad[0], 0]} to itself"


def first_bad_quaternion(quaternions: np.ndarray) -> tuple[int, str] | None:
    """`(index, message)` of the first `(K, 4)` quaternion that cannot be normalized in double precision, or None.

    Too short (norm below `MIN_QUATERNION_NORM`, most likely corrupt), not finite, or so long
    that the sum of squares overflows (a component above about 1e154).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        norms = np.sqrt(np.einsum("ij,ij->i", quaternions, quaternions))
    bad = np.flatnonzero(~(norms >= MIN_QUATERNION_NORM) | ~np.isfinite(norms))
    if not len(bad):
        return None
    k = int(bad[0])
    problem = "too small" if norms[k] < MIN_QUATERNION_NORM else "too large (overflows a double)"
    return k, f"quaternion (qx qy qz qw) = {quaternions[k].tolist()} has a norm {problem} to normalize"
