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
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Literal, Protocol

import numpy as np

from egnc.errors import SolverError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_choice, check_float, check_int
from egnc.linalg.linear_solvers import LinearSolver, NotPositiveDefiniteError, resolve_name
from egnc.linalg.normal_equations import NormalEquationsPattern, edge_products
from egnc.linalg.step_solver import LINEAR_METHODS, LinearMethod, LinearStatistics, StepSolver, WholeSystem, dot
from egnc.nonlinear.factors import BetweenFactors, EdgeErrors, group_of
from egnc.nonlinear.prior_factors import PriorFactors
from egnc.nonlinear.prior_gauge import gauge_fixed, with_prior_anchor, with_prior_products

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
_GAUSS_NEWTON_SINGULAR = (
    "Gauss-Newton cannot solve its normal equations at iteration {}{}: they are singular (or, by"
    " rounding, indefinite), so some pose or direction is not pinned down by the edges (a part of"
    " the graph joined to the rest by no edge and holding no fixed pose, or only by edges with"
    " tiny information). Use Levenberg-Marquardt instead (SolverOptions(method='lm'), egnc-solve"
    " --solver lm), whose damping keeps the system solvable, or fix a pose in each such part."
)
_GAUSS_NEWTON_NO_DECREASE = (
    " (Gauss-Newton's full step increased the cost, as it does on ill-conditioned normal equations,"
    " e.g. a pose held only by an edge with tiny information: Levenberg-Marquardt,"
    " SolverOptions(method='lm') or egnc-solve --solver lm, damps the step)"
)


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
        cost: final total cost `sum rho(r)` (plus `0.5 r^2` of each prior).
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
    prior_norms: np.ndarray | None = None
    """`(K,)` whitened residual norms of the priors at the solution, None without priors."""

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
        priors: the graph's priors, or None. They enter the linear layer as edges from a fixed
            virtual pose (row N, `egnc.nonlinear.prior_gauge`).
        weighted_priors: whether a solve's `EdgeLoss` covers the priors too: it then sees the
            `(E + K,)` norms of the edges followed by the priors (the robust layer's factor
            arrays, where priors may be rejected); False holds the priors quadratic.
    """

    factors: BetweenFactors
    fixed: np.ndarray
    system: WholeSystem
    step_solver: StepSolver
    priors: PriorFactors | None = None
    weighted_priors: bool = False

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
        weighted_priors: bool = False,
    ) -> Problem:
        """Prepare `graph` for solving (`from_factors`); `factors`: the graph's factors if already
        built (`BetweenFactors.subset` of a larger graph's); `weighted_priors`: the loss covers
        the priors (`Problem.weighted_priors`)."""
        priors = PriorFactors.from_priors(graph.priors) if graph.num_priors else None
        fixed = gauge_fixed(graph) if graph.num_priors else graph.fixed
        factors = factors or BetweenFactors.from_graph(graph)
        problem = cls.from_factors(factors, fixed, linear_solver, fill_reducing, priors)
        return replace(problem, weighted_priors=True) if weighted_priors and priors is not None else problem

    @classmethod
    def from_factors(
        cls,
        factors: BetweenFactors,
        fixed: np.ndarray,
        linear_solver: str = "auto",
        fill_reducing: bool = True,
        priors: PriorFactors | None = None,
    ) -> Problem:
        """Prepare the poses joined by `factors` for solving; the gauge is fixed on pose 0 unless
        some poses are fixed.

        `fixed`: `(N,)` bool, the poses held. `fill_reducing`: False leaves the whole system in
        pose-row order, without computing a fill-reducing order, for a problem solved once by CG
        with a given trusted set (the online solver's): its direct solver then orders the system
        itself if a CG step falls back to it. `priors`: held quadratic; with them, no pose is fixed
        here (`egnc.nonlinear.prior_gauge.gauge_fixed` decides).
        """
        backend = resolve_name(linear_solver)
        fixed = np.array(fixed, dtype=bool)
        if not fixed.any() and priors is None:
            fixed[0] = True
        d = factors.information.shape[-1]
        edges, all_fixed = (factors.edges, fixed) if priors is None else with_prior_anchor(factors.edges, fixed, priors)
        # Unknown blocks in a fill-reducing order of the free poses, computed once.
        system = WholeSystem(edges, all_fixed, d, backend, fill_reducing)
        return cls(factors, fixed, system, StepSolver(edges, all_fixed, d, backend, system), priors)

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
        free, blocks = self._free_blocks
        moved = T.copy()
        moved[free] = group_of(self.factors.dim).rplus(T[free], step.reshape(-1, self.tangent_dim)[blocks])
        return moved

    @cached_property
    def _free_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """`(N,)` bool, the free poses, and `(num_free,)` the unknown block of each, in pose order."""
        free = self.system.free_index[: self.num_poses] >= 0  # past N: the priors' virtual pose
        return free, self.system.free_index[: self.num_poses][free]


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

    Raises:
        SolverError: Gauss-Newton met normal equations it cannot solve (singular: a pose or a
            direction the edges do not pin down); the message says to use Levenberg-Marquardt.
    """
    run = _Run(problem, loss or QuadraticLoss(), options, trusted)
    run.start(np.array(initial_poses, dtype=np.float64), errors)
    while run.status != NUMERICAL_FAILURE and run.iterations < options.max_iterations:
        if not run.iterate(on_iteration):
            break
    return run.result(keep_errors)


@dataclass(frozen=True, eq=False)
class _Point:
    """Poses with their residuals, whitened residual norms and cost."""

    T: np.ndarray
    errors: EdgeErrors
    r: np.ndarray
    cost: float
    prior_r: np.ndarray | None = None


class _Run:
    """The state of one `solve_least_squares`: the current point, the LM damping, the counters.

    `iterate` takes one step from the current point (trying damping values until one is
    accepted, for LM) and says whether to go on; `status` then holds the termination code.
    """

    def __init__(self, problem: Problem, loss: EdgeLoss, options: SolverOptions, trusted: np.ndarray | None):
        self.started = time.perf_counter()
        self.problem, self.loss, self.options, self.trusted = problem, loss, options, trusted
        self.use_damping = options.method == "lm"
        self.clock = _Clock()
        self.steps = problem.step_solver
        self.point: _Point
        self.history: list[float] = []
        self.damping, self.growth = options.initial_damping, 2.0
        self.step_damping = 0.0
        self.iterations = self.linear_solves = 0
        self.status = 0
        # The normal equations at the current point, built when a step from it is needed.
        self.gradient: np.ndarray | None = None
        self.diagonal: np.ndarray | None = None

    def evaluate(self, T: np.ndarray, known: EdgeErrors | None = None) -> _Point:
        """The point at poses `T` (`known`: their residuals, if already computed)."""
        factors = self.problem.factors
        errors = factors.evaluate(T) if known is None else known
        r = factors.whitened_norms(errors.residuals)
        priors = self.problem.priors
        if priors is None:
            return _Point(T, errors, r, float(np.sum(self.loss.cost(r))))
        prior_r = priors.whitened_norms(priors.residuals(T))
        if self.problem.weighted_priors:
            return _Point(T, errors, r, float(np.sum(self.loss.cost(np.concatenate((r, prior_r))))), prior_r)
        return _Point(T, errors, r, float(np.sum(self.loss.cost(r)) + 0.5 * np.sum(prior_r**2)), prior_r)

    def start(self, T: np.ndarray, errors: EdgeErrors | None) -> None:
        """Evaluate the initial poses `T` `(N, n, n)`."""
        self.steps.start_solve()
        with self.clock("linearize"):
            self.point = self.evaluate(T, errors)
        self.history.append(self.point.cost)
        if not np.isfinite(self.point.cost):
            self.status = NUMERICAL_FAILURE

    def iterate(self, on_iteration: IterationCallback | None) -> bool:
        """Try one step from the current point; False when the solve stops (`status` set)."""
        if self.gradient is None and not self.linearize():
            self.status = NUMERICAL_FAILURE
            return False
        gradient, diagonal = self.gradient, self.diagonal
        assert gradient is not None and diagonal is not None, "set and cleared together"
        if np.max(np.abs(gradient), initial=0.0) <= self.options.gradient_tol:
            self.status = 2
            return False
        with self.clock("factorize"):
            shift = self.damping * diagonal if self.use_damping else np.zeros_like(diagonal)
            step = self.solve_step(shift, gradient)
        if step is None:  # LM only: the damped system could not be solved
            return self.grow_damping()
        if np.sqrt(dot(step, step)) <= self.options.step_tol:
            self.status = 3
            return False
        with self.clock("update"):
            trial = self.evaluate(self.problem.retract(self.point.T, step))
        # The decrease the damped quadratic model predicts; `shift * step` is `damping * diagonal * step`.
        predicted = 0.5 * dot(step, (shift * step if self.use_damping else 0.0) - gradient)
        gain = (self.point.cost - trial.cost) / predicted if predicted > 0 and np.isfinite(trial.cost) else -1.0
        if self.use_damping and gain <= 1e-3:
            return self.grow_damping()
        if not self.use_damping and not trial.cost < self.point.cost:  # also a non-finite trial cost
            self.status = 4
            return False
        return self.accept(trial, gain, on_iteration)

    def linearize(self) -> bool:
        """Build the normal equations at the current point; False if they are not finite."""
        steps, factors, options = self.steps, self.problem.factors, self.options
        steps.discard_factorization()
        with self.clock("linearize"):
            linearization = factors.linearize(self.point.T, self.point.errors)  # reuses the residuals
        with self.clock("assemble"):
            weights, prior_weights = self.weights()
            products = edge_products(linearization, factors.information, weights)
            trusted = self.trusted
            if self.problem.priors is not None:  # after the edges, as edges from the virtual pose
                products, weights, trusted = with_prior_products(
                    self.problem.priors, self.point.T, products, weights, trusted, prior_weights
                )
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
            return False
        self.gradient, self.diagonal = gradient, np.clip(diagonal, 1e-6, 1e32)
        return True

    def weights(self) -> tuple[np.ndarray, np.ndarray | None]:
        """`(E,)` IRLS weights of the edges at the current point, and `(K,)` the priors' where the
        loss covers them (`Problem.weighted_priors`; None: weight 1)."""
        point = self.point
        if not self.problem.weighted_priors or point.prior_r is None:
            return self.loss.weight(point.r), None
        weights = self.loss.weight(np.concatenate((point.r, point.prior_r)))
        return weights[: len(point.r)], weights[len(point.r) :]

    def solve_step(self, shift: np.ndarray, gradient: np.ndarray) -> np.ndarray | None:
        """The step `-(H + diag(shift))^-1 g`, or None (LM) when it cannot be solved or is not finite.

        Raises:
            SolverError: Gauss-Newton's (undamped) system is singular: no damping can help it.
        """
        self.linear_solves += 1
        try:
            step = -self.steps.solve(shift, gradient)
        except NotPositiveDefiniteError as error:
            if self.use_damping:
                return None
            raise SolverError(_GAUSS_NEWTON_SINGULAR.format(self.iterations, f" ({error})")) from None
        if np.all(np.isfinite(step)):
            return step
        if self.use_damping:
            return None
        raise SolverError(_GAUSS_NEWTON_SINGULAR.format(self.iterations, ": its step is not finite"))

    def grow_damping(self) -> bool:
        """LM after a rejected step: more damping; False (status 4) past `max_damping`."""
        self.damping, self.growth = self.damping * self.growth, self.growth * 2
        if self.damping > self.options.max_damping:
            self.status = 4
            return False
        return True

    def accept(self, trial: _Point, gain: float, on_iteration: IterationCallback | None) -> bool:
        """Move to `trial`; False when the cost decrease says the solve converged (status 1)."""
        if self.use_damping:
            self.step_damping = self.damping
            self.damping *= max(DAMPING_MIN_FACTOR, 1.0 - (2.0 * gain - 1.0) ** 3)
            self.growth = 2.0
        previous = self.point.cost
        self.point = trial
        self.gradient = self.diagonal = None
        self.history.append(trial.cost)
        self.iterations += 1
        if on_iteration is not None:
            on_iteration(self.iterations, trial.cost)
        if previous - trial.cost <= self.options.rel_cost_tol * previous:
            self.status = 1
            return False
        return True

    def result(self, keep_errors: bool) -> SolverResult:
        """The `SolverResult` of the run so far."""
        point = self.point
        gauss_newton_stuck = self.status == 4 and not self.use_damping
        return SolverResult(
            poses=point.T,
            residual_norms=point.r,
            cost=point.cost,
            cost_history=np.array(self.history),
            iterations=self.iterations,
            linear_solves=self.linear_solves,
            status=self.status,
            message=STATUS_MESSAGES[self.status] + (_GAUSS_NEWTON_NO_DECREASE if gauss_newton_stuck else ""),
            time_s=time.perf_counter() - self.started,
            timings=dict(self.clock.totals),
            linear=self.steps.statistics,
            step_damping=self.step_damping,
            next_damping=self.damping if self.use_damping else 0.0,
            errors=point.errors if keep_errors else None,
            prior_norms=point.prior_r,
        )
