"""Connected components of a pose graph, and the check that it is connected.

A disconnected pose graph has no unique solution (each component floats freely), so it must be
reported before solving rather than silently solved.

Components are found by vectorized union-find (hook and compress, as in Shiloach and Vishkin):
every pose points to a root, initially itself; each pass hooks the larger root of every edge whose
ends have different roots onto the smallest such neighbouring root, then pointer-jumps until every
pose points straight at its root. Roots only decrease, so the passes end with each component
rooted at its lowest row, in a few NumPy passes and no Python loop over poses or edges. This runs on
every file read; `scipy.sparse.csgraph` would do the same but its import (it pulls in
`scipy.sparse.linalg` and `scipy.linalg`) costs about 0.1 s of every `egnc-solve`.

References:
    Y. Shiloach and U. Vishkin, "An O(log n) parallel connectivity algorithm", J. Algorithms 3, 1982.
"""

from __future__ import annotations

import numpy as np

from egnc.errors import GraphError

_MAX_COMPONENTS_SHOWN = 3
_MAX_RUNS_SHOWN = 3


def connected_components(num_poses: int, edges: np.ndarray) -> tuple[int, np.ndarray]:
    """Label the connected components of the undirected graph.

    Args:
        num_poses: number of poses N.
        edges: `(E, 2)` int row indices `(i, j)`.

    Returns:
        `(count, labels)`: the number of components and `(N,)` int labels in `[0, count)`.
        Labels are numbered in order of each component's lowest row, so the component holding
        row 0 is label 0.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    i, j = edges[:, 0], edges[:, 1]
    root = np.arange(num_poses, dtype=np.int64)
    while True:
        root_i, root_j = root[i], root[j]
        apart = root_i != root_j
        if not apart.any():
            break
        # Both are roots (every pose points at its root here): hook the larger onto the smaller.
        np.minimum.at(root, np.maximum(root_i, root_j)[apart], np.minimum(root_i, root_j)[apart])
        while True:  # pointer jumping: each pass halves the depth of every tree
            jumped = root[root]
            if np.array_equal(jumped, root):
                break
            root = jumped
    # Each component's root is its lowest row, so sorted roots number components by lowest row.
    roots, labels = np.unique(root, return_inverse=True)
    return len(roots), labels.reshape(num_poses)


def describe_components(vertex_ids: np.ndarray, labels: np.ndarray) -> str:
    """Summarize components on one line, e.g. `{0..99} (100 poses), {100..149} (50 poses), ...`.

    Args:
        vertex_ids: `(N,)` sorted vertex ids.
        labels: `(N,)` component labels from `connected_components`.
    """
    vertex_ids = np.asarray(vertex_ids)
    count = int(labels.max()) + 1 if len(labels) else 0
    parts = []
    for label in range(min(count, _MAX_COMPONENTS_SHOWN)):
        ids = vertex_ids[labels == label]
        parts.append(f"{describe_ids(ids)} ({len(ids)} pose{'s' if len(ids) != 1 else ''})")
    if count > _MAX_COMPONENTS_SHOWN:
        parts.append(f"... ({count - _MAX_COMPONENTS_SHOWN} more)")
    return ", ".join(parts)


def require_connected(
    vertex_ids: np.ndarray, edges: np.ndarray, *, source: str = "", ignore: np.ndarray | None = None
) -> None:
    """Raise `GraphError` unless the edges connect every pose (but the `ignore`d ones).

    Args:
        vertex_ids: `(N,)` sorted vertex ids, used only to name poses in the message.
        edges: `(E, 2)` int row indices `(i, j)` into `vertex_ids`.
        source: where the graph came from (e.g. a file name), prefixed to the message.
        ignore: `(N,)` bool, poses left out of the check (e.g. from `isolated_vertices`).
    """
    if ignore is not None and ignore.any():
        kept = np.flatnonzero(~ignore)
        vertex_ids = np.asarray(vertex_ids)[kept]
        edges = np.searchsorted(kept, edges)  # no edge touches an ignored pose
    count, labels = connected_components(len(vertex_ids), edges)
    if count <= 1:
        return
    prefix = f"{source}: " if source else ""
    raise GraphError(
        f"{prefix}the pose graph is disconnected, {count} connected components: "
        f"{describe_components(vertex_ids, labels)}; "
        "every pose must be linked to the others by edges"
    )


def isolated_vertices(num_poses: int, edges: np.ndarray) -> np.ndarray:
    """`(N,)` bool: the poses that no edge touches."""
    return np.bincount(np.asarray(edges).ravel(), minlength=num_poses) == 0


def hold_isolated_fixed(fixed: np.ndarray, isolated: np.ndarray) -> np.ndarray:
    """The `(N,)` fixed mask with the isolated poses held fixed, and the gauge kept on the others.

    Fixed poses carry no unknowns, so isolated ones cannot make the normal equations singular.
    The solver fixes row 0 only when no pose is fixed; when no connected pose was fixed, the
    lowest connected row is fixed here instead, as the gauge it would otherwise have taken.
    """
    fixed = fixed | isolated
    if not fixed[~isolated].any():
        fixed[np.argmin(isolated)] = True
    return fixed


def describe_ids(ids: np.ndarray) -> str:
    """Format sorted ids as runs of consecutive values: `{0..9, 12, 20..29, ...}`."""
    breaks = np.flatnonzero(np.diff(ids) != 1) + 1
    starts = np.concatenate(([0], breaks))
    ends = np.concatenate((breaks, [len(ids)])) - 1
    runs = [
        f"{ids[s]}" if s == e else f"{ids[s]}..{ids[e]}"
        for s, e in zip(starts[:_MAX_RUNS_SHOWN], ends[:_MAX_RUNS_SHOWN])
    ]
    if len(starts) > _MAX_RUNS_SHOWN:
        runs.append("...")
    return "{" + ", ".join(runs) + "}"
