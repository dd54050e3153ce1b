"""Marginal covariances of poses and of loop-closure predictions, from the least-squares information.

At a least-squares solution the Gauss-Newton information of the free pose steps is
`H = sum_e J_e^T Omega_e J_e`, and `H^-1` is their covariance (the Laplace approximation GTSAM's
`Marginals` uses). Poses held fixed (the gauge) have none: covariances are relative to them.

For a loop closure `(i, j)` that is *not* in `H`, its residual `e` predicted by the rest of the
graph has covariance `S = Omega^-1 + A H^-1 A^T`, with `A = [J_e_xi | J_e_xj]` the residual's
Jacobian. Then `e^T S^-1 e` (the innovation statistic) is chi-square with `d` degrees of freedom
when the loop agrees with the map; for a linear model it is also twice the least-squares cost the
loop would add. This is the re-admission test of `egnc.gnc`.

Every query needs `A H^-1 A^T`, a `d x d` block: it is read off `H^-1 B` for a right-hand side `B`
holding `A^T` in the rows of the two poses, solved for many queries at once with one
factorization (in groups of columns, to bound memory). `B` has `2 d` nonzeros per column, so it
is kept sparse and `B^T H^-1 B` is a sparse-dense product: as a dense product it cost twice the
solve itself (a 192-column batch over 75 000 unknowns: 1.3 s against 0.7 s).

References:
    M. Kaess, F. Dellaert, "Covariance recovery from a square root information matrix for data
    association", RAS 2009 (marginals of selected poses and of data-association candidates).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import scipy.sparse as sp

from egnc.factors import BetweenFactors
from egnc.least_squares import Problem

_MAX_RHS_VALUES = 2**24
"""Largest `n x columns` right-hand side solved at once (128 MiB of float64)."""


def covariance_solver(problem: Problem, poses: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """`B -> H^-1 B` for the unweighted information `H` of `problem` at `poses` `(N, n, n)` (one factorization).

    Raises:
        NotPositiveDefiniteError: `H` cannot be factorized (a degenerate solution).
    """
    factors = problem.factors
    linearization = factors.linearize(poses)
    data, _ = problem.pattern.assemble(linearization, factors.information, np.ones(len(factors.edges)))
    return problem.linear_solver.factorize(data)


def _transposed_jacobians(problem: Problem, rows: np.ndarray, blocks: np.ndarray) -> sp.csc_matrix:
    """Sparse `(n, K d)` matrix `B` whose `k`-th group of `d` columns is `A_k^T`.

    Args:
        problem: gives the unknowns' layout.
        rows: `(K, m)` pose rows each query depends on.
        blocks: `(K, m, d, d)` the query's Jacobian block `A_k` for each of those poses (output by
            pose tangent); blocks of fixed poses are dropped (they carry no unknowns).
    """
    free_index = problem.pattern.free_index
    num_queries, d = len(rows), blocks.shape[-1]
    columns = np.arange(num_queries)[:, None] * d + np.arange(d)  # (K, d)
    row_parts, column_parts, value_parts = [], [], []
    for side in range(rows.shape[1]):
        var = free_index[rows[:, side]]
        free = var >= 0
        row_index = var[free, None] * d + np.arange(d)  # (K', d)
        # B[row a of the pose block, column b of the query] = A[b, a]
        shape = (int(free.sum()), d, d)
        row_parts.append(np.broadcast_to(row_index[:, :, None], shape).ravel())
        column_parts.append(np.broadcast_to(columns[free][:, None, :], shape).ravel())
        value_parts.append(np.swapaxes(blocks[free, side], 1, 2).ravel())
    return sp.csc_matrix(
        (np.concatenate(value_parts), (np.concatenate(row_parts), np.concatenate(column_parts))),
        shape=(problem.pattern.size, num_queries * d),
    )


def _solved_columns(
    B: sp.csc_matrix, covariance_solve: Callable[[np.ndarray], np.ndarray], group: int
) -> Iterator[tuple[slice, np.ndarray]]:
    """`(columns, H^-1 B[:, columns])` over consecutive groups of whole `group`-column blocks, so that
    at most about `_MAX_RHS_VALUES` values of dense right-hand side exist at once."""
    n, width = B.shape
    chunk = max(group, _MAX_RHS_VALUES // max(n, 1) // group * group)
    for start in range(0, width, chunk):
        columns = slice(start, min(start + chunk, width))
        yield columns, covariance_solve(B[:, columns].toarray())


def pose_covariances(problem: Problem, poses: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """`(K, d, d)` marginal covariances of the right-perturbation tangents of pose `rows` `(K,)`.

    Tangent order `[v, omega]` (translation first), as the residuals; fixed poses get zeros.
    Solved in groups of columns so that memory stays bounded for many poses.
    """
    rows = np.asarray(rows, dtype=np.int64)
    d = problem.graph.tangent_dim
    if not problem.pattern.size:
        return np.zeros((len(rows), d, d))
    B = _transposed_jacobians(problem, rows[:, None], np.broadcast_to(np.eye(d), (len(rows), 1, d, d)))
    return _diagonal_blocks(B, covariance_solver(problem, poses), d)


def relative_covariances(problem: Problem, poses: np.ndarray, loops: BetweenFactors) -> np.ndarray:
    """`(K, d, d)` covariances `A H^-1 A^T` of the residuals of `loops` predicted by the map of `problem`.

    `A` is a loop's residual Jacobian at `poses`; for a loop that is an edge of `problem` this is
    the covariance of its fitted residual's prediction (its leverage is `Omega^(1/2) A H^-1 A^T
    Omega^(1/2)`), for one that is not, the map's share of its innovation covariance.

    Raises:
        NotPositiveDefiniteError: `H` cannot be factorized (a degenerate solution).
    """
    d = loops.information.shape[-1]
    if not problem.pattern.size or not len(loops.edges):
        return np.zeros((len(loops.edges), d, d))
    linearization = loops.linearize(poses)
    blocks = np.stack([linearization.J_e_xi, linearization.J_e_xj], axis=1)
    B = _transposed_jacobians(problem, loops.edges, blocks)
    return _diagonal_blocks(B, covariance_solver(problem, poses), d)


def _diagonal_blocks(B: sp.csc_matrix, covariance_solve: Callable[[np.ndarray], np.ndarray], d: int) -> np.ndarray:
    """`(K, d, d)` the diagonal `d x d` blocks of `B^T H^-1 B`, symmetrized, for `B` `(n, K d)`."""
    out = np.zeros((B.shape[1] // d, d, d))
    for columns, X in _solved_columns(B, covariance_solve, d):
        # B is sparse: the product over these columns is cheap next to the solve
        count = (columns.stop - columns.start) // d
        blocks = (B[:, columns].T @ X).reshape(count, d, count, d)
        out[columns.start // d : columns.stop // d] = blocks[np.arange(count), :, np.arange(count), :]
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def innovations(
    problem: Problem,
    poses: np.ndarray,
    loops: BetweenFactors,
    covariance_solve: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of loop closures left out of `problem` and their joint predicted covariance.

    Args:
        problem: the least-squares problem of the accepted edges, at its solution `poses`.
        poses: `(N, n, n)` the solution.
        loops: `K` left-out loop closures (rows of the same poses); keep `K` small (the
            covariance is dense).
        covariance_solve: `covariance_solver(problem, poses)`
            if already computed (several batches at one solution share it).

    Returns:
        `(e, S)`: `(K, d)` residuals and `(K d, K d)` covariance `blockdiag(Omega^-1) + A H^-1 A^T`.
    """
    linearization = loops.linearize(poses)
    e = linearization.residuals
    d = e.shape[1]
    S = np.zeros((e.size, e.size))
    if problem.pattern.size and len(e):
        blocks = np.stack([linearization.J_e_xi, linearization.J_e_xj], axis=1)
        B = _transposed_jacobians(problem, loops.edges, blocks)
        if covariance_solve is None:
            covariance_solve = covariance_solver(problem, poses)
        transposed = B.T.tocsr()
        for columns, X in _solved_columns(B, covariance_solve, d):
            S[:, columns] = transposed @ X
        S = 0.5 * (S + S.T)
    block = np.arange(len(e))[:, None] * d + np.arange(d)  # (K, d) rows of each loop
    S[block[:, :, None], block[:, None, :]] += np.linalg.inv(loops.information)
    return e, S
