"""What the `add_*` calls of an online solver take in: checked entries, held until the next update.

Every call checks what it is given (integer ids within int64, finite numbers of the right shape,
symmetric positive-definite information, quaternions that normalize, known poses) and raises
`GraphError` before taking anything in; a new edge a double cannot represent at the current
estimate (`egnc.graph.health`, as the batch solve checks a graph) raises `NumericalError`. What
passes waits in `Pending` until `OnlineSolver.update()` takes it into the map
(`egnc.online.state.MapState.integrate`). An empty batch adds nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, cast

import numpy as np
from numpy.typing import ArrayLike

from egnc.errors import GraphError
from egnc.graph import POSE_SIZE, TANGENT_SIZE
from egnc.graph.checks import check_vertex_ids, describe
from egnc.graph.health import UnrepresentableError, coarse_edges
from egnc.graph.priors import POSE
from egnc.graph.validity import first_bad_quaternion

__all__ = ["Estimate", "Intake", "Pending", "id_pair", "one_row", "vertex_id"]


_LARGEST = float(np.finfo(float).max)


class Estimate(Protocol):
    """What the intake reads of the map (`egnc.online.state.MapState`): its poses and edges."""

    row: dict[int, int]
    T: np.ndarray
    edges: np.ndarray
    information: np.ndarray


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
    prior_ids: list[int] = field(default_factory=list)  # measurement priors (egnc.online.priors)
    prior_kinds: list[int] = field(default_factory=list)
    prior_measurements: list[np.ndarray] = field(default_factory=list)
    prior_information: list[np.ndarray] = field(default_factory=list)
    prior_known: list[bool] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.pose_ids or self.edge_ids or self.prior is not None or self.prior_ids)


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
        self._reach: dict[int, float] = {}  # pending poses: a bound on their largest coordinate, metres

    def take(self) -> Pending:
        """The pending entries, leaving none."""
        pending, self.pending = self.pending, Pending()
        self._reach = {}
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
            if values is not None:
                self._reach[added] = float(np.abs(values[k, : self.dim]).max())

    def add_prior(self, vertex: int, pose: ArrayLike, has_prior: bool, estimate: Estimate) -> None:
        """Hold pose `vertex` at `pose` `(P,)`; `has_prior`: whether the map holds one already.

        The map moves rigidly onto the prior: its edges must stay representable there.
        """
        if has_prior or self.pending.prior is not None:
            raise GraphError("a second prior: the online solver uses one prior as the gauge")
        value = self._poses_array(one_row(pose), 1, "prior pose")[0]
        vertex = vertex_id(vertex)
        if len(estimate.edges):
            extent = float(np.abs(estimate.T[:, : self.dim, self.dim]).max())
            far = float(np.abs(value[: self.dim]).max()) + 2.0 * extent  # bounds the moved map's coordinates
            found = coarse_edges(np.full(len(estimate.edges), far), estimate.information, self.dim)
            if found is not None:
                raise UnrepresentableError(
                    f"prior on pose {vertex}: moved onto it, the map cannot be represented in double precision:"
                    f" edge {found[1]} {found[2]}",
                    found[1],
                )
        if vertex not in self.known_ids:
            self.add_poses([vertex], one_row(value))
        self.pending.prior = (vertex, value)

    def add_measurement_priors(
        self, kind: int, ids: ArrayLike, values: ArrayLike, information: ArrayLike, known: bool, first: int
    ) -> np.ndarray:
        """Priors of `kind` (`POSE` or `POSITION`, `egnc.graph.priors`) on poses `ids` `(K,)`:
        `values` `(K, P)` poses or `(K, dim)` positions, `information` `(K, m, m)`, known inliers if
        `known`; returns their prior indices `(K,)`, from `first` (the priors before them)."""
        vertices = _ids(ids, 1)
        k, dim, d = len(vertices), self.dim, TANGENT_SIZE[self.dim]
        m = d if kind == POSE else dim
        name = "prior poses" if kind == POSE else "prior positions"
        array = self._poses_array(values, k, name) if kind == POSE else _array(values, (k, dim), name)
        info = _array(information, (k, m, m), "prior information")
        _check_information(info)
        unknown = [vertex for vertex in vertices.tolist() if vertex not in self.known_ids]
        if unknown:
            raise GraphError(f"prior on pose {unknown[0]}: the pose is not known; add it or its odometry first")
        padded_values = np.zeros((k, POSE_SIZE[dim]))
        padded_values[:, : array.shape[1]] = array
        padded_info = np.zeros((k, d, d))
        padded_info[:, :m, :m] = info
        first += len(self.pending.prior_ids)
        for vertex, value, matrix in zip(vertices.tolist(), padded_values, padded_info):
            self.pending.prior_ids.append(vertex)
            self.pending.prior_kinds.append(kind)
            self.pending.prior_measurements.append(value)
            self.pending.prior_information.append(matrix)
            self.pending.prior_known.append(known)
        return np.arange(first, first + k)

    def add_edges(
        self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike, robust: bool, estimate: Estimate
    ) -> np.ndarray:
        """Edges `ids` `(K, 2)` with `measurements` `(K, P)` and `information` `(K, d, d)`, loop
        closures if `robust`; returns their indices `(K,)`, after the edges of the map `estimate`."""
        pairs = _ids(ids, 2)
        k = len(pairs)
        d = TANGENT_SIZE[self.dim]
        values = self._poses_array(measurements, k, "measurements")
        info = _array(information, (k, d, d), "information")
        _check_information(info)
        self._check_ends(pairs, robust)
        first = len(estimate.edges) + len(self.pending.edge_ids)
        self._check_representable(pairs, values, info, robust, estimate, first)
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

    def _check_representable(
        self, pairs: np.ndarray, values: np.ndarray, info: np.ndarray, robust: bool, estimate: Estimate, first: int
    ) -> None:
        """Refuse new edges `pairs` `(K, 2)` that a double cannot represent at the current `estimate`
        (`egnc.graph.health`): the batch solve's rule, on each edge's poses and measurement. A pose
        this batch places gets the bound of the pose it is composed from plus the step's length."""
        if not len(pairs):
            return
        dim = self.dim
        step = np.abs(values[:, :dim]).max(axis=1)
        rows = np.array([estimate.row.get(end, -1) for end in pairs.ravel().tolist()], dtype=np.int64)
        in_map = np.abs(estimate.T[np.maximum(rows, 0), :dim, dim]).max(axis=1) if len(estimate.T) else rows * 0.0
        scale = np.maximum(step, np.where(rows >= 0, in_map, 0.0).reshape(-1, 2).max(axis=1))
        root = math.sqrt(dim)  # times the largest coordinate, it bounds a step's length
        reach = dict(self._reach)  # not kept unless the whole batch passes
        for k in np.flatnonzero((rows < 0).reshape(-1, 2).any(axis=1)).tolist():  # edges to poses not in the map
            i, j = pairs[k].tolist()
            ends = [
                float(in_map[2 * k + e]) if rows[2 * k + e] >= 0 else reach.get(end) for e, end in enumerate((i, j))
            ]
            for e, end in enumerate((i, j)):
                other = ends[1 - e]
                if ends[e] is None and other is not None:
                    ends[e] = reach[end] = min(other + root * float(step[k]), _LARGEST)  # placed by composing this edge
            scale[k] = max(float(scale[k]), *(end or 0.0 for end in ends))
        found = coarse_edges(scale, info, dim)
        if found is not None:
            count, worst, why = found
            i, j = pairs[worst].tolist()
            kind = "loop closure" if robust else "odometry"
            raise UnrepresentableError(
                f"{kind} ({i}, {j}) cannot be represented in double precision at the current estimate: it {why}"
                + (f" ({count} of the {len(pairs)} new edges)" if count > 1 else ""),
                first + worst,
            )
        self._reach = reach

    def _poses_array(self, values: ArrayLike, count: int, name: str) -> np.ndarray:
        """`values` as `(count, P)` float64 poses, finite, with quaternions that normalize in 3D."""
        array = _array(values, (count, POSE_SIZE[self.dim]), name)
        found = first_bad_quaternion(array[:, 3:7]) if self.dim == 3 else None
        if found:
            where = f" row {found[0]}" if count > 1 else ""
            raise GraphError(f"{name}{where}: {found[1]}")
        return array


def _check_information(info: np.ndarray) -> None:
    """Refuse information matrices `(K, m, m)` that are not symmetric positive definite."""
    if not np.allclose(info, info.swapaxes(1, 2), rtol=1e-9, atol=0.0):
        raise GraphError("information matrices must be symmetric")
    if len(info) and np.any(np.linalg.eigvalsh(0.5 * (info + info.swapaxes(1, 2)))[:, 0] <= 0.0):
        raise GraphError("information matrices must be positive definite")


def vertex_id(value: object) -> int:
    """One vertex id as an int; it must be an integer within int64 (bools refused; `_ids` checks the sign)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise GraphError(f"vertex ids must be integers, got {describe(value)}")
    return int(check_vertex_ids("vertex id", value, GraphError))


def id_pair(i: int, j: int) -> ArrayLike:
    """The ids of one edge as a one-row batch for `Intake.add_edges`."""
    return [[vertex_id(i), vertex_id(j)]]


def one_row(value: object) -> ArrayLike:
    """`value` as a one-row batch, unconverted: junk or ragged input fails in `_array`, which names it."""
    return cast(ArrayLike, [value])


def _ids(values: ArrayLike, width: int) -> np.ndarray:
    """Vertex ids as int64, `(K,)` for `width` 1 or `(K, 2)` for 2; non-negative. `[]` is an empty batch."""
    array = check_vertex_ids("vertex ids", values, GraphError)
    if array.size % width:
        raise GraphError(f"edge ids come in pairs, got {array.size} ids")
    array = array.reshape(-1) if width == 1 else array.reshape(-1, 2)
    if np.any(array < 0):
        raise GraphError("vertex ids must be non-negative")
    return array


def _array(values: ArrayLike, shape: tuple[int, ...], name: str) -> np.ndarray:
    """`values` as float64 of exactly `shape`, finite; of an empty batch (`shape[0] == 0`), any empty array."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):  # not numbers, or ragged nesting
        raise GraphError(f"{name} must be numbers of shape {shape}") from None
    if shape[0] == 0 and array.size == 0:
        return np.zeros(shape)
    if array.shape != shape:
        raise GraphError(f"{name} has shape {array.shape}, expected {shape}")
    if not np.all(np.isfinite(array)):
        raise GraphError(f"{name} holds NaN or infinite values")
    return array
