"""Local regions of a pose graph: solve only the poses an incremental change moves.

An online update with a loop closure changes the optimum mostly near the loop's ends: the map is
converged before it, and the new edge's pull fades with its graph distance. iSAM2 exploits this
with its Bayes tree (it re-eliminates only the cliques a change touches and relinearizes only the
variables whose step exceeds a threshold). Here an update first solves a *local problem*: the
poses within `hops` edges of the change are free, the poses one edge beyond them are held fixed
(the boundary), and every edge with an end among the free poses is in it; no other edge is, since
nothing else moves.

A region held at its boundary is stiffer than the map: where the whole map would turn a part of
itself, the region strains. Two tests tell when that matters (the caller, `egnc.online`, falls
back to the whole map on either): a loop closure crossed the strong-outlier line in the local
solve (the strain may have made a decision the whole map would not), or the boundary still
pulls on the rest of the map.
The second is measured by each boundary pose's block-Jacobi decrease: the cost decrease
`0.5 g_b^T H_bb^-1 g_b` its own Newton step would bring with every other pose held, from its
gradient `g_b` and diagonal block `H_bb` over all its edges. One pose at a time underestimates
what a long, soft mode of the map (a chain of odometry that could turn as a whole) releases, so
the caller compares it with a small share of its tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.graph.index_sets import sorted_unique
from egnc.linalg.normal_equations import edge_products
from egnc.nonlinear.factors import BetweenFactors
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.prior_factors import PriorFactors

__all__ = ["LocalProblem", "Neighbourhoods", "block_jacobi_decrease"]


class Neighbourhoods:
    """Which poses and edges are near which, grown as edges arrive.

    An index of the edges at each pose (compressed rows: pose -> its edge indices) covers the
    first edges; the edges added since form a tail that every query scans. The index is rebuilt
    when the tail outgrows `TAIL_PER_ROOT` times the square root of the edge count, so a query
    costs what the poses it asks about hold plus the tail, not a pass over every edge.

    Attributes:
        edges: `(E, 2)` pose rows of every edge.
        num_poses: number of poses `N`.
    """

    TAIL_PER_ROOT = 4
    """The index is rebuilt when more than this times `sqrt(E)` edges (at least 256) are past it."""

    def __init__(self) -> None:
        self.edges = np.zeros((0, 2), dtype=np.int64)
        self.num_poses = 0
        self._indexed = 0  # edges in the index
        self._indptr = np.zeros(1, dtype=np.int64)  # (indexed poses + 1,)
        self._incident = np.zeros(0, dtype=np.int64)  # (2 * indexed,) edge indices by pose

    @classmethod
    def of(cls, edges: np.ndarray, num_poses: int) -> Neighbourhoods:
        """The neighbourhoods of `edges` `(E, 2)` (pose rows) among `num_poses` poses."""
        neighbourhoods = cls()
        neighbourhoods.grow(edges, num_poses)
        return neighbourhoods

    def grow(self, edges: np.ndarray, num_poses: int) -> None:
        """Take the graph grown to `edges` `(E, 2)` (the earlier edges first, unchanged) and `num_poses`."""
        self.edges, self.num_poses = edges, num_poses
        tail = len(edges) - self._indexed
        if tail > max(256, self.TAIL_PER_ROOT * np.sqrt(len(edges))):
            self._rebuild()

    def _rebuild(self) -> None:
        ends = self.edges.reshape(-1)
        order = np.argsort(ends, kind="stable")
        self._incident = order // 2
        self._indptr = np.zeros(self.num_poses + 1, dtype=np.int64)
        np.cumsum(np.bincount(ends, minlength=self.num_poses), out=self._indptr[1:])
        self._indexed = len(self.edges)

    def _incident_to(self, rows: np.ndarray, among: np.ndarray) -> np.ndarray:
        """Indices of the edges with an end among `rows` (`among`: `(N,)` bool mask of the same
        rows); an edge with both ends there appears twice."""
        indexed = rows[rows < len(self._indptr) - 1]
        starts, stops = self._indptr[indexed], self._indptr[indexed + 1]
        counts = stops - starts
        # Concatenated ranges [start, stop) without a Python loop.
        offsets = np.repeat(starts - np.cumsum(counts) + counts, counts)
        gathered = self._incident[offsets + np.arange(int(counts.sum()))]
        tail = self.edges[self._indexed :]
        if not len(tail):
            return gathered
        return np.concatenate((gathered, self._indexed + np.flatnonzero(among[tail].any(axis=1))))

    def within(self, seeds: np.ndarray, hops: int, hops_along: np.ndarray | None = None) -> np.ndarray:
        """Sorted rows of the poses at most `hops` edges from a pose of `seeds` (the seeds included).

        `hops_along`: `(E,)` bool, the edges a hop may take (default all). A loop closure the
        map has switched off moves nothing, and random false loops would make every pose a few
        hops from every other.
        """
        inside = np.zeros(self.num_poses, dtype=bool)
        inside[seeds] = True
        frontier = np.flatnonzero(inside)
        for _ in range(hops):
            among = np.zeros(self.num_poses, dtype=bool)
            among[frontier] = True
            edges = self._incident_to(frontier, among)
            if hops_along is not None:
                edges = edges[hops_along[edges]]
            ends = self.edges[edges].reshape(-1)
            reached = sorted_unique(ends[~inside[ends]])
            if not len(reached):
                break
            inside[reached] = True
            frontier = reached
        return np.flatnonzero(inside)

    def edges_of(self, rows: np.ndarray) -> np.ndarray:
        """Sorted indices of the edges with at least one end among the poses `rows`."""
        among = np.zeros(self.num_poses, dtype=bool)
        among[rows] = True
        return sorted_unique(self._incident_to(np.flatnonzero(among), among))


@dataclass(frozen=True, eq=False)
class LocalProblem:
    """A region's poses free, their other neighbours fixed, every edge with a free end, and
    every prior on a free pose (an edge from a fixed pose: it anchors its pose).

    Attributes:
        rows: `(M,)` sorted pose rows of the whole graph in the local problem (free and boundary).
        free: `(M,)` bool, which of `rows` the solve moves.
        edges: `(K,)` sorted indices of the whole graph's edges in it.
        factors: `(K + Q,)` its factor indices in the whole graph's per-factor arrays: `edges`,
            then the `Q` priors' (`E + k`, `egnc.online.priors`); `edges` itself without priors.
        problem: the `egnc.nonlinear.least_squares.Problem` over them, local rows and factors.
    """

    rows: np.ndarray
    free: np.ndarray
    edges: np.ndarray
    factors: np.ndarray
    problem: Problem

    @classmethod
    def build(
        cls,
        region: np.ndarray,
        neighbourhoods: Neighbourhoods,
        factors: BetweenFactors,
        held: int,
        linear_solver: str,
        priors: PriorFactors | None = None,
    ) -> LocalProblem:
        """The local problem of the free poses `region` (sorted rows).

        Args:
            region: `(R,)` sorted rows of the poses to solve.
            neighbourhoods: of the whole graph's edges.
            factors: the whole graph's factors.
            held: a row held fixed even inside the region (the gauge), or -1.
            linear_solver: backend name (`egnc.linalg.linear_solvers`).
            priors: the whole graph's priors, None without; the loss then covers the local
                problem's factors, edges then priors (`Problem.weighted_priors`).
        """
        edges = neighbourhoods.edges_of(region)
        rows = sorted_unique(factors.edges[edges].ravel())
        local_edges = np.searchsorted(rows, factors.edges[edges])
        in_region = region[np.minimum(np.searchsorted(region, rows), len(region) - 1)] == rows
        free = in_region & (rows != held)
        local_factors = BetweenFactors(factors.dim, local_edges, factors.Z_inv[edges], factors.information[edges])
        local_priors = np.zeros(0, dtype=np.int64) if priors is None else _on_free_poses(priors.rows, rows[free])
        if priors is None or not len(local_priors):
            # A region is small: its direct solver orders it itself, cheaper than a block order.
            return cls(rows, free, edges, edges, Problem.from_factors(local_factors, ~free, linear_solver, False))
        position = np.searchsorted(rows, priors.rows[local_priors])
        anchored = priors.subset(local_priors, position)
        problem = Problem.from_factors(local_factors, ~free, linear_solver, False, anchored)
        indices = np.concatenate((edges, len(factors.edges) + local_priors))
        return cls(rows, free, edges, indices, replace(problem, weighted_priors=True))

    @property
    def boundary(self) -> np.ndarray:
        """Sorted rows of the fixed poses (the region's other neighbours, and a held pose inside it)."""
        return self.rows[~self.free]


def _on_free_poses(prior_rows: np.ndarray, free_rows: np.ndarray) -> np.ndarray:
    """Increasing indices of the priors on pose rows `prior_rows` `(K,)` that measure one of the
    sorted `free_rows`."""
    if not len(free_rows):
        return np.zeros(0, dtype=np.int64)
    position = np.minimum(np.searchsorted(free_rows, prior_rows), len(free_rows) - 1)
    return np.flatnonzero(free_rows[position] == prior_rows)


def block_jacobi_decrease(
    factors: BetweenFactors,
    edges: np.ndarray,
    T: np.ndarray,
    weights: np.ndarray,
    rows: np.ndarray,
    priors: tuple[PriorFactors, np.ndarray] | None = None,
) -> np.ndarray:
    """Per pose of `rows`, the cost decrease its own Newton step would bring, all else held.

    Args:
        factors: the whole graph's factors.
        edges: `(K,)` every edge with an end in `rows` (other edges add nothing).
        T: `(N, n, n)` the whole graph's pose matrices.
        weights: `(K,)` IRLS weights of `edges`.
        rows: `(B,)` sorted pose rows.
        priors: the priors on poses of `rows` and their `(Q,)` IRLS weights, or None: each an
            edge from a fixed virtual pose (row N, `egnc.nonlinear.prior_gauge`).

    Returns:
        `(B,)` `0.5 g_b^T H_bb^-1 g_b`, from the gradient `g_b` and diagonal block `H_bb` of
        `sum w J^T Omega J` over the edges of pose `b` (cost units).
    """
    subset = factors.subset(edges)
    d = subset.information.shape[-1]
    products = edge_products(subset.linearize(T), subset.information, weights)
    ends = subset.edges
    if priors is not None:
        prior_factors, prior_weights = priors
        prior_products = edge_products(prior_factors.linearize(T), prior_factors.information, prior_weights)
        products = np.concatenate((products, prior_products))
        anchor = np.full(len(prior_factors), len(T), dtype=np.int64)
        ends = np.concatenate((ends, np.stack((anchor, prior_factors.rows), axis=1)))
    gradient = np.zeros((len(rows) + 1, d))
    block = np.zeros((len(rows) + 1, d, d))
    for end in (0, 1):
        position = np.searchsorted(rows, ends[:, end])
        inside = position < len(rows)
        inside[inside] = rows[position[inside]] == ends[inside, end]
        slot = np.where(inside, position, len(rows))  # the last slot collects the other ends
        span = slice(end * d, (end + 1) * d)
        np.add.at(gradient, slot, products[:, span, 2 * d])
        np.add.at(block, slot, products[:, span, span])
    gradient, block = gradient[:-1], block[:-1]
    step = np.linalg.solve(block + 1e-12 * np.eye(d), gradient[:, :, None])[:, :, 0]
    return 0.5 * np.einsum("bi,bi->b", gradient, step)
