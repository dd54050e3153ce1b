"""Positive-definiteness of information (and covariance) matrices, and the readers' repairs.

A reader meets matrices that are not positive definite in real files (cubicle.g2o: 5021 of 16869).
`strict` refuses them; `nearest-pd` clips the eigenvalues of each bad symmetric matrix to a floor of
`NEAREST_PD_FLOOR` times its largest eigenvalue (the nearest positive-semidefinite matrix in the
Frobenius norm, Higham 1988, lifted just enough to be definite); `diagonal` keeps only its diagonal.
Only the matrices that fail are changed.

References:
    N. J. Higham, "Computing a nearest symmetric positive semidefinite matrix", Linear Algebra
    Appl. 103, 1988.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from egnc.graph.validity import not_positive_definite

InformationMode = Literal["strict", "nearest-pd", "diagonal"]
INFORMATION_MODES: tuple[InformationMode, ...] = ("strict", "nearest-pd", "diagonal")

NEAREST_PD_FLOOR = 1e-6
"""Smallest eigenvalue after `nearest-pd`, relative to the largest: a condition number of 1e6."""


@dataclass(frozen=True)
class Repair:
    """What `repair_information` changed.

    Attributes:
        count: matrices replaced.
        largest_change: largest `||A' - A||_F / ||A||_F` over them.
        largest_index: index of that matrix in the input.
    """

    count: int
    largest_change: float
    largest_index: int


def repair_information(
    information: np.ndarray, bad: np.ndarray, mode: InformationMode
) -> tuple[np.ndarray, np.ndarray, Repair]:
    """Replace the matrices `information[bad]` `(K, d, d)` by positive-definite ones.

    Args:
        information: `(E, d, d)` symmetric matrices, finite.
        bad: indices from `egnc.graph.validity.not_positive_definite` (non-empty).
        mode: `"nearest-pd"` or `"diagonal"` (see the module docstring).

    Returns:
        `(repaired, still_bad, repair)`: the `(E, d, d)` matrices, the indices that no repair of
        this mode can make positive definite (e.g. a diagonal with an entry <= 0, or a matrix
        without a positive eigenvalue), and the summary of the change.
    """
    before = information[bad]
    if mode == "diagonal":
        after = before * np.eye(before.shape[-1])
    else:
        eigenvalues, vectors = np.linalg.eigh(before)
        floor = NEAREST_PD_FLOOR * eigenvalues[:, -1:]
        clipped = np.maximum(eigenvalues, floor)
        after = np.einsum("kij,kj,klj->kil", vectors, clipped, vectors)
        after = 0.5 * (after + after.swapaxes(1, 2))
    repaired = information.copy()
    repaired[bad] = after
    with np.errstate(all="ignore"):  # a zero matrix has no relative change; it stays bad anyway
        change = np.linalg.norm(after - before, axis=(1, 2)) / np.linalg.norm(before, axis=(1, 2))
    k = int(np.nanargmax(change)) if np.isfinite(change).any() else 0
    return repaired, bad[not_positive_definite(after)], Repair(len(bad), float(change[k]), int(bad[k]))
