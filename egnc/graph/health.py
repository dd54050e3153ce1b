"""Refuse problems a double cannot represent, before any number reaches BLAS or CHOLMOD.

A pose at x = 1e20 m is a valid float, but neighbouring doubles there are 16 km apart: the
difference of two such positions cannot express a 1 cm odometry step, every residual is rounding
noise, and least squares returns garbage with a small-looking relative cost decrease (issue 11:
intel with one vertex at 1e20 was reported "converged" at cost 5e42). At 1e300 the cost overflows
and OpenBLAS prints errors on stdout. Both are numerically meaningless; this module says so.

Rule: for every edge, the spacing of doubles at the larger of its two poses' coordinates
(`numpy.spacing`) must stay below the standard deviation its information matrix gives the
translation (`1 / sqrt(max diagonal entry)`): otherwise the measurement asks for a precision
the coordinates cannot hold. Measurements are checked the same way, and information matrices
and poses must be finite. The online solver applies the same rule to each new edge at its
`add_*` call (`coarse_edges`), against its current estimate.
"""

from __future__ import annotations

import numpy as np

from egnc.errors import NumericalError
from egnc.graph import PoseGraph


class UnrepresentableError(NumericalError):
    """A `NumericalError` about one edge: `edge` is its index (the CLI names the edge's file line)."""

    def __init__(self, message: str, edge: int):
        super().__init__(message)
        self.edge = edge


def coarse_edges(scale: np.ndarray, information: np.ndarray, dim: int) -> tuple[int, int, str] | None:
    """`(count, worst, why)` for the edges whose coordinates are too coarse for their information; None if none.

    Args:
        scale: `(K,)` the largest absolute coordinate (metres) each edge involves: its poses' and
            its measurement's translation.
        information: `(K, d, d)` their information matrices, finite.
        dim: 2 or 3.

    Returns:
        How many edges fail, the index of the worst one and a sentence about it ("involves ...").
    """
    # the translation's standard deviation each edge asks for, metres
    precision = np.max(np.diagonal(information[:, :dim, :dim], axis1=1, axis2=2), axis=1)
    sigma = 1.0 / np.sqrt(np.maximum(precision, np.finfo(float).tiny))
    coarse = np.spacing(scale) > sigma
    if not np.any(coarse):
        return None
    worst = int(np.argmax(np.spacing(scale) / sigma))
    why = (
        f"involves coordinates of {scale[worst]:.3g} m, where doubles are {np.spacing(scale[worst]):.3g} m"
        f" apart, coarser than its {sigma[worst]:.3g} m standard deviation; move the poses near the origin"
    )
    return int(coarse.sum()), worst, why


def check_representable(graph: PoseGraph) -> None:
    """Raise `NumericalError` (one line) when `graph` cannot be solved in double precision.

    An `UnrepresentableError` (its `edge` the worst edge's index) when coordinates are too coarse.

    Args:
        graph: the pose graph, with its initial guess in `graph.poses`.
    """
    dim = graph.dim
    if not (np.all(np.isfinite(graph.poses)) and np.all(np.isfinite(graph.measurements))):
        raise NumericalError("the poses or measurements hold non-finite numbers")
    if not np.all(np.isfinite(graph.information)):
        raise NumericalError("some information matrices hold non-finite numbers")
    position = np.abs(graph.poses[:, :dim]).max(axis=1)
    scale = np.maximum(position[graph.edges].max(axis=1), np.abs(graph.measurements[:, :dim]).max(axis=1))
    found = coarse_edges(scale, graph.information, dim)
    if found is not None:
        count, worst, why = found
        i, j = graph.vertex_ids[graph.edges[worst]]
        raise UnrepresentableError(
            f"{count} edges cannot be represented in double precision: edge {worst} ({i} -> {j}) {why}", worst
        )
