"""Linear solvers that analyse a pattern at their first factorization, and in a backend's block order.

A robust problem's whole normal equations hold every false loop's fill-in, and its steps mostly
go through CG with the trusted preconditioner (`egnc.linalg.step_solver`): `OnFirstUse` defers
their symbolic analysis to a direct step that needs it. `InBlockOrder` factorizes a pattern built
in pose-row order in the backend's fill-reducing block order (for a backend whose block order
costs a factorization), and `PermutedFactorization` is such a factorization seen from the
pattern's own unknowns.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from egnc.linalg.linear_solvers import (
    Backend,
    Factorization,
    LinearSolver,
    TriangularFactor,
    block_order,
    make_linear_solver,
)
from egnc.linalg.normal_equations import NormalEquationsPattern

__all__ = ["InBlockOrder", "OnFirstUse", "PermutedFactorization"]


class OnFirstUse:
    """A `LinearSolver` whose symbolic analysis runs at its first factorization.

    A robust problem's full pattern holds every false loop's fill-in, and its steps go through
    the trusted preconditioner: the full analysis is needed only when a step falls back to the
    direct solve. On a 100 000-pose grid with 30 % false loops CHOLMOD refuses to analyse it at
    all ("problem too large": the factor would exceed its integer range).
    """

    name: str

    def __init__(
        self,
        backend: Backend,
        pattern: NormalEquationsPattern,
        ordered: bool = True,
        in_block_order: tuple[int, np.ndarray] | None = None,
    ):
        """`ordered`: the pattern is in a fill-reducing order already. `in_block_order`:
        `(num_blocks, (K, 2) block pairs)` of a pattern in pose-row order to factorize in the
        backend's block order instead (`InBlockOrder`)."""
        self.name = self._backend = backend
        self._pattern = pattern
        self._ordered = ordered
        self._in_block_order = in_block_order
        self._solver: LinearSolver | None = None

    def _analysed(self) -> LinearSolver:
        if self._solver is None:
            pattern = self._pattern
            if self._in_block_order is not None:
                self._solver = InBlockOrder(self._backend, pattern, *self._in_block_order)
            else:
                self._solver = make_linear_solver(self.name, pattern.indptr, pattern.indices, ordered=self._ordered)
        return self._solver

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the matrix with CSC values `data` `(nnz,)` and return `x` `(n,)`."""
        return self._analysed().solve(data, rhs)

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the matrix with CSC values `data` `(nnz,)`."""
        return self._analysed().factorize(data)


_PERMUTED_COLUMNS = 32
"""Right-hand-side columns `InBlockOrder` permutes and solves at once: a whole permuted copy of a
many-column right-hand side (the marginal covariances') added 16 MiB to the peak of
manhattanOlson3500's robust solve, and SuperLU solves 32 columns at a time as fast as 192."""


class InBlockOrder:
    """A `LinearSolver` for a pattern in pose-row order that factorizes it in the backend's block order.

    The order (`block_order`) is computed here, and the pattern permuted into it once: each
    factorization gathers the values into that pattern, each solve permutes the right-hand side
    and the solution. The factorization is the one of a pattern built in that order.
    """

    name: str

    def __init__(self, backend: Backend, pattern: NormalEquationsPattern, num_blocks: int, block_pairs: np.ndarray):
        """Args:
        backend: resolved backend (one that stores the whole matrix, not its lower triangle).
        pattern: the pattern, in pose-row order.
        num_blocks: number of unknown blocks (free poses).
        block_pairs: `(K, 2)` block indices joined by an edge.
        """
        assert not pattern.lower_only, "a permuted lower triangle is not lower"
        self.name = backend
        order = block_order(backend, num_blocks, block_pairs)
        d = pattern.size // max(num_blocks, 1)
        self._unknowns = (order[:, None] * d + np.arange(d)).ravel()  # unknown at each ordered position
        n = pattern.size
        index = np.int32 if pattern.nnz < 2**31 else np.int64  # halves the transient copies below
        slot = sp.csc_matrix(
            (np.arange(pattern.nnz, dtype=index), pattern.indices.astype(index), pattern.indptr.astype(index)),
            shape=(n, n),
        )
        ordered = slot[:, self._unknowns][self._unknowns, :].tocsc()
        ordered.sort_indices()
        self._slots = ordered.data  # data slot of each value of the ordered pattern
        self._solver = make_linear_solver(backend, ordered.indptr, ordered.indices, ordered=True)

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the matrix with CSC values `data` `(nnz,)` and return `x` `(n,)`."""
        return self.factorize(data)(rhs)

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the matrix with CSC values `data` `(nnz,)` (pose-row order)."""
        return PermutedFactorization(self._solver.factorize(data[self._slots]), self._unknowns)


class PermutedFactorization:
    """The factorization of `A[unknowns][:, unknowns]` as one of `A` (`InBlockOrder`, a trusted system)."""

    def __init__(self, ordered: Factorization, unknowns: np.ndarray):
        self._ordered = ordered
        self._unknowns = unknowns

    def __call__(self, rhs: np.ndarray) -> np.ndarray:
        unknowns = self._unknowns
        out = np.empty(rhs.shape)
        if rhs.ndim == 1:
            out[unknowns] = self._ordered(rhs[unknowns])
            return out
        for start in range(0, rhs.shape[1], _PERMUTED_COLUMNS):
            columns = slice(start, start + _PERMUTED_COLUMNS)
            out[unknowns, columns] = self._ordered(rhs[unknowns, columns])
        return out

    def triangular(self, build: bool = True) -> TriangularFactor | None:
        """The ordered factor, its elimination order mapped back to `A`'s unknowns (`Factorization.triangular`)."""
        factor = self._ordered.triangular(build)
        return None if factor is None else replace(factor, order=self._unknowns[factor.order])
