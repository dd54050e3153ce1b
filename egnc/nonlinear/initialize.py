"""Initial guess for poses that a file does not provide: compose measurements along a spanning tree.

A breadth-first spanning tree is grown at once from every pose whose value is known (the roots);
when none is known, from row 0 (the lowest id), which is placed at the identity. Each other pose
is then `X_child = X_parent Z` along its tree edge (`Z^-1` when the edge points the other way), so
every tree edge has zero residual. A breadth-first tree keeps paths from the roots short, which
limits the drift accumulated along them.

Composition is vectorized by pointer jumping: every pose holds its transform relative to an
ancestor, and each pass replaces the ancestor by the ancestor's ancestor,
`T_a(a(v))_v = T_a(a(v))_a(v) T_a(v)_v`, for all poses at once. After `ceil(log2(depth + 1))`
passes every pose is expressed in the world frame, so even a pure odometry chain of N poses takes
about log2(N) NumPy passes rather than N.
"""

from __future__ import annotations

import numpy as np

from egnc.errors import GraphError
from egnc.graph import POSE_SIZE
from egnc.lie import se2, se3

_NO_PARENT = -1


def spanning_tree(num_poses: int, edges: np.ndarray, roots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grow one breadth-first spanning forest from all `roots` at once.

    Args:
        num_poses: number of poses N.
        edges: `(E, 2)` int row indices `(i, j)`; direction is ignored for the tree.
        roots: `(R,)` int rows the tree starts from (R >= 1).

    Returns:
        `(parent, tree_edge)`, both `(N,)` int64: the parent row of each pose and the index of the
        edge joining it to its parent, `-1` for roots. Among parallel edges the first in `edges`
        order is used.

    Raises:
        GraphError: some pose is not connected to any root.
    """
    # Imported here: csgraph pulls in scipy.sparse.linalg and scipy.linalg (0.1 s), and only files
    # with poses missing, or `init="odometry"`, grow a tree.
    import scipy.sparse
    import scipy.sparse.csgraph

    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    roots = np.unique(np.asarray(roots, dtype=np.int64))
    if len(roots) == 0:
        raise GraphError("spanning tree needs at least one root pose")
    # A virtual node N joined to every root turns the multi-source BFS into a single-source one.
    virtual = num_poses
    heads = np.concatenate((edges[:, 0], np.full(len(roots), virtual)))
    tails = np.concatenate((edges[:, 1], roots))
    adjacency = scipy.sparse.csr_array(
        (np.ones(len(heads), dtype=np.int8), (heads, tails)), shape=(num_poses + 1, num_poses + 1)
    )
    _, predecessors = scipy.sparse.csgraph.breadth_first_order(
        adjacency, virtual, directed=False, return_predecessors=True
    )
    parent = predecessors[:num_poses].astype(np.int64)
    unreached = np.flatnonzero(parent < 0)
    if len(unreached):
        raise GraphError(
            f"cannot initialize: {len(unreached)} pose(s) (rows {unreached[:5].tolist()}...) "
            "are not connected to any pose with a known value"
        )
    parent[parent == virtual] = _NO_PARENT

    # Find the edge for each (parent, child) pair via sorted undirected keys lo * N + hi.
    key_of_edge = edges.min(axis=1) * num_poses + edges.max(axis=1)
    order = np.argsort(key_of_edge, kind="stable")
    children = np.flatnonzero(parent != _NO_PARENT)
    pair_key = np.minimum(parent[children], children) * num_poses + np.maximum(parent[children], children)
    tree_edge = np.full(num_poses, _NO_PARENT, dtype=np.int64)
    tree_edge[children] = order[np.searchsorted(key_of_edge[order], pair_key)]
    return parent, tree_edge


def compose_along_tree(
    dim: int,
    parent: np.ndarray,
    tree_edge: np.ndarray,
    edges: np.ndarray,
    measurements: np.ndarray,
    root_poses: np.ndarray,
) -> np.ndarray:
    """Compose edge measurements down a spanning tree.

    Args:
        dim: 2 or 3.
        parent, tree_edge: `(N,)` from `spanning_tree`.
        edges: `(E, 2)` int row indices; edge `k` measures `X_i^-1 X_j`.
        measurements: `(E, P)` relative poses `Z_ij` in the file parametrization.
        root_poses: `(N, P)` poses; only the rows of roots (`parent == -1`) are used.

    Returns:
        `(N, P)` poses: roots as given, every other pose `X_parent Z` (or `X_parent Z^-1`).
    """
    group, from_params, to_params = _GROUPS[dim]
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    children = np.flatnonzero(parent != _NO_PARENT)
    roots = np.flatnonzero(parent == _NO_PARENT)
    n = len(parent)
    size = dim + 1

    # T[v] is the transform from ancestor[v]'s frame to v's; roots are relative to the world.
    T = np.empty((n, size, size))
    T[roots] = from_params(np.asarray(root_poses)[roots])
    k = tree_edge[children]
    Z = from_params(np.asarray(measurements)[k])
    forward = edges[k, 0] == parent[children]
    T[children] = np.where(forward[:, None, None], Z, group.inverse(Z))

    ancestor = np.asarray(parent, dtype=np.int64).copy()
    pending = children
    while len(pending):
        up = ancestor[pending]
        T[pending] = group.compose(T[up], T[pending])
        ancestor[pending] = ancestor[up]
        pending = pending[ancestor[pending] != _NO_PARENT]

    poses = to_params(T)
    # Roots keep their exact input values (no round trip through matrices).
    poses[roots] = np.asarray(root_poses)[roots]
    return poses


def initialize_poses(
    dim: int,
    edges: np.ndarray,
    measurements: np.ndarray,
    *,
    poses: np.ndarray | None = None,
    known: np.ndarray | None = None,
) -> np.ndarray:
    """Return an initial guess: known poses kept, all others composed along a BFS spanning tree.

    Args:
        dim: 2 or 3.
        edges: `(E, 2)` int row indices `(i, j)`, each measuring `X_i^-1 X_j`.
        measurements: `(E, P)` relative poses `Z_ij`, `(x, y, theta)` or
            `(x, y, z, qx, qy, qz, qw)`.
        poses: `(N, P)` poses whose `known` rows are kept; None means none is known and N is
            taken from the edges.
        known: `(N,)` bool; None means no pose is known. With no known pose, row 0 is placed at
            the identity and the tree grows from it.

    Returns:
        `(N, P)` float64 poses.

    Raises:
        GraphError: some pose cannot be reached from a known one.
    """
    p = POSE_SIZE[dim]
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if poses is None:
        n = int(edges.max()) + 1 if len(edges) else 1
        poses = np.zeros((n, p))
    poses = np.array(poses, dtype=np.float64).reshape(-1, p)
    known = np.zeros(len(poses), dtype=bool) if known is None else np.asarray(known, dtype=bool)
    roots = np.flatnonzero(known)
    if len(roots) == 0:
        roots = np.array([0])
        poses[0] = _IDENTITY[dim]
    parent, tree_edge = spanning_tree(len(poses), edges, roots)
    return compose_along_tree(dim, parent, tree_edge, edges, measurements, poses)


_IDENTITY = {
    2: np.zeros(3),
    3: np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
}
_GROUPS = {
    2: (se2, se2.from_xytheta, se2.to_xytheta),
    3: (se3, se3.from_xyz_quat, se3.to_xyz_quat),
}
