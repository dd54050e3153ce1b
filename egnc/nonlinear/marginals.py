"""Marginal covariances of poses and of loop-closure predictions, from the least-squares information.

At a least-squares solution the Gauss-Newton information of the free pose steps is
`H = sum_e J_e^T Omega_e J_e`, and `H^-1` is their covariance (the Laplace approximation GTSAM's
`Marginals` uses). Poses held fixed (the gauge) have none: covariances are relative to them.

For a loop closure `(i, j)` that is *not* in `H`, its residual `e` predicted by the rest of the
graph has covariance `S = Omega^-1 + A H^-1 A^T`, with `A = [J_e_xi | J_e_xj]` the residual's
Jacobian. Then `e^T S^-1 e` (the innovation statistic) is chi-square with `d` degrees of freedom
when the loop agrees with the map; for a linear model it is also twice the least-squares cost the
loop would add. This is the re-admission test of `egnc.robust.gnc`.

Every query needs `A H^-1 A^T`, a `d x d` block: it is read off `H^-1 B` for a right-hand side `B`
holding `A^T` in the rows of the two poses, solved for many queries at once with one
factorization (in groups of columns, to bound memory). `B` has `2 d` nonzeros per column, so it
is kept sparse and `B^T H^-1 B` is a sparse-dense product: as a dense product it cost twice the
solve itself (a 192-column batch over 75 000 unknowns: 1.3 s against 0.7 s).

The joint covariance of a few queries (`innovations`) needs less: with `H = P^T L D L^T P`,
`B^T H^-1 B = W^T D^-1 W` for `W = L^-1 P B`, and `W` is zero outside the *reach* of `B`'s rows,
the positions whose elimination depends on them (their ancestors in the elimination tree). So
`W` is solved with the columns of `L` on that reach only, where the backend exposes its factor
(`egnc.linalg.linear_solvers.TriangularFactor`): on a 100 000-pose 2D grid a 64-loop batch's reach is
7 % of the unknowns and 31 % of `L`'s entries (BENCHMARKS.md, issue 18). The reach's columns are
taken in dense panels, one per run of columns that share their rows below (a supernode of `L`):
each panel is a dense triangular solve and a matrix product on all right-hand sides at once.

References:
    M. Kaess, F. Dellaert, "Covariance recovery from a square root information matrix for data
    association", RAS 2009 (marginals of selected poses and of data-association candidates).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from egnc.errors import GraphError
from egnc.graph.connectivity import connected_components, describe_ids
from egnc.linalg.linear_solvers import (
    Factorization,
    NotPositiveDefiniteError,
    TriangularFactor,
    exact_factor_pattern,
    serial_native_threads,
)
from egnc.linalg.normal_equations import NormalEquationsPattern, edge_products
from egnc.nonlinear.factors import BetweenFactors
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.prior_gauge import with_prior_products

_MAX_RHS_VALUES = 2**24
"""Largest `n x columns` right-hand side solved at once (128 MiB of float64)."""

REACH_MIN_UNKNOWNS = 50_000
"""Systems with fewer unknowns solve `B^T H^-1 B` whole: their solves take milliseconds, less than
exposing the factor and importing SciPy's triangular solver (BENCHMARKS.md, issue 18)."""

REACH_MAX_SHARE = 0.4
"""The factor is exported and the reach solved when the columns of `L` on the reach hold at most
this share of its entries. In time the reach pays at any share (its panels cost about a third of
a whole forward and back solve per entry and right-hand side); the bound keeps the export, a
copy of `L`, off systems whose queries reach most of `L` (3D grids), where that copy would set
the robust solve's peak memory (BENCHMARKS.md, issue 18)."""


@dataclass(frozen=True, eq=False)
class ReachEstimate:
    """Which share of `L`'s entries the reach of a query holds, known before `L` is exported.

    Exporting a factor (`Factorization.triangular`) copies it, which on large 3D maps is the
    robust solve's peak memory, while their reaches hold too much of `L` to be used
    (BENCHMARKS.md, issue 18, seventeenth session). Every `d x d` block of a pair of poses has
    the same pattern in `L`, so the pose-level pattern, factorized without values
    (`exact_factor_pattern`), gives the elimination tree and every column's count exactly. It
    counts no explicit zeros, which a supernodal factor stores: its shares read up to about 1.3x
    the exported factor's.

    Attributes:
        parent: pose-level elimination tree: the parent position of each position, -1 at a root.
        position: `(B,)` elimination position of each unknown block.
        entries: `(B,)` entries of `L` in the `d` columns of the block at each position.
        d: tangent dimension.
    """

    parent: list[int]
    position: np.ndarray
    entries: np.ndarray
    d: int

    @classmethod
    def of(cls, problem: Problem) -> ReachEstimate | None:
        """The estimate for `problem`'s information, or None where the reach is not used (a system
        below `REACH_MIN_UNKNOWNS`) or cannot be estimated (a backend other than CHOLMOD, whose
        elimination order is not the pattern's, or no CHOLMOD to factorize the structure)."""
        pattern, d = problem.pattern, problem.tangent_dim
        if pattern.size < REACH_MIN_UNKNOWNS or problem.linear_solver.name != "cholmod":
            return None
        # CHOLMOD's pattern is the lower triangle: scalar column J d holds the stored blocks of
        # block column J, d sorted rows each, the diagonal block first.
        num_blocks = pattern.size // d
        starts = pattern.indptr[np.arange(num_blocks) * d]
        counts = (pattern.indptr[np.arange(num_blocks) * d + 1] - starts) // d
        indptr = np.concatenate([[0], np.cumsum(counts)])
        rank = np.arange(indptr[-1]) - np.repeat(indptr[:-1], counts)  # each block's place in its column
        rows = pattern.indices[np.repeat(starts, counts) + d * rank] // d
        blocks = sp.csc_matrix((np.ones(len(rows)), rows, indptr), shape=(num_blocks, num_blocks))
        exact = exact_factor_pattern(blocks)
        if exact is None:
            return None
        factor, order = exact
        position = np.empty(num_blocks, dtype=np.int64)
        position[order] = np.arange(num_blocks)
        # A block column of c blocks holds d columns of c d, c d - 1, ..., c d - d + 1 entries.
        entries = d * d * np.diff(factor.indptr) - d * (d - 1) // 2
        return cls(_tree_parents(factor).tolist(), position, entries, d)

    def share(self, B: sp.csc_matrix) -> float:
        """The share of `L`'s entries in the columns of the reach of `B`'s rows (`(n, K)`, unknowns)."""
        reached: set[int] = set()
        for position in np.unique(self.position[B.indices // self.d]).tolist():
            while position >= 0 and position not in reached:  # up the tree to a root or a reached position
                reached.add(position)
                position = self.parent[position]
        return float(self.entries[list(reached)].sum() / self.entries.sum())


def covariance_solver(problem: Problem, poses: np.ndarray, weights: np.ndarray | None = None) -> Factorization:
    """The factorization of the information `H` of `problem` at `poses` `(N, n, n)`: `B -> H^-1 B`.

    `weights`: `(E,)` weight of each of `problem`'s edges in `H` (0 leaves an edge out), followed
    by the priors' `(K,)` where its loss covers them (`Problem.weighted_priors`); None: 1.

    Raises:
        NotPositiveDefiniteError: `H` cannot be factorized (a degenerate solution).
    """
    factors = problem.factors
    linearization = factors.linearize(poses)
    weights = np.ones(len(factors.edges)) if weights is None else weights
    if problem.priors is None:
        data, _ = problem.pattern.assemble(linearization, factors.information, weights)
    else:  # the pattern holds the priors after the edges (`egnc.nonlinear.prior_gauge`)
        E = len(factors.edges)
        prior_weights = weights[E:] if problem.weighted_priors and len(weights) > E else None
        products = edge_products(linearization, factors.information, weights[:E])
        with_priors = with_prior_products(problem.priors, poses, products, weights[:E], None, prior_weights)
        data, _ = problem.pattern.scatter(with_priors[0])
    return problem.linear_solver.factorize(data)


def transposed_jacobians(pattern: NormalEquationsPattern, rows: np.ndarray, blocks: np.ndarray) -> sp.csc_matrix:
    """Sparse `(n, K d)` matrix `B` whose `k`-th group of `d` columns is `A_k^T`; repeated rows add up.

    Args:
        pattern: gives the unknowns' layout (`free_index`, `size`).
        rows: `(K, m)` pose rows each query depends on.
        blocks: `(K, m, d, d)` the query's Jacobian block `A_k` for each of those poses (output by
            pose tangent); blocks of fixed poses are dropped (they carry no unknowns).
    """
    free_index = pattern.free_index
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
        shape=(pattern.size, num_queries * d),
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


def pose_covariances(
    problem: Problem, poses: np.ndarray, rows: np.ndarray, vertex_ids: np.ndarray | None = None
) -> np.ndarray:
    """`(K, d, d)` marginal covariances of the right-perturbation tangents of pose `rows` `(K,)`.

    Tangent order `[v, omega]` (translation first), as the residuals; fixed poses get zeros.
    Solved in groups of columns so that memory stays bounded for many poses. `vertex_ids`:
    `(N,)` the poses' ids, to name them in errors (None: by row).

    Raises:
        GraphError: the edges of `problem` leave some poses without a path to a fixed one
            (`require_anchored`).
        NotPositiveDefiniteError: `H` cannot be factorized for another reason (a degenerate solution).
    """
    rows = np.asarray(rows, dtype=np.int64)
    d = problem.tangent_dim
    if not problem.pattern.size:
        return np.zeros((len(rows), d, d))
    require_anchored(problem, vertex_ids)
    B = transposed_jacobians(problem.pattern, rows[:, None], np.broadcast_to(np.eye(d), (len(rows), 1, d, d)))
    try:
        solver = covariance_solver(problem, poses)
    except NotPositiveDefiniteError:
        # The backend's own words (CHOLMOD's source line, SuperLU's "exactly singular") name no pose.
        raise NotPositiveDefiniteError(
            "marginal_covariances: the information of the accepted edges is singular at this solution, so the"
            " poses have no covariance; check it for poses placed on top of one another or non-finite values"
        ) from None
    return diagonal_blocks(B, solver, d)


def require_anchored(problem: Problem, vertex_ids: np.ndarray | None = None) -> None:
    """Raise `GraphError` unless every pose joined by `problem`'s edges has a path to a fixed pose.

    A pose without one (in a component of the edges holding no fixed pose, e.g. cut off by
    rejected loop closures, or touched by no edge) can move freely: its information is singular
    and it has no covariance. The gauge pose `Problem` fixes counts as fixed.

    Args:
        problem: the least-squares problem (`Problem.fixed` holds the gauge).
        vertex_ids: `(N,)` the poses' ids, to name them (None: by row).
    """
    count, labels = connected_components(problem.num_poses, problem.factors.edges)
    anchored = np.zeros(count, dtype=bool)
    anchored[labels[problem.fixed]] = True
    if problem.priors is not None and not problem.fixed.any():  # the priors pin the gauge
        anchored[labels[problem.priors.rows]] = True
    loose = np.flatnonzero(~anchored[labels])
    if not len(loose):
        return
    named = (
        f"poses {describe_ids(np.asarray(vertex_ids)[loose])}"
        if vertex_ids is not None
        else f"the poses in rows {describe_ids(loose)} of the graph"
    )
    components = int(np.count_nonzero(~anchored))
    raise GraphError(
        f"marginal_covariances: {named} ({len(loose)} of {problem.num_poses}, in {components} part"
        f"{'s' if components != 1 else ''} of the graph) have no path of accepted edges to a fixed pose, so they"
        " have no covariance; accept an edge joining them to the rest, or hold one pose of each part fixed"
    )


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
    B = transposed_jacobians(problem.pattern, loops.edges, blocks)
    return diagonal_blocks(B, covariance_solver(problem, poses), d)


def diagonal_blocks(B: sp.csc_matrix, covariance_solve: Callable[[np.ndarray], np.ndarray], d: int) -> np.ndarray:
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
    covariance_solve: Factorization | None = None,
    estimate: ReachEstimate | None = None,
    export: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of loop closures left out of `problem` and their joint predicted covariance.

    Args:
        problem: the least-squares problem of the accepted edges, at its solution `poses`.
        poses: `(N, n, n)` the solution.
        loops: `K` left-out loop closures (rows of the same poses); keep `K` small (the
            covariance is dense).
        covariance_solve: `covariance_solver(problem, poses)`
            if already computed (several batches at one solution share it).
        estimate: `ReachEstimate.of(problem)`, computed once for the batches that share
            `covariance_solve`; without it the factor is exported for any large system.
        export: whether this query may export the factor (`quadratic_form`).

    Returns:
        `(e, S)`: `(K, d)` residuals and `(K d, K d)` covariance `blockdiag(Omega^-1) + A H^-1 A^T`.
    """
    linearization = loops.linearize(poses)
    e = linearization.residuals
    d = e.shape[1]
    S = np.zeros((e.size, e.size))
    if problem.pattern.size and len(e):
        blocks = np.stack([linearization.J_e_xi, linearization.J_e_xj], axis=1)
        B = transposed_jacobians(problem.pattern, loops.edges, blocks)
        if covariance_solve is None:
            covariance_solve = covariance_solver(problem, poses)
        S = quadratic_form(B, covariance_solve, estimate, export)
    block = np.arange(len(e))[:, None] * d + np.arange(d)  # (K, d) rows of each loop
    S[block[:, :, None], block[:, None, :]] += np.linalg.inv(loops.information)
    return e, S


def quadratic_form(
    B: sp.csc_matrix, covariance_solve: Factorization, estimate: ReachEstimate | None = None, export: bool = True
) -> np.ndarray:
    """`(K, K)` `B^T H^-1 B`, symmetrized, for a sparse `B` `(n, K)` and the factorization of `H`.

    Solved on the reach of `B`'s rows (module docstring) when the system has at least
    `REACH_MIN_UNKNOWNS` unknowns, the factor is exposed, the reach holds at most
    `REACH_MAX_SHARE` of it and its solution fits the memory bound of a right-hand side; else by
    whole solves in column groups. The factor is exported for a query only where `export` is
    true and the `estimate` of its reach's share (`ReachEstimate`) is at most `REACH_MAX_SHARE`;
    once exported, its own count decides. A query of a few columns costs less whole than the
    export (one loop on a 100 000-pose 2D grid: 0.09 s against 0.33 s), so a caller passes
    `export=False` for one that larger queries may not follow.
    """
    factor = None
    if B.shape[0] >= REACH_MIN_UNKNOWNS:
        factor = covariance_solve.triangular(build=False)
        if factor is None and export and (estimate is None or estimate.share(B) <= REACH_MAX_SHARE):
            factor = covariance_solve.triangular()
    solved = None if factor is None else _reach_solve(factor, B)
    if factor is not None and solved is not None:
        reach, W = solved
        out = W.T @ (W if factor.pivots is None else W / factor.pivots[reach, None])
        return 0.5 * (out + out.T)
    out = np.empty((B.shape[1], B.shape[1]))
    transposed = B.T.tocsr()
    for columns, X in _solved_columns(B, covariance_solve, 1):
        out[:, columns] = transposed @ X
    return 0.5 * (out + out.T)


def _reach_solve(factor: TriangularFactor, B: sp.csc_matrix) -> tuple[np.ndarray, np.ndarray] | None:
    """`(reach, W)`: the elimination positions `reach` `(m,)` where `L^-1 P B` can be nonzero, and
    its rows there `(m, K)`; None when `m K` exceeds the right-hand-side bound (`_MAX_RHS_VALUES`)
    or the reach's columns hold more than `REACH_MAX_SHARE` of `L`'s entries."""
    lower = factor.lower
    n = lower.shape[0]
    position = np.empty(n, dtype=np.int64)
    position[factor.order] = np.arange(n)
    rows = position[B.indices]  # elimination position of each entry of B
    sources = np.unique(rows)

    def worth_it(reach: np.ndarray) -> bool:
        return len(reach) * B.shape[1] <= _MAX_RHS_VALUES and _entries(lower, reach) <= REACH_MAX_SHARE * lower.nnz

    reach = _ancestors(_elimination_tree(lower), sources)
    if not worth_it(reach):  # nor is the factor's whole reach, which holds this one
        return None
    rhs = sp.csc_matrix((B.data, rows, B.indptr), shape=(n, B.shape[1]))
    with serial_native_threads():  # BLAS calls on small panels: one thread (egnc.linalg.linear_solvers)
        solved = _forward_solve_on(lower, reach, rhs)
        if solved is None:  # a factor whose columns reach past their tree ancestors
            reach = _ancestors(lower, sources)
            if not worth_it(reach):
                return None
            solved = _forward_solve_on(lower, reach, rhs)
    assert solved is not None, "the reach along the factor's own columns holds every row they reach"
    return reach, solved


def _forward_solve_on(lower: sp.csc_matrix, reach: np.ndarray, rhs: sp.csc_matrix) -> np.ndarray | None:
    """`(m, K)` rows `reach` `(m,)` of `L^-1 rhs` (`rhs` `(n, K)`, zero outside `reach`), panel by
    panel; None where a row of a reach column lies outside `reach` (`L^-1 rhs` is then not zero there).

    A panel is a run of consecutive columns each of which holds its diagonal and then exactly the
    rows of the next (a supernode of `L`): `w` columns over `r` rows below them are one dense
    `w x w` triangular solve and one `r x w` product on all right-hand sides at once (BLAS 3)
    instead of `w` sparse column updates. Runs whose counts and first rows suggest a panel are
    checked row by row and, where the rows differ, solved one column at a time.
    """
    from scipy.linalg import solve_triangular  # SciPy's dense linear algebra: imported where it is used

    indptr, indices, data = lower.indptr, lower.indices, lower.data
    local = np.full(lower.shape[0], -1, dtype=np.int64)
    local[reach] = np.arange(len(reach))
    solution = sp.csc_matrix((rhs.data, local[rhs.indices], rhs.indptr), shape=(len(reach), rhs.shape[1])).toarray()

    def solve_panel(start: int, end: int) -> bool | None:
        """Solve reach positions `start..end - 1` as one panel: True, or False where their rows do
        not form one, None where a row is outside the reach."""
        first, last = int(reach[start]), int(reach[end - 1])
        width = end - start
        below = indices[indptr[last] + 1 : indptr[last + 1]]  # rows under the panel's triangle
        if np.any(local[below] < 0):
            return None
        begin, stop = indptr[first], indptr[last + 1]
        column = np.repeat(np.arange(width), np.diff(indptr[first : last + 2]))
        row = np.arange(stop - begin) - (indptr[first : last + 1] - begin)[column] + column  # within the panel
        if not np.array_equal(indices[begin:stop], np.concatenate([np.arange(first, last + 1), below])[row]):
            return False
        height = width + len(below)
        panel = np.zeros((width, height))  # transposed: column k of the panel is row k here
        panel[column, row] = data[begin:stop]
        block = solve_triangular(panel[:, :width].T, solution[start:end], lower=True, check_finite=False)
        solution[start:end] = block
        if len(below):
            solution[local[below]] -= panel[:, width:].T @ block
        return True

    counts = indptr[reach + 1] - indptr[reach]
    parents = _tree_parents(lower, reach)
    joined = np.zeros(len(reach), dtype=bool)
    joined[1:] = (np.diff(reach) == 1) & (counts[:-1] == counts[1:] + 1) & (parents[:-1] == reach[1:])
    starts = np.flatnonzero(~joined)
    ends = np.concatenate([starts[1:], [len(reach)]])[: len(starts)]  # none for an empty reach
    for start, end in zip(starts.tolist(), ends.tolist(), strict=True):
        solved = solve_panel(start, end)
        if solved is False:  # one column alone is always a panel
            solved = all(solve_panel(k, k + 1) is not None for k in range(start, end))
        if not solved:
            return None
    return solution


def _entries(lower: sp.csc_matrix, positions: np.ndarray) -> int:
    """Stored entries of the columns `positions` of `lower`."""
    return int(np.sum(np.diff(lower.indptr)[positions]))


def _tree_parents(lower: sp.csc_matrix, columns: np.ndarray | None = None) -> np.ndarray:
    """`(c,)` the elimination-tree parent of each of `columns` (default: all) of `lower`, a CSC
    lower triangle with sorted rows: the first row below the diagonal of its column, -1 for a root."""
    columns = np.arange(lower.shape[0]) if columns is None else columns
    first_below = lower.indptr[columns] + (lower.indices[lower.indptr[columns]] == columns)
    has_parent = first_below < lower.indptr[columns + 1]
    parents = np.full(len(columns), -1, dtype=np.int64)
    parents[has_parent] = lower.indices[first_below[has_parent]]
    return parents


def _elimination_tree(lower: sp.csc_matrix) -> sp.csc_matrix:
    """`(n, n)` pattern whose column `k` holds the parent of position `k` in the elimination tree of
    `lower` (`_tree_parents`), empty for a root."""
    n = lower.shape[0]
    parents = _tree_parents(lower)
    has_parent = parents >= 0
    indptr = np.concatenate([[0], np.cumsum(has_parent)])
    return sp.csc_matrix((np.ones(int(has_parent.sum())), parents[has_parent], indptr), shape=(n, n))


def _ancestors(graph: sp.csc_matrix, sources: np.ndarray) -> np.ndarray:
    """Sorted positions reachable from `sources` along `graph`'s edges (column `k` to its rows), sources included."""
    from scipy.sparse.csgraph import breadth_first_order

    n = graph.shape[0]
    # A virtual vertex n with an edge to every source: one traversal from it reaches the union.
    indptr = np.concatenate([graph.indptr, [graph.indptr[-1] + len(sources)]])
    indices = np.concatenate([graph.indices, sources])
    edges = sp.csr_matrix((np.ones(len(indices)), indices, indptr), shape=(n + 1, n + 1))
    reached = breadth_first_order(edges, n, directed=True, return_predecessors=False)
    return np.sort(reached[1:])
