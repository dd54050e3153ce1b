"""The covariances of an IRL log: their two orders in 3D, their checks, and the warning when the order matters.

A 3D IRL entry carries a 6x6 covariance whose order the format leaves to the programs:

- `"gtsam"`, `(rx, ry, rz, x, y, z)`, rotation first: riSAM's C++ reader hands COV to
  `noiseModel::Gaussian::Covariance` of a `Pose3` factor, whose tangent is rotation first.
  Logs written for that reader (egnc's writer by default) need this reading; it is the default.
- `"g2o"`, `(x, y, z, rx, ry, rz)`, translation first: riSAM's `g2o-2-irl` converter writes
  `inv(g2o information)` without reordering it, so its logs of g2o files hold g2o's order. Read
  them this way to keep the g2o file's noise model (sphere2500: translation information 10,
  rotation about 400).

When the translation and rotation blocks are alike (riSAM's isotropic data sets) the two readings
agree; when they differ, reading a converter's log the C++ way gives every edge a translation that
claims to be 6x more precise than its measurement (sphere2500), and a chi-square decision rejects
the tail of honest loops. `reading_warning` says so, once per file, when the reading is ambiguous:
the caller took the default and the file does not declare its order (egnc's own writer,
`IrlLog.from_graph`, puts `ORDER_MARK` and the order in the header's notes line).

The rule for "differ": the mean over the entries of the first diagonal block (three variances) and
of the second differ by more than `ANISOTROPY_RATIO`. A log with the same variance on all six
stays silent, as does every 2D log (its `(x, y, theta)` order is shared by g2o and GTSAM).
"""

from __future__ import annotations

import re
from typing import Literal, get_args

import numpy as np

from egnc.errors import EgncError
from egnc.graph.validity import not_positive_definite

__all__ = [
    "ANISOTROPY_RATIO",
    "CovarianceOrder",
    "bad_covariances",
    "check_order",
    "declared_order",
    "information",
    "information_in_egnc_order",
    "order_mark",
    "reading_warning",
    "to_file_order",
]

CovarianceOrder = Literal["gtsam", "g2o"]
"""How a 3D IRL covariance is ordered: `"gtsam"` rotation first, `"g2o"` translation first."""

ANISOTROPY_RATIO = 1.5
"""Mean variances of the two 3x3 diagonal blocks further apart than this make the reading matter."""

ORDER_MARK = "egnc-covariance-order:"
"""What egnc's writer puts in a 3D log's notes line, followed by the order, so its logs need no warning."""

_GTSAM_TO_EGNC_3D = np.array([3, 4, 5, 0, 1, 2])
"""Index map from GTSAM's Pose3 tangent order `(rx, ry, rz, x, y, z)` to egnc's `(x, y, z, rx, ry, rz)`."""

_MARK_PATTERN = re.compile(re.escape(ORDER_MARK) + r"\s*(\S+)")


def check_order(covariance_order: str) -> CovarianceOrder:
    """`covariance_order` when it is one of the readings, else an `EgncError` naming them."""
    if covariance_order not in get_args(CovarianceOrder):
        raise EgncError(f"covariance_order must be 'gtsam' or 'g2o', got {covariance_order!r}")
    return covariance_order  # type: ignore[return-value]


def order_mark(covariance_order: CovarianceOrder) -> str:
    """The notes-line text that declares a log's covariance order (`"egnc-covariance-order: gtsam"`)."""
    return f"{ORDER_MARK} {covariance_order}"


def declared_order(notes: str) -> str | None:
    """The order a notes line declares with `ORDER_MARK`, or None."""
    match = _MARK_PATTERN.search(notes)
    return None if match is None else match.group(1)


def information_in_egnc_order(information: np.ndarray, dim: int, covariance_order: CovarianceOrder) -> np.ndarray:
    """`(K, d, d)` information matrices of file-order covariances, permuted to egnc's tangent order."""
    if dim == 3 and covariance_order == "gtsam":
        return information[:, _GTSAM_TO_EGNC_3D][:, :, _GTSAM_TO_EGNC_3D]
    return information  # 2D, and 3D in g2o's order, are egnc's order already


def to_file_order(covariances: np.ndarray, dim: int, covariance_order: CovarianceOrder) -> np.ndarray:
    """`(K, d, d)` covariances in egnc's tangent order, permuted to the file's."""
    if dim == 3 and covariance_order == "gtsam":
        order = np.argsort(_GTSAM_TO_EGNC_3D)
        return covariances[:, order][:, :, order]
    return covariances


def reading_warning(
    covariances: np.ndarray, dim: int, notes: str, covariance_order: CovarianceOrder | None
) -> str | None:
    """What to warn about the reading of a log's `(E, d, d)` file-order covariances, or None.

    Args:
        covariances: the file's covariances, as written.
        dim: pose dimension; 2D logs are never ambiguous.
        notes: the header's notes line, where egnc's writer declares the order.
        covariance_order: the reading the caller chose, or None when it took the default.

    Silent in 2D, on logs whose two diagonal blocks are alike (`ANISOTROPY_RATIO`), when the caller
    chose a reading, and on logs whose notes declare the reading used (egnc's writer). A reading
    other than the one the notes declare is said.
    """
    if dim != 3 or len(covariances) == 0:
        return None
    read_as = "gtsam" if covariance_order is None else covariance_order
    declared = declared_order(notes)
    if declared is not None:
        if declared == read_as:
            return None
        return (
            f"the log's notes declare covariance order {declared!r}, but it is read as {read_as!r};"
            f" read it with --irl-covariance-order {declared} (read_irl's covariance_order={declared!r})"
        )
    if covariance_order is not None:
        return None
    variances = np.einsum("...ii->...i", covariances)
    first, second = variances[:, :3].mean(), variances[:, 3:].mean()
    ratio = max(first / second, second / first)
    if not ratio > ANISOTROPY_RATIO:
        return None
    return (
        f"the 3D covariances' two diagonal blocks differ (mean variances {first:.3g} and {second:.3g},"
        f" {ratio:.1f}x), so their order matters: read as 'gtsam' (rx ry rz x y z, riSAM's C++ reader,"
        " the default); riSAM's g2o-2-irl converter writes g2o's order (x y z rx ry rz), read as 'g2o'."
        " Choose with --irl-covariance-order {gtsam,g2o} (read_irl's covariance_order)"
    )


def bad_covariances(covariances: np.ndarray) -> tuple[np.ndarray, str]:
    """Indices of the `(K, d, d)` covariances egnc cannot use, and what is wrong with the first."""
    scale = np.abs(covariances).max(axis=(1, 2))
    asymmetric = np.abs(covariances - covariances.swapaxes(1, 2)).max(axis=(1, 2)) > 1e-9 * scale
    bad = np.union1d(np.flatnonzero(asymmetric), not_positive_definite(covariances))
    if len(bad):
        return bad, "covariance is not symmetric positive definite"
    bad = not_positive_definite(information(covariances))
    return bad, "covariance is too close to singular: its inverse (the information matrix) overflows a double"


def information(covariances: np.ndarray) -> np.ndarray:
    """`(K, d, d)` symmetric inverses of symmetric positive-definite covariances (inf where they overflow)."""
    with np.errstate(all="ignore"):
        inverse = np.linalg.inv(covariances)
    return 0.5 * (inverse + inverse.swapaxes(1, 2))
