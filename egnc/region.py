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

from dataclasses import dataclass

import numpy as np

from egnc.factors import BetweenFactors, from_matrices
from egnc.graph import PoseGraph
from egnc.least_squares import Problem
from egnc.normal_equations import edge_products

__all__ = ["LocalProblem", "Neighbourhoods", "block_jacobi_decrease"]


@dataclass(frozen=True, eq=False)
class Neighbourhoods:
    """Which poses and edges are near which.

    Attributes:
        edges: `(E, 2)` pose rows of every edge.
        hop_edges: `(H, 2)` pose rows of the edges a hop may take.
        num_poses: number of poses `N`.
    """

    edges: np.ndarray
    hop_edges: np.ndarray
    num_poses: int

    @classmethod
    def of(cls, edges: np.ndarray, num_poses: int, hops_along: np.ndarray | None = None) -> Neighbourhoods:
        """The neighbourhoods of `edges` `(E, 2)` (pose rows) among `num_poses` poses.

        `hops_along`: `(E,)` bool, the edges a hop may take (default all). A loop closure the
        map has switched off moves nothing, and random false loops would make every pose a few
        hops from every other.
        """
        return cls(edges, edges if hops_along is None else edges[hops_along], num_poses)

    def within(self, seeds: np.ndarray, hops: int) -> np.ndarray:
        """Sorted rows of the poses at most `hops` edges from a pose of `seeds` (the seeds included)."""
        inside = np.zeros(self.num_poses, dtype=bool)
        inside[seeds] = True
        for _ in range(hops):
            # One vectorized pass over the edges per hop: no per-pose Python.
            reached = self.hop_edges[inside[self.hop_edges].any(axis=1)]
            if inside[reached].all():
                break
            inside[reached] = True
        return np.flatnonzero(inside)

    def edges_of(self, rows: np.ndarray) -> np.ndarray:
        """Sorted indices of the edges with at least one end among the poses `rows`."""
        among = np.zeros(self.num_poses, dtype=bool)
        among[rows] = True
        return np.flatnonzero(among[self.edges].any(axis=1))


@dataclass(frozen=True, eq=False)
class LocalProblem:
    """A region's poses free, their other neighbours fixed, and every edge with a free end.

    Attributes:
        rows: `(M,)` sorted pose rows of the whole graph in the local problem (free and boundary).
        free: `(M,)` bool, which of `rows` the solve moves.
        edges: `(K,)` sorted indices of the whole graph's edges in it.
        problem: the `egnc.least_squares.Problem` over them, local rows and edges.
    """

    rows: np.ndarray
    free: np.ndarray
    edges: np.ndarray
    problem: Problem

    @classmethod
    def build(
        cls,
        region: np.ndarray,
        neighbourhoods: Neighbourhoods,
        factors: BetweenFactors,
        measurements: np.ndarray,
        T: np.ndarray,
        held: int,
        linear_solver: str,
    ) -> LocalProblem:
        """The local problem of the free poses `region` (sorted rows).

        Args:
            region: `(R,)` sorted rows of the poses to solve.
            neighbourhoods: of the whole graph's edges.
            factors: the whole graph's factors.
            measurements: `(E, P)` the whole graph's measurements in the stored parametrization.
            T: `(N, n, n)` the whole graph's pose matrices.
            held: a row held fixed even inside the region (the gauge), or -1.
            linear_solver: backend name (`egnc.linear_solvers`).
        """
        edges = neighbourhoods.edges_of(region)
        rows = np.unique(factors.edges[edges])
        local_edges = np.searchsorted(rows, factors.edges[edges])
        free = np.isin(rows, region) & (rows != held)
        dim = factors.dim
        d = factors.information.shape[-1]
        graph = PoseGraph(
            dim=dim,
            vertex_ids=np.arange(len(rows)),
            poses=from_matrices(dim, T[rows]),
            edges=local_edges,
            measurements=measurements[edges],
            information=factors.information[edges].reshape(-1, d, d),
            fixed=~free,
        )
        local_factors = BetweenFactors(dim, local_edges, factors.Z_inv[edges], factors.information[edges])
        # A region is small: its direct solver orders it itself, cheaper than a block order.
        return cls(rows, free, edges, Problem.from_graph(graph, linear_solver, local_factors, fill_reducing=False))

    @property
    def boundary(self) -> np.ndarray:
        """Sorted rows of the fixed poses (the region's other neighbours, and a held pose inside it)."""
        return self.rows[~self.free]


def block_jacobi_decrease(
    factors: BetweenFactors, edges: np.ndarray, T: np.ndarray, weights: np.ndarray, rows: np.ndarray
) -> np.ndarray:
    """Per pose of `rows`, the cost decrease its own Newton step would bring, all else held.

    Args:
        factors: the whole graph's factors.
        edges: `(K,)` every edge with an end in `rows` (other edges add nothing).
        T: `(N, n, n)` the whole graph's pose matrices.
        weights: `(K,)` IRLS weights of `edges`.
        rows: `(B,)` sorted pose rows.

    Returns:
        `(B,)` `0.5 g_b^T H_bb^-1 g_b`, from the gradient `g_b` and diagonal block `H_bb` of
        `sum w J^T Omega J` over the edges of pose `b` (cost units).
    """
    subset = factors.subset(edges)
    d = subset.information.shape[-1]
    products = edge_products(subset.linearize(T), subset.information, weights)
    gradient = np.zeros((len(rows) + 1, d))
    block = np.zeros((len(rows) + 1, d, d))
    for end in (0, 1):
        position = np.searchsorted(rows, subset.edges[:, end])
        inside = position < len(rows)
        inside[inside] = rows[position[inside]] == subset.edges[inside, end]
        slot = np.where(inside, position, len(rows))  # the last slot collects the other ends
        span = slice(end * d, (end + 1) * d)
        np.add.at(gradient, slot, products[:, span, 2 * d])
        np.add.at(block, slot, products[:, span, span])
    gradient, block = gradient[:-1], block[:-1]
    step = np.linalg.solve(block + 1e-12 * np.eye(d), gradient[:, :, None])[:, :, 0]
    return 0.5 * np.einsum("bi,bi->b", gradient, step)
