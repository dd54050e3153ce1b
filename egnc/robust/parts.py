"""Groups of loop closures between two otherwise separate parts of a graph, and which group to keep.

When the known inliers (odometry) fall into parts, as two robots' trajectories do, only the
loops between the parts place one part relative to the other. A loop from row `i` of part `p` to
row `j` of part `q`, measuring `Z = X_i^-1 X_j`, implies one rigid motion of part `q`:

    D = X_i Z X_j^-1        (part q moved by D makes the loop hold exactly)

Loops that agree imply the same `D` up to noise; a group of false loops made by perceptual
aliasing agrees with itself on another `D`. The poses `X` are a decision's map (where the loops
it accepts agree), or each part's own least-squares map (its known inliers and accepted loops,
none between the parts), where a map bent by a mix of groups does not blur them but each part's
drift splits a true group into pieces along it. `part_groups` finds the groups by consensus: each
loop's `D` is tried on every loop between the two parts, the one that explains most of them
(squared whitened residual under the outlier test's threshold) is a group, and so on for the
rest, while a group has at least two members.

Two uses: the `"parts"` start (`egnc.robust.pipeline`) moves part `q` by each group's `D`
and decides from there with only that group's loops accepted between the parts, so the decision
of lowest truncated cost keeps one group whole; and `part_group_warning` says when the kept
decision mixes groups, or rejects a whole group that would place the parts differently.

Only the pair of parts joined by the most loops is examined (two robots; a third part is left as
the decision made it), and only where the known inliers form at most `MAX_PARTS` parts: an
odometry broken into many pieces (cubicle's 403) is not a map of a few robots.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.graph.connectivity import connected_components
from egnc.graph.priors import Priors
from egnc.graph.symbols import symbol_characters, vertex_name
from egnc.nonlinear.factors import group_of, to_matrices
from egnc.nonlinear.least_squares import Problem, solve_least_squares
from egnc.robust.kernels import chi2_quantile

__all__ = [
    "AGREEMENT_SCALE",
    "MAX_CANDIDATES",
    "MAX_PARTS",
    "MAX_GROUPS",
    "PartGroups",
    "part_group_warning",
    "part_groups",
]

MAX_GROUPS = 4
"""Groups looked for between the two parts: a true group split by drift, and a rival."""

MAX_PARTS = 8
"""Most parts of the known inliers for the groups to be looked for (a few robots)."""

AGREEMENT_SCALE = 4.0
"""A loop agrees with another's motion `D` when its `r^2` is below 4 times the outlier test's
threshold: `D` carries the other loop's noise too (about twice the variance) and the map's
between them; a group of another placement is off by far more."""

MAX_CANDIDATES = 400
"""Loops whose motion `D` is tried (evenly spaced when there are more): the test is `(K, L)`."""


@dataclass(frozen=True, eq=False)
class PartGroups:
    """The loop closures between two parts and their groups.

    Attributes:
        loops: `(L,)` edge indices of the loops between the two parts.
        anchor: `(N,)` bool, the rows of part `p` (the part of the pair's first row), which stays.
        moved: `(N,)` bool, the rows of part `q` (the other part of the pair).
        groups: `(L,)` int group of each loop (0 the largest), -1 for a loop in no group.
        motions: `(G, n, n)` the motion `D` of part `q` each group implies.
    """

    loops: np.ndarray
    anchor: np.ndarray
    moved: np.ndarray
    groups: np.ndarray
    motions: np.ndarray

    @property
    def count(self) -> int:
        """Number of groups G."""
        return len(self.motions)

    def members(self, group: int) -> np.ndarray:
        """Edge indices of the loops of `group`."""
        return self.loops[self.groups == group]


def part_groups(
    graph: PoseGraph,
    robust: np.ndarray,
    inliers: np.ndarray,
    poses: np.ndarray,
    quantile: float,
    linear_solver: str | None = None,
) -> PartGroups | None:
    """The groups of loops between the two parts of `graph` joined by the most loops.

    Args:
        graph: the pose graph.
        robust: `(E,)` bool, the loop closures; the other edges are the known inliers.
        inliers: `(E,)` bool, a decision's accepted edges (its loops within a part shape the part).
        poses: `(N, n, n)` the decision's map, where each part's own map starts.
        quantile: the outlier test's quantile: a loop agrees with `D` when `r^2` is below
            `AGREEMENT_SCALE` times `chi2.ppf(q, d)`.
        linear_solver: the backend of each part's own least-squares map, the `X` of the
            groups; None: the groups are found at `poses`.

    Returns:
        The `PartGroups`, or None when the known inliers are connected or form more than
        `MAX_PARTS` parts, or no two parts of at least two poses each are joined by two loops.
    """
    known = ~robust
    count, labels = connected_components(graph.num_poses, graph.edges[known])
    if not 2 <= count <= MAX_PARTS:
        return None
    sizes = np.bincount(labels[graph.edges[known, 0]], minlength=count)
    ends = labels[graph.edges]
    between = robust & (ends[:, 0] != ends[:, 1]) & (sizes[ends] > 0).all(axis=1)
    if np.count_nonzero(between) < 2:
        return None
    pairs = np.sort(ends[between], axis=1)
    unique, counts = np.unique(pairs, axis=0, return_counts=True)
    p, q = unique[np.argmax(counts)]
    if counts.max() < 2:
        return None
    loops = np.flatnonzero(between & (np.sort(ends, axis=1) == (p, q)).all(axis=1))
    own = poses if linear_solver is None else _part_maps(graph, inliers & ~between, labels, poses, linear_solver)
    T_i, Z, T_j = _oriented(graph, loops, labels == q, own)
    threshold = AGREEMENT_SCALE * chi2_quantile(quantile, graph.tangent_dim)
    groups, motions = _consensus(graph, loops, T_i, Z, T_j, threshold)
    return PartGroups(loops, labels == p, labels == q, groups, motions)


def _part_maps(graph: PoseGraph, keep: np.ndarray, labels: np.ndarray, poses: np.ndarray, backend: str) -> np.ndarray:
    """`(N, n, n)` least squares of the edges `keep` (none between parts), each part held by its first row."""
    first = np.zeros(graph.num_poses, dtype=bool)
    first[np.unique(labels, return_index=True)[1]] = True
    parts = replace(graph.subgraph_edges(keep), fixed=graph.fixed | first, priors=Priors.empty(graph.dim))
    try:
        return solve_least_squares(Problem.from_graph(parts, backend), poses).poses
    except SolverError:  # a part the kept edges leave singular: its shape as the decision left it
        return poses


def _oriented(
    graph: PoseGraph, loops: np.ndarray, in_q: np.ndarray, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`(T_i, Z, T_j)` of each loop turned to run from part `p` to part `q` (`Z` inverted where turned)."""
    group = group_of(graph.dim)
    i, j = graph.edges[loops, 0], graph.edges[loops, 1]
    Z = to_matrices(graph.dim, graph.measurements[loops])
    turned = in_q[i]
    Z[turned] = group.inverse(Z[turned])
    i, j = np.where(turned, j, i), np.where(turned, i, j)
    return poses[i], Z, poses[j]


def _consensus(
    graph: PoseGraph, loops: np.ndarray, T_i: np.ndarray, Z: np.ndarray, T_j: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy consensus groups: `(groups (L,), motions (G, n, n))` (module docstring)."""
    group = group_of(graph.dim)
    information = graph.information[loops]
    D = T_i @ Z @ np.linalg.inv(T_j)  # (L, n, n): the motion of part q each loop implies
    tried = np.unique(np.linspace(0, len(loops) - 1, min(len(loops), MAX_CANDIDATES)).astype(np.int64))
    # E[k, m] = Z_m^-1 T_i^-1 D_k T_j: loop m's error with part q moved by loop k's motion.
    predicted = np.linalg.inv(T_i)[None] @ D[tried][:, None] @ T_j[None]
    e = group.log(np.linalg.inv(Z)[None] @ predicted)
    agrees = np.einsum("kmi,mij,kmj->km", e, information, e) < threshold
    groups = np.full(len(loops), -1, dtype=np.int64)
    motions: list[np.ndarray] = []
    while len(motions) < MAX_GROUPS:
        free = agrees & (groups < 0)[None]
        support = free.sum(axis=1)
        best = int(np.argmax(support))
        if support[best] < 2:
            break
        groups[free[best]] = len(motions)
        motions.append(D[tried[best]])
    return groups, np.array(motions).reshape(-1, *D.shape[1:])


def part_group_warning(
    graph: PoseGraph, robust: np.ndarray, inliers: np.ndarray, poses: np.ndarray, quantile: float
) -> str | None:
    """A warning when the accepted loops between two parts mix groups, or a whole group was
    rejected that would place the parts otherwise; None otherwise (and for connected graphs).

    Args:
        graph: the pose graph.
        robust: `(E,)` bool, the loop closures.
        inliers: `(E,)` bool, the decision.
        poses: `(N, n, n)` the decision's map.
        quantile: the outlier test's quantile.
    """
    found = part_groups(graph, robust, inliers, poses, quantile)
    if found is None or found.count < 2:
        return None
    ids = graph.vertex_ids
    accepted = [int(np.count_nonzero(inliers[found.members(g)])) for g in range(found.count)]
    sizes = [len(found.members(g)) for g in range(found.count)]
    used = [g for g in range(found.count) if accepted[g]]
    where = f"between {_part_name(ids[found.anchor])} and {_part_name(ids[found.moved])}"
    if len(used) > 1:
        groups = ", ".join(f"{accepted[g]} of a group of {sizes[g]}" for g in used)
        return (
            f"the accepted loop closures {where} come from groups that disagree on where one part lies "
            f"({groups}): check them"
        )
    kept = used[0] if used else None
    rival = next((g for g in range(found.count) if g != kept and not accepted[g]), None)
    if rival is None:
        return None
    members = found.members(rival)
    kept_text = f"a group of {sizes[kept]} was kept" if kept is not None else "none was kept"
    return (
        f"the loop closures {where} form groups that disagree on where one part lies: {kept_text}, a "
        f"rejected group of {sizes[rival]} (edges {', '.join(map(str, members[:5]))}"
        f"{' and more' if len(members) > 5 else ''}) would place it otherwise; perceptual aliasing makes "
        "such consistent false groups: check them"
    )


def _part_name(ids: np.ndarray) -> str:
    """How a warning names a part of the sorted vertex `ids`: `robot a (a0 to a1749)` when they are
    GTSAM Symbols of one character (`egnc.graph.symbols`), else `the part of vertex 17`."""
    characters = np.unique(symbol_characters(ids))
    if len(characters) == 1 and characters[0]:
        return f"robot {characters[0]} ({vertex_name(ids[0])} to {vertex_name(ids[-1])})"
    return f"the part of vertex {vertex_name(ids[0])}"
