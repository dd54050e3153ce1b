"""What the `add_*` calls of an online solver take in: checked entries, held until the next update.

Every call checks what it is given (integer ids, finite numbers of the right shape, symmetric
positive-definite information, quaternions that normalize, known poses) and raises `GraphError`
before taking anything in; what passes waits in `Pending` until `OnlineSolver.update()` takes it
into the map (`egnc.online.state.MapState.integrate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from egnc.errors import GraphError
from egnc.graph import POSE_SIZE, TANGENT_SIZE
from egnc.graph.checks import describe
from egnc.graph.validity import first_bad_quaternion

__all__ = ["Intake", "Pending", "id_pair", "one_row", "vertex_id"]


@dataclass
class Pending:
    """Entries added since the last update, in arrival order."""

    pose_ids: list[int] = field(default_factory=list)
    pose_values: list[np.ndarray | None] = field(default_factory=list)
    edge_ids: list[tuple[int, int]] = field(default_factory=list)
    measurements: list[np.ndarray] = field(default_factory=list)
    information: list[np.ndarray] = field(default_factory=list)
    robust: list[bool] = field(default_factory=list)
    prior: tuple[int, np.ndarray] | None = None

    def __bool__(self) -> bool:
        return bool(self.pose_ids or self.edge_ids or self.prior is not None)


class Intake:
    """The checked entries of the `add_*` calls, and the vertex ids known so far.

    Attributes:
        dim: 2 or 3.
        known_ids: every vertex id added, taken in or pending.
        pending: the entries the next update takes in.
    """

    def __init__(self, dim: int):
        self.dim = dim
        self.known_ids: set[int] = set()
        self.pending = Pending()

    def take(self) -> Pending:
        """The pending entries, leaving none."""
        pending, self.pending = self.pending, Pending()
        return pending

    def add_poses(self, vertex_ids: ArrayLike, poses: ArrayLike | None) -> None:
        """Poses `vertex_ids` `(K,)` with initial guesses `poses` `(K, P)`, or None (placed by odometry)."""
        ids = _ids(vertex_ids, 1)
        values = None if poses is None else self._poses_array(poses, len(ids), "poses")
        if len(set(ids.tolist())) < len(ids) or self.known_ids.intersection(ids.tolist()):
            raise GraphError(f"a pose among {ids[:5].tolist()} was already added")
        for k, added in enumerate(ids.tolist()):
            self.known_ids.add(added)
            self.pending.pose_ids.append(added)
            self.pending.pose_values.append(None if values is None else values[k])

    def add_prior(self, vertex: int, pose: ArrayLike, has_prior: bool) -> None:
        """Hold pose `vertex` at `pose` `(P,)`; `has_prior`: whether the map holds one already."""
        if has_prior or self.pending.prior is not None:
            raise GraphError("a second prior: the online solver uses one prior as the gauge")
        value = self._poses_array(one_row(pose), 1, "prior pose")[0]
        vertex = vertex_id(vertex)
        if vertex not in self.known_ids:
            self.add_poses([vertex], one_row(value))
        self.pending.prior = (vertex, value)

    def add_edges(
        self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike, robust: bool, num_edges: int
    ) -> np.ndarray:
        """Edges `ids` `(K, 2)` with `measurements` `(K, P)` and `information` `(K, d, d)`, loop
        closures if `robust`; returns their indices `(K,)`, after the map's `num_edges` edges."""
        pairs = _ids(ids, 2)
        k = len(pairs)
        d = TANGENT_SIZE[self.dim]
        values = self._poses_array(measurements, k, "measurements")
        info = _array(information, (k, d, d), "information")
        if not np.allclose(info, info.swapaxes(1, 2), rtol=1e-9, atol=0.0):
            raise GraphError("information matrices must be symmetric")
        if k and np.any(np.linalg.eigvalsh(0.5 * (info + info.swapaxes(1, 2)))[:, 0] <= 0.0):
            raise GraphError("information matrices must be positive definite")
        self._check_ends(pairs, robust)
        first = num_edges + len(self.pending.edge_ids)
        for (i, j), value, matrix in zip(pairs.tolist(), values, info):
            for end in (i, j):
                if end not in self.known_ids:
                    self.known_ids.add(end)
                    self.pending.pose_ids.append(end)
                    self.pending.pose_values.append(None)
            self.pending.edge_ids.append((i, j))
            self.pending.measurements.append(value)
            self.pending.information.append(matrix)
            self.pending.robust.append(robust)
        return np.arange(first, first + k)

    def _check_ends(self, pairs: np.ndarray, robust: bool) -> None:
        """Refuse edges `pairs` `(K, 2)` that join a pose to itself, loop closures to an unknown
        pose, and odometry between two unknown poses."""
        reached: set[int] = set()  # ends of this batch's edges so far: an edge may start where an earlier one ends
        for i, j in pairs.tolist():
            if i == j:
                raise GraphError(f"an edge joins pose {i} to itself")
            known_i = i in self.known_ids or i in reached
            known_j = j in self.known_ids or j in reached
            if robust and not (known_i and known_j):
                missing = j if known_i else i
                raise GraphError(f"loop closure ({i}, {j}): pose {missing} is not known; add it or its odometry first")
            if not robust and not known_i and not known_j:
                raise GraphError(f"odometry ({i}, {j}) joins two unknown poses: one end must be known")
            reached.update((i, j))

    def _poses_array(self, values: ArrayLike, count: int, name: str) -> np.ndarray:
        """`values` as `(count, P)` float64 poses, finite, with quaternions that normalize in 3D."""
        array = _array(values, (count, POSE_SIZE[self.dim]), name)
        found = first_bad_quaternion(array[:, 3:7]) if self.dim == 3 else None
        if found:
            where = f" row {found[0]}" if count > 1 else ""
            raise GraphError(f"{name}{where}: {found[1]}")
        return array


def vertex_id(value: object) -> int:
    """One vertex id as an int; it must be an integer (bools refused; the range is `_ids`'s to check)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise GraphError(f"vertex ids must be integers, got {describe(value)}")
    return int(value)


def id_pair(i: int, j: int) -> ArrayLike:
    """The ids of one edge as a one-row batch for `Intake.add_edges`."""
    return [[vertex_id(i), vertex_id(j)]]


def one_row(value: object) -> ArrayLike:
    """`value` as a one-row batch, unconverted: junk or ragged input fails in `_array`, which names it."""
    return cast(ArrayLike, [value])


def _ids(values: ArrayLike, width: int) -> np.ndarray:
    """Vertex ids as int64, `(K,)` for `width` 1 or `(K, 2)` for 2; non-negative."""
    try:
        array = np.asarray(values)
    except ValueError:  # ragged nesting
        raise GraphError(f"vertex ids must be integers, got {describe(values)}") from None
    if array.dtype.kind not in "iu":
        raise GraphError(f"vertex ids must be integers, got {array.dtype}")
    if array.size % width:
        raise GraphError(f"edge ids come in pairs, got {array.size} ids")
    array = array.astype(np.int64).reshape(-1) if width == 1 else array.astype(np.int64).reshape(-1, 2)
    if np.any(array < 0):
        raise GraphError("vertex ids must be non-negative")
    return array


def _array(values: ArrayLike, shape: tuple[int, ...], name: str) -> np.ndarray:
    """`values` as float64 of exactly `shape`, finite."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):  # not numbers, or ragged nesting
        raise GraphError(f"{name} must be numbers of shape {shape}") from None
    if array.shape != shape:
        raise GraphError(f"{name} has shape {array.shape}, expected {shape}")
    if not np.all(np.isfinite(array)):
        raise GraphError(f"{name} holds NaN or infinite values")
    return array
