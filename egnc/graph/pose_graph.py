"""The pose-graph container: poses, relative-pose edges and their information matrices.

Poses and measurements are kept in the file's own parametrization so that reading and writing a
graph is lossless:

- 2D (SE(2)): `(x, y, theta)`, shape `(..., 3)`, metres and radians.
- 3D (SE(3)): `(x, y, z, qx, qy, qz, qw)`, shape `(..., 7)`, metres and a unit quaternion.

Information matrices are ordered translation-then-rotation, as in g2o, which is also the order of
egnc's tangent vectors (`[v, omega]`), so no permutation is ever applied.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from egnc.errors import GraphError, OptionError
from egnc.graph.checks import check_int, describe
from egnc.graph.priors import Priors
from egnc.graph.validity import (
    NO_EDGES,
    first_bad_quaternion,
    first_self_edge,
    not_positive_definite,
    not_positive_definite_message,
)

POSE_SIZE = {2: 3, 3: 7}
"""Number of stored parameters per pose, by spatial dimension."""

TANGENT_SIZE = {2: 3, 3: 6}
"""Tangent-space dimension d of SE(2) and SE(3)."""

_DTYPES = {
    "vertex_ids": np.int64,
    "poses": np.float64,
    "edges": np.int64,
    "measurements": np.float64,
    "information": np.float64,
    "fixed": bool,
    "edge_lines": np.int64,
}


_OWNED: weakref.WeakValueDictionary[int, np.ndarray] = weakref.WeakValueDictionary()
"""The arrays `PoseGraph` holds, by `id`: read-only views of private copies, so no caller can make them
writable again (`setflags(write=True)` is refused on a view of a read-only array). Being immutable
and already checked, they are shared by the graphs derived from one another (`with_poses`,
`dataclasses.replace`) instead of being copied and checked again."""


def is_dim(value: object) -> bool:
    """Whether `value` is the integer 2 or 3 (NumPy integers too; bools and floats are not)."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, np.integer)) and value in POSE_SIZE


def _private_copy(name: str, value: object, dtype: type) -> np.ndarray:
    """A read-only view of a new copy of `value` as `dtype`: its base is not the caller's array.

    Raises:
        GraphError: `value` holds something other than numbers, non-integers for an integer
            field (NumPy would truncate 1.5 to 1 without a word), or for a bool field anything
            but True/False or 0/1 (NumPy would take None for False and 0.5 for True).
    """
    try:
        source = np.asarray(value)
        if np.issubdtype(dtype, np.integer) and source.dtype.kind == "f" and not np.all(np.mod(source, 1) == 0):
            raise ValueError("not integers")
        if dtype is bool and source.dtype.kind != "b" and not _zeros_and_ones(source):
            raise GraphError(f"{name} must be an array of bools (True/False or 0/1), {_first_non_bool(source)}")
        copy: np.ndarray = np.array(source, dtype=dtype)
    except (TypeError, ValueError):
        kind = "integers" if np.issubdtype(dtype, np.integer) else "bools" if dtype is bool else "numbers"
        raise GraphError(f"{name} must be an array of {kind}, got {describe(value)}") from None
    copy.setflags(write=False)
    view = copy.view()
    _OWNED[id(view)] = view
    return view


def _zeros_and_ones(source: np.ndarray) -> bool:
    """Whether a non-bool array holds only the numbers 0 and 1 (so `None`, `0.5`, `"no"` are not bools)."""
    return source.dtype.kind in "iuf" and bool(np.all((source == 0) | (source == 1)))


def _first_non_bool(source: np.ndarray) -> str:
    """`"element k is X"` for the first element of `source` that is neither a bool nor 0 or 1."""
    for k, item in enumerate(source.ravel().tolist()):
        if not (isinstance(item, (bool, int, float)) and item in (0, 1)):
            return f"element {k} is {describe(item)}"
    return f"got {describe(source)}"  # not reached for an array `_zeros_and_ones` refused


def _lines(value: object) -> tuple[str, ...]:
    """`unknown_lines` as a tuple of str; a str itself is refused (a tuple of it is one character a line)."""
    if isinstance(value, (str, bytes, bytearray)) or not isinstance(value, Sequence):
        raise GraphError(f"unknown_lines must be a sequence of lines (str), got a {type(value).__name__}")
    for k, line in enumerate(value):
        if not isinstance(line, str):
            raise GraphError(f"unknown_lines must hold lines (str): element {k} is {describe(line)}")
    return tuple(value)


def _is_owned(value: object) -> bool:
    """Whether `value` is an array some `PoseGraph` made with `_private_copy`."""
    return isinstance(value, np.ndarray) and _OWNED.get(id(value)) is value


@dataclass(frozen=True, eq=False)
class PoseGraph:
    """An immutable pose graph.

    Attributes:
        dim: spatial dimension, 2 or 3.
        vertex_ids: `(N,)` int64, the ids used in the file, sorted ascending and unique.
        poses: `(N, P)` float64 initial guess (P = 3 in 2D, 7 in 3D), row k belongs to `vertex_ids[k]`.
        edges: `(E, 2)` int64 row indices `(i, j)` into `poses`; the edge measures `X_i^-1 X_j`.
            Edges are kept in input-file order.
        measurements: `(E, P)` float64 relative poses `Z_ij`, same parametrization as `poses`.
        information: `(E, d, d)` float64 symmetric positive-definite information matrices.
        fixed: `(N,)` bool, vertices held constant (g2o `FIX`, and vertices no edge touches); when
            none is fixed the solver fixes vertex 0 to remove the gauge freedom.
        edge_lines: `(E,)` int64 1-based source line of each edge (0 when not read from a file).
        unknown_lines: lines of the source file with tags egnc does not read (landmarks,
            parameters, ...), verbatim, kept by `read_g2o(skip_unknown=True)` so that
            `write_g2o` writes them back.
        priors: the absolute measurements of single poses (`egnc.graph.priors.Priors`), none by
            default. Edges and priors together are the graph's factors, numbered in file order
            (`edge_factor_index`, `prior_factor_index`).

    The constructor checks what the readers check (`egnc.graph.validity`, same wording, naming the edge
    index): at least one edge, no edge from a vertex to itself, positive-definite information,
    normalizable measurement quaternions; and unique sorted ids, shapes, edge rows in range. It
    raises `GraphError`. The arrays are read-only views of private copies, so neither the
    caller's arrays nor the graph can be changed through the other.
    """

    dim: int
    vertex_ids: np.ndarray
    poses: np.ndarray
    edges: np.ndarray
    measurements: np.ndarray
    information: np.ndarray
    fixed: np.ndarray = field(default=None)  # type: ignore[arg-type]
    edge_lines: np.ndarray = field(default=None)  # type: ignore[arg-type]
    unknown_lines: tuple[str, ...] = ()
    priors: Priors = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if not is_dim(self.dim):
            raise GraphError(f"dim must be 2 or 3, got {describe(self.dim)}")
        object.__setattr__(self, "dim", int(self.dim))
        p, d = POSE_SIZE[self.dim], TANGENT_SIZE[self.dim]
        given = {name for name in _DTYPES if name not in ("fixed", "edge_lines") or getattr(self, name) is not None}
        new = {name for name in given if not _is_owned(getattr(self, name))}
        for name in new:
            object.__setattr__(self, name, _private_copy(name, getattr(self, name), _DTYPES[name]))
        n = len(self.vertex_ids) if self.vertex_ids.ndim else 0
        e = len(self.edges) if self.edges.ndim else 0
        if "fixed" not in given:
            object.__setattr__(self, "fixed", _private_copy("fixed", np.zeros(n), bool))
        if "edge_lines" not in given:
            object.__setattr__(self, "edge_lines", _private_copy("edge_lines", np.zeros(e), np.int64))
        expected = {
            "vertex_ids": (n,),
            "poses": (n, p),
            "edges": (e, 2),
            "measurements": (e, p),
            "information": (e, d, d),
            "fixed": (n,),
            "edge_lines": (e,),
        }
        for name, shape in expected.items():
            actual = np.shape(getattr(self, name))
            if actual != shape:
                raise GraphError(f"{name} has shape {actual}, expected {shape}")
        self._check_edges(new)
        object.__setattr__(self, "unknown_lines", _lines(self.unknown_lines))
        self._check_priors()

    def _check_priors(self) -> None:
        """Default to no prior; a given one must be a `Priors` of this dimension on rows in range."""
        if self.priors is None:
            object.__setattr__(self, "priors", Priors.empty(self.dim))
        if not isinstance(self.priors, Priors):
            raise GraphError(f"priors must be an egnc.graph.priors.Priors, got {describe(self.priors)}")
        if self.priors.dim != self.dim:
            raise GraphError(f"priors are {self.priors.dim}D but the graph is {self.dim}D")
        if len(self.priors) and (self.priors.rows.min() < 0 or self.priors.rows.max() >= self.num_poses):
            raise GraphError("priors refer to vertex rows outside [0, N)")

    def _check_edges(self, new: set[str]) -> None:
        """The reader's checks (`egnc.graph.validity`), on the arrays not already checked by another graph."""
        if not self.num_edges:
            raise GraphError(f"no edges: {NO_EDGES}")
        # Compared, not subtracted: np.diff of int64 ids wraps around at the limits (int64 min to 1 is negative).
        if "vertex_ids" in new and np.any(self.vertex_ids[1:] <= self.vertex_ids[:-1]):
            raise GraphError("vertex_ids must be sorted ascending and unique")
        if self.edges.min() < 0 or self.edges.max() >= self.num_poses:
            raise GraphError("edges refer to vertex rows outside [0, N)")
        found = first_self_edge(self.vertex_ids[self.edges])
        if found:
            raise GraphError(f"edge {found[0]}: {found[1]}")
        if self.dim == 3 and "measurements" in new:
            found = first_bad_quaternion(self.measurements[:, 3:7])
            if found:
                raise GraphError(f"edge {found[0]}: measurement {found[1]}")
        if "information" in new:
            bad = not_positive_definite(self.information)
            if len(bad):
                raise GraphError(f"edge {bad[0]}: {not_positive_definite_message(self.information, bad)}")

    def __repr__(self) -> str:
        """Sizes only: the arrays of a real graph would fill the screen."""
        return (
            f"PoseGraph(dim={self.dim}, poses={self.num_poses}, edges={self.num_edges},"
            f" loop_closures={int(np.count_nonzero(self.is_loop_closure))}, fixed={int(np.count_nonzero(self.fixed))}"
            + (f", priors={len(self.priors)})" if len(self.priors) else ")")
        )

    @property
    def num_poses(self) -> int:
        """Number of poses N."""
        return len(self.vertex_ids)

    @property
    def num_edges(self) -> int:
        """Number of edges E."""
        return len(self.edges)

    @property
    def num_priors(self) -> int:
        """Number of priors K."""
        return len(self.priors)

    @property
    def edge_factor_index(self) -> np.ndarray:
        """`(E,)` int64 factor index of each edge: its rank among the edges and priors in file
        order (source line; without lines, edges before priors). `arange(E)` without priors."""
        return self._factor_index()[: self.num_edges]

    @property
    def prior_factor_index(self) -> np.ndarray:
        """`(K,)` int64 factor index of each prior (`edge_factor_index`)."""
        return self._factor_index()[self.num_edges :]

    def _factor_index(self) -> np.ndarray:
        """`(E + K,)` factor index of the edges then the priors."""
        if not self.num_priors:
            return np.arange(self.num_edges)
        order = np.argsort(np.concatenate((self.edge_lines, self.priors.lines)), kind="stable")
        index = np.empty(len(order), dtype=np.int64)
        index[order] = np.arange(len(order))
        return index

    @property
    def tangent_dim(self) -> int:
        """Tangent dimension d: 3 in 2D, 6 in 3D."""
        return TANGENT_SIZE[self.dim]

    @property
    def is_odometry(self) -> np.ndarray:
        """`(E,)` bool: edges joining consecutive ids in either direction (`id_j == id_i +/- 1`),
        the known inliers by default."""
        ids = self.vertex_ids[self.edges]
        low, high = ids.min(axis=1), ids.max(axis=1)
        # `high - 1` cannot wrap unless high is int64's minimum, and then it is not `low`; `low + 1`
        # would wrap at int64's maximum and call an edge from the largest id to the smallest odometry.
        return high - 1 == low

    @property
    def is_loop_closure(self) -> np.ndarray:
        """`(E,)` bool: every edge that is not odometry."""
        return ~self.is_odometry

    @property
    def is_duplicate(self) -> np.ndarray:
        """`(E,)` bool: edges joining the same two vertices as an earlier edge, in either direction."""
        pairs = np.sort(self.edges, axis=1)
        # One int64 key per unordered pair: 1-D unique is several times faster than unique(axis=0).
        _, first = np.unique(pairs[:, 0] * self.num_poses + pairs[:, 1], return_index=True)
        duplicate = np.ones(self.num_edges, dtype=bool)
        duplicate[first] = False
        return duplicate

    def with_poses(self, poses: np.ndarray) -> PoseGraph:
        """Return a copy of the graph with new poses `(N, P)`, e.g. an optimized trajectory."""
        return replace(self, poses=poses)

    def first_poses(self, count: int) -> PoseGraph:
        """The graph of the first `count` poses (rows) and the edges among them: what a log holds
        after its `count`-th pose (a replay's prefix, a small piece of a large file). The lines of
        unknown tags are left out (they may name later vertices).

        Raises:
            OptionError: `count` is not an integer from 1 to `num_poses`.
            GraphError: no edge joins two of those poses.
        """
        count = check_int("count", count, 1)
        if count > self.num_poses:
            raise OptionError(f"count must be at most the {self.num_poses} poses, got {count}")
        keep = (self.edges < count).all(axis=1)
        keep_priors = self.priors.rows < count
        return PoseGraph(
            self.dim,
            self.vertex_ids[:count],
            self.poses[:count],
            self.edges[keep],
            self.measurements[keep],
            self.information[keep],
            fixed=self.fixed[:count],
            edge_lines=self.edge_lines[keep],
            priors=self.priors.subset(keep_priors),
        )

    def subgraph_edges(self, keep: np.ndarray) -> PoseGraph:
        """Return a copy with only the edges where `keep` `(E,)` bool is true (poses unchanged).

        Raises:
            OptionError: `keep` is not an `(E,)` bool mask.
            GraphError: no edge is kept.
        """
        keep = np.asarray(keep)
        if keep.dtype != bool or keep.shape != (self.num_edges,):
            raise OptionError(
                f"keep must be a bool mask of shape ({self.num_edges},), got dtype {keep.dtype} and shape {keep.shape}"
            )
        return replace(
            self,
            edges=self.edges[keep],
            measurements=self.measurements[keep],
            information=self.information[keep],
            edge_lines=self.edge_lines[keep],
        )
