"""Corrupt a pose graph with false loop closures, following riSAM's evaluation protocol.

With L true loop closures and an outlier percentage p, `round(p L / (100 - p))` false loop
closures are added, so that p % of all loop closures are false (DESIGN.md section 5). Each joins
two poses a, b with `|a - b| >= 2` (pose rows, so it is never mistaken for odometry), measures
the identity, and has the fixed covariance `diag(0.015, 0.01, 0.001)` in 2D or `0.01 I_6` in 3D.
A candidate is kept only if it really is an outlier: its squared whitened error at the
outlier-free optimum `reference_poses` exceeds `chi2.ppf(0.95, d)`, the EGNC paper's outlier rule
(DESIGN.md section 4; egnc's own decision after a solve uses the higher threshold
`chi2.ppf(GncOptions.outlier_quantile, d)`, 0.99 by default). riSAM's generator compares the
unsquared distance with that quantile instead, which only keeps larger errors
(`outlier_rule="distance"`).
A candidate is also redrawn when its two poses already share an edge, of the graph or an earlier
false loop (in either direction): the corrupted graph has no duplicate edge
(`PoseGraph.is_duplicate`) that the input did not have, so a reader warns about nothing new.
This only removes candidates from the stream of draws, so a seed whose draws held no such pair
gives the same false loops as before the rule was added.

Variants (riSAM's options):
- "random": independent pairs.
- "group": groups of `group_size` consecutive false loops `(a + k, b + k)`, k = 0..group_size-1,
  which support each other and are harder to reject; every member must pass the test.
- "mixed": half of the false loops random, half in groups.
- "close": random pairs whose reference positions are within `close_radius` metres, plausible
  loop closures that are still wrong.

The candidates are drawn in batches from `np.random.default_rng(seed)`, all tested at once, and
the accepted ones kept in draw order, so the result depends only on the seed and the inputs.

The false loops are interleaved with the original edges where a time-ordered file would hold them:
after the original edges whose newest pose is not newer than the false loop's, and oriented like
most of the true loop closures. Appending them would give them away by position alone; the
original edges keep their relative order, and `source_edges` maps every edge back to the input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from egnc.errors import EgncError
from egnc.graph import POSE_SIZE, TANGENT_SIZE, PoseGraph
from egnc.nonlinear.factors import group_of, to_matrices
from egnc.robust.kernels import chi2_quantile

Variant = Literal["random", "group", "mixed", "close"]
VARIANTS: tuple[str, ...] = ("random", "group", "mixed", "close")
"""Names accepted by `add_false_loops(variant=...)`."""

OutlierRule = Literal["squared", "distance"]
OUTLIER_RULES: tuple[str, ...] = ("squared", "distance")
"""Names accepted by `add_false_loops(outlier_rule=...)`."""

FALSE_LOOP_COVARIANCE = {2: (0.015, 0.01, 0.001), 3: (0.01,) * 6}
"""Diagonal covariance of every false loop closure by dimension (riSAM's protocol), `[v, omega]`."""

ACCEPT_QUANTILE = 0.95
"""A candidate is kept when its squared whitened error exceeds `chi2.ppf(ACCEPT_QUANTILE, d)`."""

_MIN_BATCH = 256
_MAX_DRAWS_PER_LOOP = 1000
"""Give up after this many candidate draws per wanted false loop (plus a fixed allowance)."""


@dataclass(frozen=True, eq=False)
class CorruptedGraph:
    """A pose graph with false loop closures and the labels that identify them.

    Attributes:
        graph: the corrupted graph: the input's vertices and edges plus the false loops.
        is_outlier: `(E,)` bool, true for the added false loops, in `graph`'s edge order.
        source_edges: `(E,)` int64 index of each edge in the input graph, -1 for false loops.
    """

    graph: PoseGraph
    is_outlier: np.ndarray
    source_edges: np.ndarray


def false_loop_count(num_loops: int, percent: float) -> int:
    """Number of false loops that make `percent` % of all loop closures false: `round(p L / (100 - p))`.

    Halves round up, so the count does not depend on Python's round-half-to-even.
    """
    return int(math.floor(percent * num_loops / (100.0 - percent) + 0.5))


def add_false_loops(
    graph: PoseGraph,
    percent: float,
    *,
    seed: int,
    reference_poses: np.ndarray,
    variant: Variant = "random",
    group_size: int = 5,
    close_radius: float = 10.0,
    outlier_rule: OutlierRule = "squared",
) -> CorruptedGraph:
    """Add seeded false loop closures to `graph` (riSAM's protocol, see the module docstring).

    Args:
        graph: the outlier-free graph; its loop closures count as the true ones.
        percent: wanted share of false loops among all loop closures, in [0, 100).
        seed: seed of `np.random.default_rng`.
        reference_poses: `(N, P)` outlier-free optimum in the graph's parametrization, used to
            verify that every false loop is an outlier (and for the "close" radius).
        variant: "random", "group", "mixed" or "close".
        group_size: false loops per group for "group" and "mixed" (the last group may be cut
            short to reach the exact count).
        close_radius: "close" only: maximum distance in metres between the endpoints' reference
            positions.
        outlier_rule: a candidate is an outlier when its whitened error at `reference_poses`
            exceeds `q = chi2.ppf(0.95, d)`: its square `r^2 > q` ("squared", the EGNC paper's
            rule) or the error itself, `r > q` ("distance", riSAM's generator).

    Returns:
        The `CorruptedGraph`.

    Raises:
        EgncError: invalid arguments, a graph without loop closures, or too few pose pairs
            satisfy the constraints to place all false loops.
    """
    if not 0.0 <= percent < 100.0:
        raise EgncError(f"add_false_loops: percent must lie in [0, 100), got {percent}")
    if variant not in VARIANTS:
        raise EgncError(f"add_false_loops: unknown variant {variant!r}: choose one of {', '.join(VARIANTS)}")
    if group_size < 1:
        raise EgncError(f"add_false_loops: group_size must be at least 1, got {group_size}")
    if outlier_rule not in OUTLIER_RULES:
        raise EgncError(
            f"add_false_loops: unknown outlier_rule {outlier_rule!r}: choose one of {', '.join(OUTLIER_RULES)}"
        )
    if not close_radius > 0.0:
        raise EgncError(f"add_false_loops: close_radius must be positive, got {close_radius}")
    reference_poses = np.asarray(reference_poses, dtype=np.float64)
    expected = (graph.num_poses, POSE_SIZE[graph.dim])
    if reference_poses.shape != expected:
        raise EgncError(f"add_false_loops: reference_poses has shape {reference_poses.shape}, expected {expected}")
    if not np.all(np.isfinite(reference_poses)):
        raise EgncError("add_false_loops: reference_poses contains NaN or infinite values")
    loops = graph.edges[graph.is_loop_closure]
    if len(loops) == 0:
        raise EgncError("add_false_loops: the graph has no loop closures to set the outlier percentage against")

    count = false_loop_count(len(loops), percent)
    if variant == "group":
        segments = [(count, group_size)]
    elif variant == "mixed":
        segments = [(count - count // 2, 1), (count // 2, group_size)]
    else:
        segments = [(count, 1)]
    sampler = _Sampler(
        rng=np.random.default_rng(seed),
        T_world=to_matrices(graph.dim, reference_poses),
        dim=graph.dim,
        forward=bool(2 * np.count_nonzero(loops[:, 0] < loops[:, 1]) >= len(loops)),
        close_radius=close_radius if variant == "close" else None,
        edges=graph.edges,
        distance_rule=outlier_rule == "distance",
    )
    false_edges = np.concatenate([sampler.draw(n, size) for n, size in segments])
    return _merge(graph, false_edges)


class _Sampler:
    """Draws false loops in batches from one generator and keeps those that pass every test."""

    def __init__(
        self,
        rng: np.random.Generator,
        T_world: np.ndarray,
        dim: int,
        forward: bool,
        close_radius: float | None,
        edges: np.ndarray,
        distance_rule: bool,
    ):
        self.rng = rng
        self.T_world = T_world
        self.group = group_of(dim)
        self.forward = forward
        self.close_radius = close_radius
        self.information_diagonal = np.diag(_false_loop_information(dim))
        quantile = chi2_quantile(ACCEPT_QUANTILE, TANGENT_SIZE[dim])
        self.threshold = quantile**2 if distance_rule else quantile
        """Bound on the squared whitened error (`r > q` is `r^2 > q^2`)."""
        self.taken = {(min(a, b), max(a, b)) for a, b in edges.tolist()}
        """Unordered pose pairs that already have an edge: the graph's and the false loops kept so far."""

    def draw(self, count: int, size: int) -> np.ndarray:
        """Return `(count, 2)` int64 false-loop edges made of groups of `size` consecutive pairs."""
        if count == 0:
            return np.zeros((0, 2), dtype=np.int64)
        num_poses = len(self.T_world)
        num_groups = -(-count // size)
        # Seeds a, b lie in [0, num_poses - size] so that every member a + k, b + k exists.
        high = num_poses - size + 1
        if high < 3:
            raise EgncError(f"add_false_loops: {num_poses} poses are too few for {size} consecutive false loops")
        offsets = np.arange(size)
        kept: list[np.ndarray] = []
        num_kept = 0
        num_drawn = 0
        max_draws = _MAX_DRAWS_PER_LOOP * num_groups + 100 * _MIN_BATCH
        while num_kept < num_groups:
            if num_drawn >= max_draws:
                raise EgncError(
                    f"add_false_loops: placed only {num_kept} of {num_groups} false-loop groups after "
                    f"{num_drawn} candidates: too few pose pairs are far apart in the reference"
                    + (f" yet within close_radius = {self.close_radius} m" if self.close_radius else "")
                )
            batch = max(_MIN_BATCH, 4 * (num_groups - num_kept))
            seeds = self.rng.integers(0, high, size=(batch, 2))
            num_drawn += batch
            seeds = np.sort(seeds, axis=1) if self.forward else -np.sort(-seeds, axis=1)
            members = seeds[:, None, :] + offsets[None, :, None]  # (batch, size, 2)
            accept = np.abs(seeds[:, 0] - seeds[:, 1]) >= 2
            accept &= np.all(self._is_outlier(members), axis=1)
            if self.close_radius is not None:
                accept &= np.all(self._distance(members) <= self.close_radius, axis=1)
            accept[accept] = self._take_new_pairs(members[accept], num_groups - num_kept)
            kept.append(seeds[accept])
            num_kept += int(np.count_nonzero(accept))
        seeds = np.concatenate(kept)[:num_groups]
        return (seeds[:, None, :] + offsets[None, :, None]).reshape(-1, 2)[:count]

    def _take_new_pairs(self, candidates: np.ndarray, wanted: int) -> np.ndarray:
        """`(C, size, 2)` candidate groups in draw order -> `(C,)` bool: the first `wanted` whose pairs have no edge.

        The pairs of the groups marked true are added to `taken`, so a later candidate (in this
        batch too) cannot repeat them. A loop over the candidates that passed the other tests only.
        """
        new = np.zeros(len(candidates), dtype=bool)
        for k, group in enumerate(np.sort(candidates, axis=-1).tolist()):
            if wanted == 0:
                break
            pairs = [(a, b) for a, b in group]
            if self.taken.isdisjoint(pairs):
                self.taken.update(pairs)
                new[k] = True
                wanted -= 1
        return new

    def _is_outlier(self, pairs: np.ndarray) -> np.ndarray:
        """`(..., 2)` pose rows -> `(...)` bool: identity measurement rejected by the chi-square test."""
        T_a, T_b = self.T_world[pairs[..., 0]], self.T_world[pairs[..., 1]]
        e = self.group.log(self.group.between(T_a, T_b))  # Log(I^-1 X_a^-1 X_b)
        return np.einsum("...i,i,...i->...", e, self.information_diagonal, e) > self.threshold

    def _distance(self, pairs: np.ndarray) -> np.ndarray:
        """`(..., 2)` pose rows -> `(...)` distance in metres between the reference positions."""
        t_world = self.T_world[:, :-1, -1]
        return np.linalg.norm(t_world[pairs[..., 0]] - t_world[pairs[..., 1]], axis=-1)


def _false_loop_information(dim: int) -> np.ndarray:
    """`(d, d)` information matrix of a false loop: the inverse of `FALSE_LOOP_COVARIANCE`."""
    return np.diag(1.0 / np.array(FALSE_LOOP_COVARIANCE[dim]))


def _merge(graph: PoseGraph, false_edges: np.ndarray) -> CorruptedGraph:
    """Interleave `false_edges` `(F, 2)` with the graph's edges in time order (module docstring)."""
    num_edges, num_false = graph.num_edges, len(false_edges)
    # Original edge e sorts at 2e + 1; a false loop placed after the first p originals sorts at 2p,
    # i.e. before original p. The stable sort keeps draw order among false loops at the same place.
    newest = np.maximum.accumulate(graph.edges.max(axis=1))
    place = np.searchsorted(newest, false_edges.max(axis=1), side="right")
    order = np.argsort(np.concatenate((2 * np.arange(num_edges) + 1, 2 * place)), kind="stable")

    identity = np.zeros(POSE_SIZE[graph.dim])
    if graph.dim == 3:
        identity[-1] = 1.0  # qw
    information = _false_loop_information(graph.dim)
    corrupted = PoseGraph(
        dim=graph.dim,
        vertex_ids=graph.vertex_ids,
        poses=graph.poses,
        edges=np.concatenate((graph.edges, false_edges))[order],
        measurements=np.concatenate((graph.measurements, np.tile(identity, (num_false, 1))))[order],
        information=np.concatenate((graph.information, np.tile(information, (num_false, 1, 1))))[order],
        fixed=graph.fixed,
        edge_lines=np.concatenate((graph.edge_lines, np.zeros(num_false, np.int64)))[order],
    )
    source = np.concatenate((np.arange(num_edges), np.full(num_false, -1)))[order]
    is_outlier = source < 0
    source.setflags(write=False)
    is_outlier.setflags(write=False)
    return CorruptedGraph(graph=corrupted, is_outlier=is_outlier, source_edges=source)
