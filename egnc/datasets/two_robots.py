"""Two robots (or more) from one pose graph: a trajectory cut in pieces, joined only by inter-robot loops.

`two_robots`: the first `split` poses are robot `a`, the rest robot `b`; `robots` cuts at several
rows (`splits`) into robots `a`, `b`, `c`, ... Their vertex ids are GTSAM `Symbol('a', k)`,
`Symbol('b', k)`, ... keys as int64 (`egnc.graph.symbols`), so each robot's odometry is still
consecutive ids. The odometry edges across the cuts are dropped; the loops within a robot stay;
the loops across a cut (between any two robots) are the true inter-robot loops (`true_loops` of
them kept, drawn by the seed). Each robot but `a` has its guess in its own frame: its first pose
at the identity, as a robot that starts without knowing where the others are.

False inter-robot loops of two kinds are added:

- `false_percent`: random pairs `(a_i, x_j)` between robot `a` and another robot, measuring the
  identity with riSAM's covariance (`egnc.datasets.false_loops`), so that that share of the
  inter-robot loops is false;
- `false_group`: a consistent false group, as perceptual aliasing makes: every member measures
  the relative pose robots `a` and `b` would have if `b`'s frame were moved by one wrong rigid
  motion `W` (`Z = X_ai^-1 W X_bj`, exactly, at the reference poses), between poses that are
  within `group_radius` metres of each other under that wrong alignment. The group agrees with
  itself and disagrees with the true inter-robot loops.

The inter-robot loops come after the robots' own edges, shuffled, as a map merge finds them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.datasets.false_loops import FALSE_LOOP_COVARIANCE, false_loop_count
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.graph.symbols import symbol_id
from egnc.nonlinear.factors import from_matrices, group_of, to_matrices

__all__ = ["SYMBOL_A", "SYMBOL_B", "Robots", "robots", "symbol_id", "two_robots"]

SYMBOL_A, SYMBOL_B = "a", "b"
"""The `Symbol` characters of the two robots."""

TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE = 1, 2, 3
"""Codes of `TwoRobots.kinds` for inter-robot loops (0: an edge of one robot)."""


@dataclass(frozen=True, eq=False)
class Robots:
    """A multi-robot graph and its labels.

    Attributes:
        graph: the robots' graph (ids `symbol_id`), each robot's guess but `a`'s in its own frame.
        reference: `(N, P)` reference poses of every robot in `a`'s frame (rows as `graph`'s).
        robot: `(N,)` int, each row's robot (0 for `a`, 1 for `b`, ...).
        kinds: `(E,)` int8: 0 an edge of one robot, `TRUE_LOOP`, `RANDOM_FALSE`, `GROUP_FALSE`.
        wrong_motion: `(n, n)` the rigid motion `W` of `b`'s frame the consistent group implies.
    """

    graph: PoseGraph
    reference: np.ndarray
    robot: np.ndarray
    kinds: np.ndarray
    wrong_motion: np.ndarray

    @property
    def is_inter_robot(self) -> np.ndarray:
        """`(E,)` bool: the loops between two robots."""
        return self.kinds > 0

    @property
    def is_false(self) -> np.ndarray:
        """`(E,)` bool: the false inter-robot loops."""
        return self.kinds >= RANDOM_FALSE


def two_robots(graph: PoseGraph, reference: np.ndarray, *, split: int | None = None, **options) -> Robots:
    """Cut `graph` in robots `a` (the first `split` rows, default half) and `b`: `robots` with one cut."""
    return robots(graph, reference, splits=(graph.num_poses // 2 if split is None else split,), **options)


def robots(
    graph: PoseGraph,
    reference: np.ndarray,
    *,
    splits: tuple[int, ...],
    true_loops: int | None = None,
    false_percent: float = 0.0,
    false_group: int = 0,
    group_radius: float = 3.0,
    wrong_motion: np.ndarray | None = None,
    seed: int = 1,
) -> Robots:
    """Cut `graph` in robots joined by inter-robot loops, some false (module docstring).

    Args:
        graph: a one-robot graph whose edges join rows in time order (odometry `k -> k + 1`).
        reference: `(N, P)` its outlier-free optimum (the truth of the false loops' tests).
        splits: the first row of robot `b`, of `c`, ..., increasing.
        true_loops: true inter-robot loops kept (default: every loop across a cut).
        false_percent: share in % of the inter-robot loops that are random false ones.
        false_group: the size of the consistent false group between `a` and `b` (0: none).
        group_radius: metres between the two poses of a group member under the wrong alignment.
        wrong_motion: `W`, `(n, n)`, default a rotation by 90 degrees about the centre of `b`'s
            reference positions and a shift of 20 metres along x (2D; about z in 3D).
        seed: of `np.random.default_rng`.
    """
    n = graph.num_poses
    starts = np.array([0, *splits, n])
    if not (np.diff(starts) > 0).all():
        raise EgncError(f"robots: splits must increase within (0, {n}), got {list(splits)}")
    rng = np.random.default_rng(seed)
    dim, group = graph.dim, group_of(graph.dim)
    T_ref = to_matrices(dim, np.asarray(reference, dtype=np.float64))
    robot = np.searchsorted(starts, np.arange(n), side="right") - 1
    crosses = robot[graph.edges[:, 0]] != robot[graph.edges[:, 1]]
    across = np.flatnonzero(crosses & graph.is_loop_closure)
    if true_loops is not None and true_loops < len(across):
        across = np.sort(rng.choice(across, size=true_loops, replace=False))
    own = np.flatnonzero(~crosses)
    b_rows = slice(starts[1], starts[2])
    W = _default_motion(dim, T_ref[b_rows]) if wrong_motion is None else np.asarray(wrong_motion, dtype=np.float64)
    random_edges = _random_pairs(rng, starts[1], n, false_loop_count(len(across), false_percent))
    group_edges = _group_pairs(rng, T_ref[: starts[1]], W @ T_ref[b_rows], starts[1], false_group, group_radius)
    group_Z = group.between(T_ref[group_edges[:, 0]], W @ T_ref[group_edges[:, 1]])
    d = graph.tangent_dim
    false_info = np.diag(1.0 / np.asarray(FALSE_LOOP_COVARIANCE[dim]))
    loop_info = graph.information[across].mean(axis=0) if len(across) else np.eye(d)
    inter_edges = np.concatenate((graph.edges[across], random_edges, group_edges))
    identity = from_matrices(dim, group.identity((len(random_edges),)))
    inter_Z = np.concatenate((graph.measurements[across], identity, from_matrices(dim, group_Z)))
    inter_info = np.concatenate(
        (
            graph.information[across],
            np.broadcast_to(false_info, (len(random_edges), d, d)),
            np.broadcast_to(loop_info, (len(group_edges), d, d)),
        )
    )
    inter_kinds = np.repeat([TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE], [len(across), len(random_edges), len(group_edges)])
    order = rng.permutation(len(inter_edges))
    T_guess = to_matrices(dim, graph.poses)
    for first, end in zip(starts[1:-1], starts[2:]):
        T_guess[first:end] = np.linalg.inv(T_guess[first]) @ T_guess[first:end]  # the robot's own frame
    ids = np.concatenate(
        [symbol_id(chr(ord(SYMBOL_A) + r), np.arange(starts[r + 1] - starts[r])) for r in range(len(starts) - 1)]
    )
    cut = PoseGraph(
        dim,
        ids,
        from_matrices(dim, T_guess),
        np.concatenate((graph.edges[own], inter_edges[order])),
        np.concatenate((graph.measurements[own], inter_Z[order])),
        np.concatenate((graph.information[own], inter_info[order])),
    )
    kinds = np.concatenate((np.zeros(len(own), dtype=np.int8), inter_kinds[order].astype(np.int8)))
    return Robots(cut, np.asarray(reference, dtype=np.float64), robot, kinds, W)


def _default_motion(dim: int, T_b: np.ndarray) -> np.ndarray:
    """A rotation by 90 degrees about the centre of `b`'s positions, then 20 metres along x."""
    centre = T_b[:, :dim, dim].mean(axis=0)
    W = np.eye(dim + 1)
    R = np.eye(dim)
    R[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    W[:dim, :dim] = R
    W[:dim, dim] = centre - R @ centre
    W[0, dim] += 20.0
    return W


def _random_pairs(rng: np.random.Generator, split: int, n: int, count: int) -> np.ndarray:
    """`(count, 2)` distinct rows `(a_i, x_j)`, `a_i` uniform below `split` (robot `a`), `x_j` above."""
    pairs: set[tuple[int, int]] = set()
    while len(pairs) < count:
        pairs.add((int(rng.integers(0, split)), int(rng.integers(split, n))))
    return np.array(sorted(pairs, key=lambda _: rng.random()), dtype=np.int64).reshape(-1, 2)


def _group_pairs(
    rng: np.random.Generator, T_a: np.ndarray, T_b_moved: np.ndarray, b_first: int, count: int, radius: float
) -> np.ndarray:
    """`(count, 2)` rows `(a_i, b_j)` whose positions are within `radius` of each other, robot `a`'s
    reference poses `T_a` against robot `b`'s moved by `W` (`T_b_moved`, rows from `b_first`)."""
    if count == 0:
        return np.zeros((0, 2), dtype=np.int64)
    dim = T_a.shape[-1] - 1
    p_a = T_a[:, :dim, dim]
    p_b = T_b_moved[:, :dim, dim]
    close: list[tuple[int, int]] = []
    for j in rng.permutation(len(p_b)):
        near = np.flatnonzero(np.linalg.norm(p_a - p_b[j], axis=1) < radius)
        if len(near):
            close.append((int(rng.choice(near)), b_first + int(j)))
        if len(close) == count:
            return np.array(close, dtype=np.int64)
    raise EgncError(f"robots: only {len(close)} pose pairs are within {radius} m under the wrong alignment")
