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
  iterations (2 to 60 on the benchmark files).

`"auto"` uses the direct path when every edge is trusted (plain least squares, the first stage
of a graduation, a refinement on accepted edges) and CG otherwise. CG stops at a relative
residual `||b - A x|| <= cg_tol ||b||` (1e-10: the steps equal the direct ones to the precision
the solver's own stopping tests see). If it has not got there in `max_cg_iterations` (200, about
one full factorization's time on sphere2500 with 50% false loops), or the trusted edges leave a
pose unconstrained, the step is solved directly. The trusted pattern, its fill-reducing order
and its symbolic analysis are computed once per distinct trusted set.

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

from egnc.connectivity import connected_components
from egnc.linear_solvers import (
    Backend,
    LinearSolver,
    NotPositiveDefiniteError,
    block_order,
    lower_triangle_only,
    make_linear_solver,
)
from egnc.normal_equations import NormalEquationsPattern

LinearMethod = Literal["auto", "direct"]
LINEAR_METHODS = ("auto", "direct")
_CACHED_TRUSTED_SETS = 4  # symbolic analyses kept; a stage's trusted set settles after a few steps


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """`a . b` without BLAS: NumPy's OpenBLAS threads a long `dot`, and its worker then spins
    while CHOLMOD factorizes, which on 2 cores doubled the factorization time."""
    return float(np.einsum("i,i->", a, b))


@dataclass(frozen=True, eq=False)
class _TrustedSystem:
    """Pattern and solver of one trusted edge set, and where its unknowns sit in the full system.

    Attributes:
        pattern: normal-equations pattern of the trusted edges, in its own fill-reducing order.
        solver: linear solver analysed for `pattern`.
        unknowns: `(n,)` full-system index of each trusted-system unknown.
    """

    pattern: NormalEquationsPattern
    solver: LinearSolver
    unknowns: np.ndarray


def analysed_pattern(
    edges: np.ndarray, fixed: np.ndarray, d: int, backend: Backend
) -> tuple[NormalEquationsPattern, LinearSolver]:
    """The normal-equations pattern of `edges` `(E, 2)` in a fill-reducing block order, and a solver analysed for it.

    Args:
        edges: `(E, 2)` pose rows of the edges.
        fixed: `(N,)` bool, poses without unknowns.
        d: tangent dimension.
        backend: resolved linear-solver backend.
    """
    free_block = np.cumsum(~fixed) - 1
    joined = edges[~fixed[edges].any(axis=1)]
    order = block_order(backend, int(np.count_nonzero(~fixed)), free_block[joined])
    pattern = NormalEquationsPattern.build(edges, fixed, d, lower_only=lower_triangle_only(backend), block_order=order)
    return pattern, make_linear_solver(backend, pattern.indptr, pattern.indices, ordered=True)


@dataclass
class LinearStatistics:
    """Counts over one nonlinear solve: direct solves, CG solves, CG iterations, CG fallbacks."""

    direct_solves: int = 0
    cg_solves: int = 0
    cg_iterations: int = 0
    cg_fallbacks: int = 0


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
        pattern: NormalEquationsPattern,
        direct_solver: LinearSolver,
    ):
        """Args:
        edges: `(E, 2)` pose rows of every edge.
        fixed: `(N,)` bool, poses without unknowns (as in `pattern`).
        d: tangent dimension.
        backend: resolved linear-solver backend.
        pattern: the full normal-equations pattern.
        direct_solver: the solver analysed for `pattern`.
        """
        self._edges, self._fixed, self._d, self._backend = edges, fixed, d, backend
        self.pattern, self.direct_solver = pattern, direct_solver
        self._components = 0  # of the whole graph, counted when a trusted set first needs it
        self._trusted_systems: OrderedDict[bytes, _TrustedSystem | None] = OrderedDict()
        self.statistics = LinearStatistics()
        self._data = np.empty(0)
        self._trusted: _TrustedSystem | None = None
        self._trusted_data = np.empty(0)

    def set_system(
        self,
        data: np.ndarray,
        products: np.ndarray,
        weights: np.ndarray,
        method: LinearMethod = "auto",
        trust_weight: float = 1e-4,
    ) -> None:
        """Take the undamped `H` of one linearization.

        Args:
            data: `(nnz,)` CSC data of `H` in `pattern`.
            products: `(E, 2d, 2d + 1)` per-edge products `H` was summed from (`edge_products`).
            weights: `(E,)` IRLS weights.
            method: `"auto"` (CG preconditioned by the trusted edges when some edge is below
                `trust_weight`) or `"direct"`.
            trust_weight: weight from which an edge is in the preconditioner.
        """
        self._data = data
        trusted = weights >= trust_weight
        self._trusted = None
        if method == "auto" and not trusted.all():
            self._trusted = self._trusted_system(trusted)
            if self._trusted is not None:
                self._trusted_data = self._trusted.pattern.scatter(products[trusted])[0]

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
            step = self._conjugate_gradients(self._trusted, shift, rhs, cg_tol, max_cg_iterations)
            if step is not None:
                return step
            self.statistics.cg_fallbacks += 1
            self._trusted = None  # the rest of this linearization's solves go direct
        self.statistics.direct_solves += 1
        damped = self._data.copy()
        damped[self.pattern.diagonal_slots] += shift
        return self.direct_solver.solve(damped, rhs)

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

        multiply = self._operator(shift)
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

    def _operator(self, shift: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """`v -> (H + diag(shift)) v` from `H`'s stored CSC data (lower triangle or whole)."""
        pattern = self.pattern
        matrix = sp.csc_matrix((self._data, pattern.indices, pattern.indptr), shape=(pattern.size, pattern.size))
        transposed = matrix.T
        diagonal = self._data[pattern.diagonal_slots]

        def multiply(v: np.ndarray) -> np.ndarray:
            out = matrix @ v + shift * v
            if pattern.lower_only:
                out += transposed @ v - diagonal * v
            return out

        return multiply

    def _trusted_system(self, trusted: np.ndarray) -> _TrustedSystem | None:
        """The cached pattern and analysis of the `trusted` `(E,)` edge set, built on first use; None
        when the trusted edges leave a pose unconstrained (they cannot precondition then)."""
        key = np.packbits(trusted).tobytes()
        if key in self._trusted_systems:
            self._trusted_systems.move_to_end(key)
            return self._trusted_systems[key]
        edges = self._edges[trusted]
        if not self._components:
            self._components = connected_components(len(self._fixed), self._edges)[0]
        system = None
        if connected_components(len(self._fixed), edges)[0] == self._components:
            pattern, solver = analysed_pattern(edges, self._fixed, self._d, self._backend)
            # Unknown k of pose p sits at free_index[p] * d + k in either system.
            free = np.flatnonzero(~self._fixed)
            component = np.arange(self._d)
            unknowns = np.empty(pattern.size, dtype=np.int64)
            unknowns[(pattern.free_index[free][:, None] * self._d + component).ravel()] = (
                self.pattern.free_index[free][:, None] * self._d + component
            ).ravel()
            system = _TrustedSystem(pattern, solver, unknowns)
        self._trusted_systems[key] = system
        if len(self._trusted_systems) > _CACHED_TRUSTED_SETS:
            self._trusted_systems.popitem(last=False)
        return system
