"""Sparse Gauss-Newton and Levenberg-Marquardt on pose graphs, with IRLS edge weights.

Each iteration linearizes every edge (`egnc.nonlinear.factors`), assembles the normal equations with a
fixed pattern (`egnc.linalg.normal_equations`), solves them with a sparse Cholesky (`egnc.linalg.linear_solvers`)
and retracts the step onto the poses (`X <- X Exp(delta)`). Poses marked fixed, or pose 0 when
none is, are held constant: this removes the gauge freedom.

Robust losses enter by iteratively reweighted least squares: at the current residual norms `r`
an `EdgeLoss` gives each edge its cost `rho(r)` and weight `w = rho'(r) / r`, and the step solves
`(sum w J^T Omega J + lambda D) delta = -sum w J^T Omega e`.

Levenberg-Marquardt follows Nielsen's damping update (as in Ceres and Madsen et al.): with the
gain ratio `q = (F - F_new) / (L(0) - L(delta))`, where `L(0) - L(delta) = 0.5 delta^T (lambda D
delta - g)` is the decrease predicted by the damped quadratic model, a step is accepted when
`q > 1e-3`; then `lambda *= max(1/3, 1 - (2q - 1)^3)`, otherwise `lambda *= nu, nu *= 2`.
`D = clip(diag(H), 1e-6, 1e32)` (Marquardt's scaling, Ceres's clip values).

Termination (checked after each accepted step; `status` codes as in `STATUS_MESSAGES`):
    1. converged: `(F_prev - F) <= rel_cost_tol * F_prev`;
    2. converged: `max |g| <= gradient_tol` (at the current poses);
    3. converged: `||delta|| <= step_tol` (tangent-space step, metres and radians mixed);
    0. `max_iterations` accepted steps were taken;
    4. no decrease possible (LM: `lambda > max_damping`; GN: the full step increased the cost);
    5. numerical failure: the cost or the gradient is not finite (nothing non-finite reaches the
       linear solver, so BLAS never sees it). A trial step with a non-finite cost is rejected.

References:
    K. Madsen, H. B. Nielsen, O. Tingleff, "Methods for non-linear least squares problems",
    2004, section 3.2 (damping update, gain ratio).
    S. Agarwal, K. Mierle et al., Ceres Solver, "Levenberg-Marquardt" trust-region strategy.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_choice, check_float, check_int
from egnc.linalg.linear_solvers import LinearSolver, NotPositiveDefiniteError, resolve_name
from egnc.linalg.normal_equations import NormalEquationsPattern, edge_products
from egnc.linalg.step_solver import LINEAR_METHODS, LinearMethod, LinearStatistics, StepSolver, WholeSystem, dot
from egnc.nonlinear.factors import BetweenFactors, EdgeErrors, group_of

STATUS_MESSAGES = {
    0: "maximum number of iterations reached",
    1: "converged: relative cost decrease below rel_cost_tol",
    2: "converged: gradient below gradient_tol",
    3: "converged: step below step_tol",
    4: "stopped: no step decreases the cost",
    5: "numerical failure: the cost or the gradient is not finite",
    6: "nothing to optimize: every pose is fixed",
}
NUMERICAL_FAILURE = 5
"""Status of a solve stopped by non-finite numbers (`egnc.graph.health` refuses most such inputs earlier)."""
NOTHING_TO_OPTIMIZE = 6
"""Status of `egnc.solve` on a graph whose poses are all fixed: it is returned unchanged."""
CONVERGED = (1, 2, 3)

IterationCallback = Callable[[int, float], None]
"""Receives `(iterations, cost)` after each accepted step of a solve (progress display)."""
DAMPING_MIN_FACTOR = 0.1  # largest shrink of lambda per accepted step, as GTSAM's factor 10


class EdgeLoss(Protocol):
    """Per-edge cost and IRLS weight as functions of the whitened residual norms `r` `(E,)`."""

    def cost(self, r: np.ndarray) -> np.ndarray:
        """Per-edge cost `rho(r)` `(E,)`; for least squares `0.5 r^2`."""
        ...

    def weight(self, r: np.ndarray) -> np.ndarray:
        """Per-edge IRLS weight `rho'(r) / r` `(E,)`."""
        ...


class QuadraticLoss:
    """Plain least squares: `rho(r) = 0.5 r^2`, weight 1."""

    def cost(self, r: np.ndarray) -> np.ndarray:
        """`0.5 r^2` per edge, `(E,)`."""
        return 0.5 * r * r

    def weight(self, r: np.ndarray) -> np.ndarray:
        """Weight 1 for every edge, `(E,)`."""
        return np.ones_like(r)


@dataclass(frozen=True)
class SolverOptions:
    """Options of the nonlinear least-squares solve.

    Attributes:
        method: `"lm"` (Levenberg-Marquardt) or `"gn"` (Gauss-Newton, full steps).
        max_iterations: maximum number of accepted steps.
        rel_cost_tol: stop when `(F_prev - F) / F_prev <= rel_cost_tol` after an accepted step.
        gradient_tol: stop when the largest gradient component `max |g| <= gradient_tol`.
        step_tol: stop when the step's Euclidean norm `||delta|| <= step_tol`.
        initial_damping: LM's starting `lambda` (Ceres: 1 / initial trust-region radius 1e4), in
            `(0, max_damping]`.
        max_damping: LM gives up (status 4) when `lambda` exceeds this; positive and finite.
        linear_method: how each step's linear system is solved (`egnc.linalg.step_solver`): `"auto"`
            (conjugate gradients preconditioned by the Cholesky factorization of the edges
            whose weight is at least `trust_weight`, when some edge is below it; else direct)
            or `"direct"` (one factorization of every edge).
        trust_weight: the IRLS weight from which an edge is in the preconditioner, in `(0, 1]`.

    The tolerances are finite and `>= 0`, `max_iterations` an int `>= 0`. Every field is checked
    at construction; a wrong type or value raises `OptionError` naming the field.
    """

    method: Literal["lm", "gn"] = "lm"
    max_iterations: int = 100
    rel_cost_tol: float = 1e-10
    gradient_tol: float = 1e-10
    step_tol: float = 1e-12
    initial_damping: float = 1e-8
    max_damping: float = 1e32
    linear_method: LinearMethod = "auto"
    trust_weight: float = 1e-4

    def __post_init__(self) -> None:
        """Check every field's type and range (`egnc.graph.checks`), storing plain Python values."""
        max_damping = check_float("SolverOptions.max_damping", self.max_damping, 0.0, open_low=True)
        checked: dict[str, object] = {
            "max_damping": max_damping,
            "method": check_choice("SolverOptions.method", self.method, ("lm", "gn")),
            "max_iterations": check_int("SolverOptions.max_iterations", self.max_iterations, 0),
            "linear_method": check_choice("SolverOptions.linear_method", self.linear_method, LINEAR_METHODS),
            "trust_weight": check_float("SolverOptions.trust_weight", self.trust_weight, 0.0, 1.0, open_low=True),
        }
        for name in ("rel_cost_tol", "gradient_tol", "step_tol"):
            checked[name] = check_float(f"SolverOptions.{name}", getattr(self, name), 0.0)
        # LM multiplies the damping, so it must start positive; above max_damping no step is ever tried.
        checked["initial_damping"] = check_float(
            "SolverOptions.initial_damping", self.initial_damping, 0.0, max_damping, open_low=True
        )
        for name, value in checked.items():
            object.__setattr__(self, name, value)


@dataclass(frozen=True, eq=False)
class SolverResult:
    """Outcome of one nonlinear least-squares solve.

    Attributes:
        poses: `(N, n, n)` optimized pose matrices.
        residual_norms: `(E,)` whitened residual norms `r` at the solution (unweighted).
        cost: final total cost `sum rho(r)`.
        cost_history: `(K + 1,)` cost before the first and after each accepted step.
        iterations: accepted steps K.
        linear_solves: factorizations performed (rejected LM steps included).
        status: termination code, see `STATUS_MESSAGES`.
        message: human-readable termination reason.
        time_s: wall time of the solve in seconds.
        timings: seconds spent in `"linearize"` (Jacobians, and the initial residuals),
            `"assemble"`, `"factorize"` (factorizations and the linear solves, CG included)
            and `"update"` (retraction, residuals and cost at the trial poses; an accepted
            step's residuals are reused).
        linear: direct solves, CG solves and iterations, CG fallbacks (`egnc.linalg.step_solver`).
        step_damping: the LM damping `lambda` (relative to `H`'s diagonal) of the last accepted
            step; 0 for Gauss-Newton and when no step was accepted.
        next_damping: the LM damping the solve would try next: as `initial_damping`, a solve
            from `poses` continues this one as if it had not stopped; 0 for Gauss-Newton.
        errors: the residuals at `poses` with what a linearization there reuses
            (`BetweenFactors.evaluate`), when the solve was asked to keep them (`keep_errors`),
            else None.
    """

    poses: np.ndarray
    residual_norms: np.ndarray
    cost: float
    cost_history: np.ndarray
    iterations: int
    linear_solves: int
    status: int
    message: str
    time_s: float
    timings: dict[str, float] = field(default_factory=dict)
    linear: LinearStatistics = field(default_factory=LinearStatistics)
    step_damping: float = 0.0
    next_damping: float = 0.0
    errors: EdgeErrors | None = None

    @property
    def converged(self) -> bool:
        """Whether a convergence criterion (status 1, 2 or 3) stopped the solve."""
        return self.status in CONVERGED


@dataclass(frozen=True, eq=False)
class Problem:
    """A graph's factors with its normal-equations pattern and linear solver, built once.

    Reusing one `Problem` across solves (e.g. GNC stages) reuses the symbolic factorization.

    Attributes:
        factors: the factors of every edge.
        fixed: `(N,)` bool, the poses without unknowns (pose 0 when the graph fixed none).
        system: the normal equations of every edge (`egnc.linalg.step_solver.WholeSystem`): the layout
            of the unknowns, and the pattern and direct solver, built at first use.
        step_solver: the step solver over `system` (`egnc.linalg.step_solver`).
    """

    factors: BetweenFactors
    fixed: np.ndarray
    system: WholeSystem
    step_solver: StepSolver

    @property
    def pattern(self) -> NormalEquationsPattern:
        """The normal-equations pattern of the free poses (built at the first call)."""
        return self.system.pattern

    @property
    def linear_solver(self) -> LinearSolver:
        """The direct solver of `pattern`."""
        return self.system.solver

    @classmethod
    def from_graph(
        cls,
        graph: PoseGraph,
        linear_solver: str = "auto",
        factors: BetweenFactors | None = None,
        fill_reducing: bool = True,
    ) -> Problem:
        """Prepare `graph` for solving (`from_factors`); `factors`: the graph's factors if already
        built (`BetweenFactors.subset` of a larger graph's)."""
        return cls.from_factors(factors or BetweenFactors.from_graph(graph), graph.fixed, linear_solver, fill_reducing)

    @classmethod
    def from_factors(
        cls, factors: BetweenFactors, fixed: np.ndarray, linear_solver: str = "auto", fill_reducing: bool = True
    ) -> Problem:
        """Prepare the poses joined by `factors` for solving; the gauge is fixed on pose 0 unless
        some poses are fixed.

        `fixed`: `(N,)` bool, the poses held. `fill_reducing`: False leaves the whole system in
        pose-row order, without computing a fill-reducing order, for a problem solved once by CG
        with a given trusted set (the online solver's): its direct solver then orders the system
        itself if a CG step falls back to it.
        """
        backend = resolve_name(linear_solver)
        fixed = np.array(fixed, dtype=bool)
        if not fixed.any():
            fixed[0] = True
        d = factors.information.shape[-1]
        # Unknown blocks in a fill-reducing order of the free poses, computed once.
        system = WholeSystem(factors.edges, fixed, d, backend, fill_reducing)
        return cls(factors, fixed, system, StepSolver(factors.edges, fixed, d, backend, system))

    @property
    def num_poses(self) -> int:
        """Number of poses N (free and fixed)."""
        return len(self.fixed)

    @property
    def tangent_dim(self) -> int:
        """Tangent dimension d: 3 in 2D, 6 in 3D."""
        return int(self.factors.information.shape[-1])

    def retract(self, T: np.ndarray, step: np.ndarray) -> np.ndarray:
        """Return poses `T` `(N, n, n)` moved by the stacked free-pose step `(n_unknowns,)`."""
        group = group_of(self.factors.dim)
        free_index = self.system.free_index
        free = free_index >= 0
        moved = T.copy()
        moved[free] = group.rplus(T[free], step.reshape(-1, self.tangent_dim)[free_index[free]])
        return moved


class _Clock:
    """Accumulates wall time per named phase."""

    def __init__(self) -> None:
        self.totals = {"linearize": 0.0, "assemble": 0.0, "factorize": 0.0, "update": 0.0}
        self._phase = ""
        self._start = 0.0

    def __call__(self, phase: str) -> _Clock:
        self._phase = phase
        return self

    def __enter__(self) -> None:
        self._start = time.perf_counter()

    def __exit__(self, *exc: object) -> None:
        self.totals[self._phase] += time.perf_counter() - self._start


def solve_least_squares(
    problem: Problem,
    initial_poses: np.ndarray,
    loss: EdgeLoss | None = None,
    options: SolverOptions = SolverOptions(),
    on_iteration: IterationCallback | None = None,
    trusted: np.ndarray | None = None,
    errors: EdgeErrors | None = None,
    keep_errors: bool = False,
) -> SolverResult:
    """Minimize `sum rho(r_e)` over the free poses by GN or LM with IRLS weights.

    Args:
        problem: factors, pattern and linear solver (see `Problem.from_graph`).
        initial_poses: `(N, n, n)` starting pose matrices.
        loss: per-edge cost and weight; `None` means plain least squares.
        options: solver options.
        on_iteration: called with `(iterations, cost)` after each accepted step.
        trusted: `(E,)` bool, the edges of the CG preconditioner for every linearization of this
            solve (`egnc.linalg.step_solver`); default: those whose weight is at least
            `options.trust_weight` at each linearization.
        errors: `problem.factors.evaluate(initial_poses)` if already computed (at these very
            poses, e.g. the `errors` of a solve that ended there), to reuse.
        keep_errors: return the residuals at the solution in `SolverResult.errors`, for a next
            solve from there (held as long as the result is: `E` relative poses).

    Returns:
        The `SolverResult`; it is returned (not raised) when the iteration limit is hit.
    """
    loss = loss or QuadraticLoss()
    started = time.perf_counter()
    clock = _Clock()
    factors = problem.factors
    T = np.array(initial_poses, dtype=np.float64)

    def evaluate(poses: np.ndarray, known: EdgeErrors | None = None) -> tuple[EdgeErrors, np.ndarray, float]:
        errors = factors.evaluate(poses) if known is None else known
        r = factors.whitened_norms(errors.residuals)
        return errors, r, float(np.sum(loss.cost(r)))

    steps = problem.step_solver
    steps.start_solve()
    with clock("linearize"):
        errors, r, cost = evaluate(T, errors)
    history = [cost]
    damping, growth = options.initial_damping, 2.0
    iterations = linear_solves = 0
    step_damping = 0.0
    status = 0 if np.isfinite(cost) else NUMERICAL_FAILURE
    gradient = diagonal = None  # normal equations at T, built when a step from T is needed
    while status != NUMERICAL_FAILURE and iterations < options.max_iterations:
        if gradient is None or diagonal is None:  # always set and cleared together
            steps.discard_factorization()
            with clock("linearize"):
                linearization = factors.linearize(T, errors)  # reuses the residuals at T
            with clock("assemble"):
                weights = loss.weight(r)
                products = edge_products(linearization, factors.information, weights)
                gradient, diagonal = steps.set_system(
                    products, weights, options.linear_method, options.trust_weight, trusted
                )
                # Freed before the next linearization builds its own (each about 100 MB on a
                # 50 000-pose 3D grid, where they set the robust solve's peak memory); a CG step's
                # products stay with the step solver until `discard_factorization` above.
                del linearization, products
            # With the information matrices checked at input, a non-finite Jacobian, residual or
            # weight shows in g or on H's diagonal (a column's weighted square).
            if not np.all(np.isfinite(diagonal)) or not np.all(np.isfinite(gradient)):
                status = NUMERICAL_FAILURE
                break
            diagonal = np.clip(diagonal, 1e-6, 1e32)
        if np.max(np.abs(gradient), initial=0.0) <= options.gradient_tol:
            status = 2
            break
        use_damping = options.method == "lm"
        with clock("factorize"):
            shift = damping * diagonal if use_damping else np.zeros_like(diagonal)
            try:
                step = -steps.solve(shift, gradient)
                solved = bool(np.all(np.isfinite(step)))
            except NotPositiveDefiniteError:
                if not use_damping:
                    raise
                solved = False
            linear_solves += 1
        if not solved:
            if not use_damping:
                raise SolverError("Gauss-Newton step is not finite: the normal equations are singular")
            damping, growth = damping * growth, growth * 2
            if damping > options.max_damping:
                status = 4
                break
            continue
        if np.sqrt(dot(step, step)) <= options.step_tol:
            status = 3
            break
        with clock("update"):
            T_new = problem.retract(T, step)
            errors_new, r_new, cost_new = evaluate(T_new)
        predicted = 0.5 * dot(step, (damping * diagonal * step if use_damping else 0.0) - gradient)
        gain = (cost - cost_new) / predicted if predicted > 0 and np.isfinite(cost_new) else -1.0
        if use_damping and gain <= 1e-3:
            damping, growth = damping * growth, growth * 2
            if damping > options.max_damping:
                status = 4
                break
            continue
        if not use_damping and not cost_new < cost:  # also a non-finite trial cost
            status = 4
            break
        if use_damping:
            step_damping = damping
            damping *= max(DAMPING_MIN_FACTOR, 1.0 - (2.0 * gain - 1.0) ** 3)
            growth = 2.0
        previous = cost
        T, errors, r, cost = T_new, errors_new, r_new, cost_new
        gradient = diagonal = None
        history.append(cost)
        iterations += 1
        if on_iteration is not None:
            on_iteration(iterations, cost)
        if previous - cost <= options.rel_cost_tol * previous:
            status = 1
            break
    return SolverResult(
        poses=T,
        residual_norms=r,
        cost=cost,
        cost_history=np.array(history),
        iterations=iterations,
        linear_solves=linear_solves,
        status=status,
        message=STATUS_MESSAGES[status],
        time_s=time.perf_counter() - started,
        timings=dict(clock.totals),
        linear=steps.statistics,
        step_damping=step_damping,
        next_damping=damping if options.method == "lm" else 0.0,
        errors=errors if keep_errors else None,
    )
