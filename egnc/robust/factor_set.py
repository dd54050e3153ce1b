"""Priors as candidates for rejection: the robust layer's factor arrays, edges then priors.

The linear layer already takes a prior as an edge from one fixed virtual pose
(`egnc.nonlinear.prior_gauge`). Where priors may be rejected, the robust layer takes the same
view one step further: every per-factor array (residual norms, the candidate mask, weights,
`mu`, the inlier flags) has one entry per factor, `(F,) = (E + K,)`, the `E` edges in graph
order followed by the `K` priors. A prior's residual is padded to `d` (`PriorFactors`), so the
norms come from one kind of array; its dimension is not: a position prior measures `dim`
numbers (2 or 3), a pose prior `d`. So every chi-square test is taken at the factor's own
dimension (`FactorSet.dims`, `chi2.ppf(q, d_k)`): the strong-outlier test of the schedule, the
outlier test, re-admission and the truncated cost. `mu*` needs none (it depends on `r` and `c`).

Without candidate priors (no priors, or priors among the known inliers) the robust layer works
on the edges' `BetweenFactors` as it always did, with one scalar `d`, and nothing here runs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.graph import PoseGraph
from egnc.nonlinear.factors import BetweenFactors
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.prior_factors import PriorFactors


@dataclass(frozen=True, eq=False)
class FactorSet:
    """The edges' and the priors' factors, evaluated as one `(E + K,)` factor array.

    Attributes:
        between: the edges' factors `(E,)`.
        priors: the priors' factors `(K,)`.
        dims: `(E + K,)` residual dimension of each factor: `d` for an edge and a pose prior,
            `dim` for a position prior.
    """

    between: BetweenFactors
    priors: PriorFactors
    dims: np.ndarray

    @classmethod
    def from_graph(cls, graph: PoseGraph, between: BetweenFactors) -> FactorSet:
        """The factor set of `graph` (which has priors), whose edges' factors are `between`."""
        dims = np.concatenate((np.full(graph.num_edges, graph.tangent_dim), graph.priors.factor_dims))
        return cls(between, PriorFactors.from_priors(graph.priors), dims)

    @property
    def num_edges(self) -> int:
        """Number of edges E (the priors follow them)."""
        return len(self.between.edges)

    @property
    def information(self) -> np.ndarray:
        """`(E + K, d, d)` information matrices (a position prior's padded with zeros)."""
        return np.concatenate((self.between.information, self.priors.information))

    def residuals(self, T: np.ndarray) -> np.ndarray:
        """`(E + K, d)` residuals at poses `T` `(N, n, n)` (a position prior's padded with zeros)."""
        return np.concatenate((self.between.residuals(T), self.priors.residuals(T)))

    def whitened_norms(self, residuals: np.ndarray) -> np.ndarray:
        """`(E + K,)` whitened norms of `residuals` `(E + K, d)`, each with its own information."""
        E = self.num_edges
        return np.concatenate((self.between.whitened_norms(residuals[:E]), self.priors.whitened_norms(residuals[E:])))

    def edges_of(self, factors: np.ndarray) -> np.ndarray:
        """The edges' part `(E, ...)` of a per-factor array `(E + K, ...)`."""
        return factors[: self.num_edges]

    def priors_of(self, factors: np.ndarray) -> np.ndarray:
        """The priors' part `(K, ...)` of a per-factor array `(E + K, ...)`."""
        return factors[self.num_edges :]


Factors = BetweenFactors | FactorSet
"""The factors the robust layer decides on: the edges alone, or the edges then the priors."""


def factor_dims(graph: PoseGraph, factors: Factors) -> int | np.ndarray:
    """The dimension of the chi-square tests: `graph.tangent_dim`, or per factor `(E + K,)`."""
    return factors.dims if isinstance(factors, FactorSet) else graph.tangent_dim


def edge_factors(factors: Factors) -> BetweenFactors:
    """The edges' factors of `factors`."""
    return factors.between if isinstance(factors, FactorSet) else factors


def subgraph(graph: PoseGraph, factors: Factors, keep: np.ndarray) -> PoseGraph:
    """`graph` with the factors `keep` `(F,)` bool: edges, and priors where `factors` holds them."""
    if not isinstance(factors, FactorSet):
        return graph.subgraph_edges(keep)
    kept = graph.subgraph_edges(factors.edges_of(keep))
    return replace(kept, priors=graph.priors.subset(factors.priors_of(keep)))


def factor_problem(graph: PoseGraph, factors: Factors, linear_solver: str, keep: np.ndarray | None = None) -> Problem:
    """The least-squares problem of the factors `keep` `(F,)` of `graph` (None: all), its loss
    covering the priors where they are candidates (`Problem.weighted_priors`)."""
    between = edge_factors(factors)
    if keep is None:
        return Problem.from_graph(graph, linear_solver, between, weighted_priors=isinstance(factors, FactorSet))
    kept = subgraph(graph, factors, keep)
    edges = factors.edges_of(keep) if isinstance(factors, FactorSet) else keep
    return Problem.from_graph(
        kept, linear_solver, between.subset(edges), weighted_priors=isinstance(factors, FactorSet)
    )
