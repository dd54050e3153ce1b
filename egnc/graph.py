"""The pose-graph container: poses, relative-pose edges and their information matrices.

Poses and measurements are kept in the file's own parametrization so that reading and writing a
graph is lossless:

- 2D (SE(2)): `(x, y, theta)`, shape `(..., 3)`, metres and radians.
- 3D (SE(3)): `(x, y, z, qx, qy, qz, qw)`, shape `(..., 7)`, metres and a unit quaternion.

Information matrices are ordered translation-then-rotation, as in g2o, which is also the order of
egnc's tangent vectors (`[v, omega]`), so no permutation is ever applied.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from egnc.errors import GraphError

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

    def __post_init__(self) -> None:
        if self.dim not in POSE_SIZE:
            raise GraphError(f"dim must be 2 or 3, got {self.dim}")
        p, d = POSE_SIZE[self.dim], TANGENT_SIZE[self.dim]
        n = len(self.vertex_ids)
        e = len(self.edges)
        if self.fixed is None:
            object.__setattr__(self, "fixed", np.zeros(n, dtype=bool))
        if self.edge_lines is None:
            object.__setattr__(self, "edge_lines", np.zeros(e, dtype=np.int64))
        # Own read-only copies, so a caller's arrays are never frozen or aliased.
        for name, dtype in _DTYPES.items():
            object.__setattr__(self, name, np.array(getattr(self, name), dtype=dtype))
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
        if e and (self.edges.min() < 0 or self.edges.max() >= n):
            raise GraphError("edges refer to vertex rows outside [0, N)")
        for name in _DTYPES:
            getattr(self, name).setflags(write=False)
        object.__setattr__(self, "unknown_lines", tuple(map(str, self.unknown_lines)))

    @property
    def num_poses(self) -> int:
        """Number of poses N."""
        return len(self.vertex_ids)

    @property
    def num_edges(self) -> int:
        """Number of edges E."""
        return len(self.edges)

    @property
    def tangent_dim(self) -> int:
        """Tangent dimension d: 3 in 2D, 6 in 3D."""
        return TANGENT_SIZE[self.dim]

    @property
    def is_odometry(self) -> np.ndarray:
        """`(E,)` bool: edges joining consecutive ids in either direction (`id_j == id_i +/- 1`),
        the known inliers by default."""
        ids = self.vertex_ids[self.edges]
        return (ids[:, 1] == ids[:, 0] + 1) | (ids[:, 0] == ids[:, 1] + 1)

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
        return replace(self, poses=np.array(poses, dtype=np.float64))

    def subgraph_edges(self, keep: np.ndarray) -> PoseGraph:
        """Return a copy with only the edges where `keep` `(E,)` bool is true (poses unchanged)."""
        keep = np.asarray(keep, dtype=bool)
        return replace(
            self,
            edges=self.edges[keep],
            measurements=self.measurements[keep],
            information=self.information[keep],
            edge_lines=self.edge_lines[keep],
        )
