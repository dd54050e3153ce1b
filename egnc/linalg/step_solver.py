"""Solve the damped normal equations of one linearization without paying for switched-off edges.

`(H + diag(s)) x = b` with `H = sum_e w_e J_e^T Omega_e J_e` is solved one of two ways:

- **direct**: a sparse Cholesky (or SuperLU) factorization of all of `H`;
- **trusted-preconditioned conjugate gradients**: split `H = H_T + H_U`, where `H_T` holds the
  trusted edges (weight `w >= trust_weight`: known inliers and the loop closures the robust
  kernel has not switched off) and `H_U` the others. CG runs on the whole of `H + diag(s)`,
  preconditioned by the Cholesky factorization of `H_T + diag(s)`. Nothing is dropped: an
  untrusted edge is in the operator with its own weight, and a loop whose weight comes back
  rejoins the trusted set at the next linearization. The preconditioner has the sparsity of the
  trusted graph (a false loop joins distant poses, and its fill-in is what made a robust
  iteration cost 20-100 clean ones), while `P^-1 (H + diag(s)) = I + P^-1 H_U` differs from
  the identity only by the untrusted edges' small, low-rank terms, so CG converges in a few
  iterations (2 to 60 on the benchmark files). CG multiplies by `H_T + H_U` as `H_T`'s stored
  matrix (the one the preconditioner factorizes, undamped) plus each untrusted edge's own
  product: the pattern of all of `H`, whose blocks hold every false loop, is built
  (`WholeSystem`) only for a step solved directly.

`"auto"` uses the direct path when every edge is trusted (plain least squares, the first stage
of a graduation, a refinement on accepted edges) and CG otherwise. CG stops at a relative
residual `||b - A x|| <= cg_tol ||b||` (1e-10: the steps equal the direct ones to the precision
the solver's own stopping tests see). If it has not got there in `max_cg_iterations` (200, about
one full factorization's time on sphere2500 with 50% false loops), or the trusted edges leave a
pose unconstrained, the step is solved directly.

A caller may give the trusted set instead (`set_system(trusted=...)`: the online solver keeps one
set, chosen by weight at the start of an update, over all its stages). An edge outside it whose
weight has come back to `trust_weight` or more since is then in `H_U` with a weight that is not
small, and CG slows down. On riSAM's sphere2500 log with 30 % false loops read in GTSAM's
covariance order, where many loops sit near the outlier line, the CG solves without such edges all
took fewer than 10 iterations, and those of 50 or more (111 to 200) had about 36 of their 50
untrusted edges back, 23 at weight 0.5 or more. So a CG solve on a given set that has not
converged in `WIDEN_AFTER_ITERATIONS` starts again, preconditioned by the given set widened by
those edges, and so does every later step of the same nonlinear solve that has such edges (one
more analysis, reused while it holds them). A direct solve instead would cost more on a large
map: the whole system's factorization, false loops' fill-in included, took 0.4 to 0.9 s on the
2500-pose map, the trusted edges' alone 35 ms (docs/decisions.md).

The preconditioner's pattern, its fill-reducing order and its symbolic analysis are computed for
the trusted edges of one linearization, and reused for every later trusted set of the same
nonlinear solve that the pattern contains (each of its edges enters the preconditioner with its
current weight). The pattern holds no edge below `trust_weight`: such an edge is mostly a
switched-off false loop, and its fill-in is what the preconditioner exists to avoid.

Reference:
    J. R. Shewchuk, "An Introduction to the Conjugate Gradient Method Without the Agonizing
    Pain", 1994, section B3 (preconditioned CG).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from egnc.graph.connectivity import connected_components
from egnc.linalg.analysis import OnFirstUse, PermutedFactorization
from egnc.linalg.linear_solvers import (
    Backend,
    Factorization,
    LinearSolver,
    NotPositiveDefiniteError,
    block_order,
    lower_triangle_only,
    orders_by_factorizing,
)
from egnc.linalg.normal_equations import NormalEquationsPattern, block_indices

LinearMethod = Literal["auto", "direct"]
LINEAR_METHODS = ("auto", "direct")
_CACHED_TRUSTED_SETS = 2
"""Trusted-set analyses a nonlinear solve keeps (a stage's trusted set settles after a few steps).
Each holds its last factorization: about 170 MiB on a 100 000-pose grid (BENCHMARKS.md, issue 18)."""
_CACHED_GIVEN_SETS = 4
"""Analyses of given trusted sets kept across solves (`set_system(trusted=...)`)."""
WIDEN_AFTER_ITERATIONS = 30
"""CG iterations on a given trusted set after which it is widened by the edges whose weight came
back (module docstring): about what the widening costs, so that a solve pays at most twice what
the better of the two would have (as in renting until the rent equals the price). On the
2500-pose sphere the analysis and first factorization of the trusted system took 150 ms and a
preconditioned iteration 5 ms; a preconditioner that stands for the system needed fewer than 10
iterations per step on the benchmark files and on riSAM's sphere2500 logs. At 20, stages that
needed 22 to 30 iterations were widened, and riSAM's 30 % log read the GTSAM way did not get faster."""


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """`a . b` without BLAS: NumPy's OpenBLAS threads a long `dot`, and its worker then spins
    while CHOLMOD factorizes, which on 2 cores doubled the factorization time."""
    return float(np.einsum("i,i->", a, b))


@dataclass(frozen=True, eq=False)
class _TrustedSystem:
    """Pattern and solver of one trusted edge set, and where its unknowns sit in the full system.

    Attributes:
        edges: `(E,)` bool, the edges of `pattern` (the trusted edges when it was analysed).
        pattern: normal-equations pattern of those edges, in its own fill-reducing order.
        solver: linear solver analysed for `pattern`.
        unknowns: `(n,)` full-system index of each trusted-system unknown.
    """

    edges: np.ndarray
    pattern: NormalEquationsPattern
    solver: LinearSolver
    unknowns: np.ndarray


def _block_layout(
    edges: np.ndarray, fixed: np.ndarray, backend: Backend, fill_reducing: bool
) -> tuple[np.ndarray | None, tuple[int, np.ndarray] | None]:
    """`(block order, in-block order)` of the normal equations of `edges` `(E, 2)`: the
    fill-reducing block order to build the pattern in, or `(num_blocks, (K, 2) block pairs)` for a
    backend that orders by factorizing (`InBlockOrder`), or neither (`fill_reducing` False: the
    pattern in pose-row order, which the solver orders itself if it is ever used)."""
    if not fill_reducing:
        return None, None
    free_block = np.cumsum(~fixed) - 1
    blocks = (int(np.count_nonzero(~fixed)), free_block[edges[~fixed[edges].any(axis=1)]])
    if orders_by_factorizing(backend):
        return None, blocks
    return block_order(backend, *blocks), None


def analysed_pattern(
    edges: np.ndarray, fixed: np.ndarray, d: int, backend: Backend
) -> tuple[NormalEquationsPattern, LinearSolver]:
    """The normal-equations pattern of `edges` `(E, 2)` in a fill-reducing block order, and its solver (`OnFirstUse`).

    Args:
        edges: `(E, 2)` pose rows of the edges.
        fixed: `(N,)` bool, poses without unknowns.
        d: tangent dimension.
        backend: resolved linear-solver backend.

    A backend whose block order costs a factorization (`orders_by_factorizing`) gets the pattern
    in pose-row order and computes the block order at its first factorization
    (`InBlockOrder`): a robust problem's whole system, false loops included, is often never
    factorized (its steps go through the trusted preconditioner).
    """
    return _built(edges, fixed, d, backend, True, *_block_layout(edges, fixed, backend, True))


def _built(
    edges: np.ndarray,
    fixed: np.ndarray,
    d: int,
    backend: Backend,
    fill_reducing: bool,
    order: np.ndarray | None,
    in_block_order: tuple[int, np.ndarray] | None,
) -> tuple[NormalEquationsPattern, LinearSolver]:
    """The pattern of `edges` in the layout `_block_layout` chose, and its solver."""
    pattern = NormalEquationsPattern.build(edges, fixed, d, lower_only=lower_triangle_only(backend), block_order=order)
    return pattern, OnFirstUse(backend, pattern, ordered=fill_reducing, in_block_order=in_block_order)


class WholeSystem:
    """The normal equations of all of a problem's edges: their unknowns' layout, and their pattern
    and direct solver, built when first asked for.

    A robust problem's steps mostly go through CG with the trusted preconditioner, whose operator
    is the trusted system plus the other edges' own products (`StepSolver`): it needs neither the
    whole pattern (and its scatter map, `(E, 2d, 2d + 1)` slots) nor its solver. They are built for
    a direct step, a CG fallback, or a caller that reads them (e.g. `egnc.nonlinear.marginals`).

    Attributes:
        free_index: `(N,)` unknown-block index of each pose, -1 for a fixed pose, as in `pattern`.
        size: number of unknowns `n`.
    """

    def __init__(self, edges: np.ndarray, fixed: np.ndarray, d: int, backend: Backend, fill_reducing: bool = True):
        """Args:
        edges: `(E, 2)` pose rows of the edges.
        fixed: `(N,)` bool, poses without unknowns.
        d: tangent dimension.
        backend: resolved linear-solver backend.
        fill_reducing: False: pose-row order, which the solver orders itself if it is ever used
            (for a system that CG solves and only a fallback factorizes).

        The block order is computed here (as `analysed_pattern` does), the pattern at first use.
        """
        self._edges, self._fixed, self._d, self._backend = edges, fixed, d, backend
        self._fill_reducing = fill_reducing
        self._order, self._in_block_order = _block_layout(edges, fixed, backend, fill_reducing)
        self.free_index = block_indices(fixed, self._order)
        self.size = d * int(np.count_nonzero(~fixed))
        self._pattern_solver: tuple[NormalEquationsPattern, LinearSolver] | None = None

    @property
    def pattern(self) -> NormalEquationsPattern:
        """The normal-equations pattern of every edge (built at the first call)."""
        return self._pattern_and_solver()[0]

    @property
    def solver(self) -> LinearSolver:
        """The direct solver of `pattern` (analysed at its first factorization, `OnFirstUse`)."""
        return self._pattern_and_solver()[1]

    def _pattern_and_solver(self) -> tuple[NormalEquationsPattern, LinearSolver]:
        if self._pattern_solver is None:
            self._pattern_solver = _built(
                self._edges, self._fixed, self._d, self._backend, self._fill_reducing, self._order, self._in_block_order
            )
        return self._pattern_solver


@dataclass
class LinearStatistics:
    """Counts over one nonlinear solve: direct solves, CG solves, CG iterations, CG fallbacks, and
    the steps whose given trusted set was widened by the edges whose weight came back."""

    direct_solves: int = 0
    cg_solves: int = 0
    cg_iterations: int = 0
    cg_fallbacks: int = 0
    widened_steps: int = 0


class StepSolver:
    """Solves `(H + diag(s)) x = b` for the linearizations of one graph (see the module docstring).

    Use: `set_system(...)` once per linearization, then `solve(shift, rhs)` once per damping value.
    """

    def __init__(
        self,
        edges: np.ndarray,
        fixed: np.ndarray,
        d: int,
        backend: Backend,
        system: WholeSystem,
    ):
        """Args:
        edges: `(E, 2)` pose rows of every edge.
        fixed: `(N,)` bool, poses without unknowns (as in `system`).
        d: tangent dimension.
        backend: resolved linear-solver backend.
        system: the normal equations of every edge (their pattern built at the first direct step).
        """
        self._edges, self._fixed, self._d, self._backend = edges, fixed, d, backend
        self.system = system
        self._edge_unknowns: np.ndarray | None = None
        self._components = 0  # of the whole graph, counted when a trusted set first needs it
        self._trusted_systems: OrderedDict[bytes, _TrustedSystem] = OrderedDict()
        self._given_systems: OrderedDict[bytes, _TrustedSystem | None] = OrderedDict()  # exact sets, kept
        self.analyses = 0  # trusted patterns analysed
        self.statistics = LinearStatistics()
        self._data: np.ndarray | None = None  # H's CSC data in the whole pattern, for direct steps
        self._products: np.ndarray | None = None  # the per-edge products, for CG's operator
        self._trusted: _TrustedSystem | None = None
        self._trusted_data = np.empty(0)
        self._last_direct: Factorization | None = None
        self._widening: np.ndarray | None = None  # a given set and the edges that came back, to widen it by
        self._widened = False  # a step of this nonlinear solve widened its given set

    def start_solve(self) -> None:
        """Begin a nonlinear solve: reset the statistics and forget the trusted patterns, so that
        which superset preconditions a step, and so its rounding, does not depend on what earlier
        solves of the same problem analysed (a solve's steps are then the same bit for bit
        whether or not earlier GNC stages were solved)."""
        self.statistics = LinearStatistics()
        self._trusted_systems.clear()
        self._widened = False

    def set_system(
        self,
        products: np.ndarray,
        weights: np.ndarray,
        method: LinearMethod = "auto",
        trust_weight: float = 1e-4,
        trusted: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Take the undamped `H` of one linearization, as its per-edge products.

        A direct step sums them into the whole pattern; CG's operator uses the trusted system
        (summed into its own pattern for the preconditioner) and the other edges' products.

        Args:
            products: `(E, 2d, 2d + 1)` per-edge products `[J_i | J_j]^T w Omega [J_i | J_j | e]`
                (`edge_products`); held until the next linearization (`discard_factorization`).
            weights: `(E,)` IRLS weights.
            method: `"auto"` (CG preconditioned by the trusted edges when some edge is not
                trusted) or `"direct"`.
            trust_weight: weight from which an edge is trusted (in the preconditioner).
            trusted: `(E,)` bool, the preconditioner's edges, instead of those chosen by
                `trust_weight`: a caller that keeps one set over many linearizations and solves
                pays one analysis for it (its analysis outlives `start_solve`). It is widened by
                the edges whose weight is at least `trust_weight` where CG needs more than
                `WIDEN_AFTER_ITERATIONS` (module docstring).

        Returns:
            The gradient `g = sum J^T w Omega e` `(n,)` and the diagonal of `H` `(n,)`, summed
            in the same order as `NormalEquationsPattern.scatter` sums them (the same bits).
        """
        self._data = self._products = None
        self._trusted = self._widening = None
        if method == "auto" and trusted is not None:
            self._trusted = None if trusted.all() else self._given_system(trusted)
            came_back = ~trusted & (weights >= trust_weight)
            if self._trusted is not None and came_back.any():
                self._widening = trusted | came_back
        elif method == "auto":
            by_weight = weights >= trust_weight
            if not by_weight.all():
                self._trusted = self._trusted_system(by_weight)
        if self._trusted is None:
            pattern = self.system.pattern
            self._data, gradient = pattern.scatter(products)
            return gradient, self._data[pattern.diagonal_slots]
        self._products = products
        if self._widened and self._widening is not None:  # an earlier step of this solve needed it
            self._widen()
        else:
            self._trusted_data = self._trusted.pattern.scatter(products[self._trusted.edges])[0]
        d2 = products.shape[1]
        rows = self._unknowns_of_edges().ravel()
        n = self.system.size
        gradient = np.bincount(rows, products[:, :, d2].ravel(), minlength=n + 1)[:n]
        diagonal = np.bincount(rows, products[:, np.arange(d2), np.arange(d2)].ravel(), minlength=n + 1)[:n]
        return gradient, diagonal

    def _unknowns_of_edges(self) -> np.ndarray:
        """`(E, 2d)` the unknown of each row of an edge's product; `n` (discarded) for a fixed pose."""
        if self._edge_unknowns is None:
            d, blocks = self._d, self.system.free_index[self._edges]  # (E, 2)
            side = np.arange(2 * d) // d
            unknowns = blocks[:, side] * d + np.arange(2 * d) % d
            self._edge_unknowns = np.where(blocks[:, side] >= 0, unknowns, self.system.size)
        return self._edge_unknowns

    def solve(
        self, shift: np.ndarray, rhs: np.ndarray, cg_tol: float = 1e-10, max_cg_iterations: int = 200
    ) -> np.ndarray:
        """Return `x` with `(H + diag(shift)) x = rhs` (`shift`, `rhs`: `(n,)`).

        CG stops at `||rhs - A x|| <= cg_tol ||rhs||`; after `max_cg_iterations` without getting
        there, the step is solved directly (and so are the other solves of this linearization).

        Raises:
            NotPositiveDefiniteError: the direct factorization failed.
        """
        if self._trusted is not None:
            step = self._preconditioned_step(shift, rhs, cg_tol, max_cg_iterations)
            if step is not None:
                return step
            self.statistics.cg_fallbacks += 1
            self._trusted = None  # the rest of this linearization's solves go direct
            assert self._products is not None, "a CG step keeps its linearization's products"
            self._data, self._products = self.system.pattern.scatter(self._products)[0], None
        self.statistics.direct_solves += 1
        assert self._data is not None, "set_system comes first"
        damped = self._data.copy()
        damped[self.system.pattern.diagonal_slots] += shift
        self._last_direct = None  # never two factorizations held at once (SuperLU's are new objects)
        self._last_direct = self.system.solver.factorize(damped)
        return self._last_direct(rhs)

    def last_direct_factorization(self) -> Factorization | None:
        """The factorization of `H + diag(shift)` that the last `solve` computed directly, or None
        where it went through CG or was discarded (`solve_least_squares` discards it before each
        linearization). Valid until this solver's backend factorizes again (it factorizes in place).
        """
        return self._last_direct

    def discard_factorization(self) -> None:
        """Let the last direct factorization and the linearization's `H` go, before the arrays of
        a new linearization are built (a SuperLU factorization is a new object each time; held
        on, either would add to the peak)."""
        self._last_direct = None
        self._data = self._products = None

    def trusted_factorization(self, products: np.ndarray, trusted: np.ndarray) -> Factorization | None:
        """The factorization of `H_T`, the sum of exactly the `trusted` `(E,)` edges' `products`
        (`(E, 2d, 2d + 1)`, `egnc.linalg.normal_equations.edge_products`), undamped, over this system's unknowns.

        It reuses the analysis `set_system(trusted=...)` made for the same set, and is valid until
        a step of this solver factorizes that set again (a backend factorizes in place). None when
        those edges leave a pose unconstrained or `H_T` is not positive definite.
        """
        system = self._given_system(trusted)
        if system is None:
            return None
        try:
            factorization = system.solver.factorize(system.pattern.scatter(products[system.edges])[0])
        except NotPositiveDefiniteError:
            return None
        return PermutedFactorization(factorization, system.unknowns)

    def _preconditioned_step(
        self, shift: np.ndarray, rhs: np.ndarray, tol: float, max_iterations: int
    ) -> np.ndarray | None:
        """CG on the current trusted system; on a given set with edges to widen it by, the first
        `WIDEN_AFTER_ITERATIONS` only, then again from `x = 0` on the widened set with the
        iterations left. None if neither reaches `tol`."""
        assert self._trusted is not None, "a CG step has a trusted system"
        if self._widening is None:
            return self._conjugate_gradients(self._trusted, shift, rhs, tol, max_iterations)
        spent = self.statistics.cg_iterations
        step = self._conjugate_gradients(self._trusted, shift, rhs, tol, min(WIDEN_AFTER_ITERATIONS, max_iterations))
        if step is not None:
            return step
        spent = self.statistics.cg_iterations - spent
        self._widen()
        return self._conjugate_gradients(self._trusted, shift, rhs, tol, max_iterations - spent)

    def _widen(self) -> None:
        """Precondition this linearization, and the later ones of the same nonlinear solve, by the
        given trusted set widened by the edges whose weight came back (`set_system`)."""
        assert self._widening is not None and self._products is not None, "set_system found edges to widen by"
        widened = self._trusted_system(self._widening)
        assert widened is not None, "a superset of a set that preconditions constrains every pose too"
        self._trusted, self._widening, self._widened = widened, None, True
        self._trusted_data = widened.pattern.scatter(self._products[widened.edges])[0]
        self.statistics.widened_steps += 1

    def _conjugate_gradients(
        self, trusted: _TrustedSystem, shift: np.ndarray, rhs: np.ndarray, tol: float, max_iterations: int
    ) -> np.ndarray | None:
        """Preconditioned CG from `x = 0`; None if it does not reach `tol` in `max_iterations`."""
        preconditioner_data = self._trusted_data.copy()
        preconditioner_data[trusted.pattern.diagonal_slots] += shift[trusted.unknowns]
        try:
            trusted_solve = trusted.solver.factorize(preconditioner_data)
        except NotPositiveDefiniteError:
            return None
        self.statistics.cg_solves += 1

        def precondition(v: np.ndarray) -> np.ndarray:
            out = np.empty_like(v)
            out[trusted.unknowns] = trusted_solve(v[trusted.unknowns])
            return out

        multiply = self._operator(trusted, shift)
        x = np.zeros_like(rhs)
        residual = rhs.copy()
        goal = tol * np.sqrt(dot(rhs, rhs))
        z = precondition(residual)
        direction = z.copy()
        rz = dot(residual, z)
        for _ in range(max_iterations):
            if not np.sqrt(dot(residual, residual)) > goal:  # also stops on a non-finite residual
                break
            self.statistics.cg_iterations += 1
            product = multiply(direction)
            curvature = dot(direction, product)
            if not curvature > 0:
                return None
            alpha = rz / curvature
            x += alpha * direction
            residual -= alpha * product
            z = precondition(residual)
            rz, previous = dot(residual, z), rz
            direction = z + (rz / previous) * direction
        converged = np.sqrt(dot(residual, residual)) <= goal
        return x if converged and np.all(np.isfinite(x)) else None

    def _operator(self, trusted: _TrustedSystem, shift: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """`v -> (H + diag(shift)) v` as `H_T v + H_U v`: the trusted system's stored CSC data
        (lower triangle or whole) and the other edges' products (`set_system`)."""
        pattern = trusted.pattern
        data = self._trusted_data
        matrix = sp.csc_matrix((data, pattern.indices, pattern.indptr), shape=(pattern.size, pattern.size))
        transposed = matrix.T
        diagonal = data[pattern.diagonal_slots]
        assert self._products is not None, "set_system comes first"
        others = np.flatnonzero(~trusted.edges)
        d2 = self._products.shape[1]
        other_products = self._products[others, :, :d2]  # (K, 2d, 2d)
        rows = self._unknowns_of_edges()[others]  # (K, 2d)
        n = self.system.size
        unknowns = trusted.unknowns

        def multiply(v: np.ndarray) -> np.ndarray:
            ordered = v[unknowns]
            product = matrix @ ordered
            if pattern.lower_only:
                product += transposed @ ordered - diagonal * ordered
            out = shift * v
            out[unknowns] += product
            if len(others):
                ends = np.append(v, 0.0)[rows]  # (K, 2d); a fixed pose's rows read 0
                terms = np.einsum("kij,kj->ki", other_products, ends)
                out += np.bincount(rows.ravel(), terms.ravel(), minlength=n + 1)[:n]
            return out

        return multiply

    def _trusted_system(self, trusted: np.ndarray) -> _TrustedSystem | None:
        """A cached analysis whose edges contain the `trusted` `(E,)` edges, else one analysed for
        them; None when they leave a pose unconstrained (they cannot precondition then).

        The preconditioner is then every edge of the pattern with its current weight: a split
        `H = H_P + H_rest` for any edge set `P` that keeps `H_P` positive definite leaves CG exact.
        """
        for key, system in reversed(self._trusted_systems.items()):
            if not np.any(trusted & ~system.edges):
                self._trusted_systems.move_to_end(key)
                return system
        analysed = self._analysed_system(trusted)
        if analysed is not None:
            self._trusted_systems[np.packbits(trusted).tobytes()] = analysed
            if len(self._trusted_systems) > _CACHED_TRUSTED_SETS:
                self._trusted_systems.popitem(last=False)
        return analysed

    def _given_system(self, trusted: np.ndarray) -> _TrustedSystem | None:
        """The analysis of exactly the `trusted` `(E,)` edges, cached across solves; None as above."""
        key = np.packbits(trusted).tobytes()
        if key not in self._given_systems:
            self._given_systems[key] = self._analysed_system(trusted)
            if len(self._given_systems) > _CACHED_GIVEN_SETS:
                self._given_systems.popitem(last=False)
        self._given_systems.move_to_end(key)
        return self._given_systems[key]

    def _analysed_system(self, selected: np.ndarray) -> _TrustedSystem | None:
        """Pattern and analysis of the `selected` `(E,)` edges; None when they leave a pose unconstrained."""
        edges = self._edges[selected]
        if not self._components:
            self._components = connected_components(len(self._fixed), self._edges)[0]
        if connected_components(len(self._fixed), edges)[0] != self._components:
            return None
        self.analyses += 1
        pattern, solver = analysed_pattern(edges, self._fixed, self._d, self._backend)
        # Unknown k of pose p sits at free_index[p] * d + k in either system.
        free = np.flatnonzero(~self._fixed)
        component = np.arange(self._d)
        unknowns = np.empty(pattern.size, dtype=np.int64)
        unknowns[(pattern.free_index[free][:, None] * self._d + component).ravel()] = (
            self.system.free_index[free][:, None] * self._d + component
        ).ravel()
        return _TrustedSystem(selected.copy(), pattern, solver, unknowns)
