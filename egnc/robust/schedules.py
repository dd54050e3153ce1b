"""GNC schedules: after each stage's solve, decide the next stage's loss from the residuals.

A schedule sees only the whitened residual norms `r` `(E,)` at the end of a stage and whether
that solve converged, and answers with the next `Stage` (a loss for the IRLS solver plus the `mu`
it uses, for reporting) or `None` when graduation is over. Known inliers (`robust == False`)
always stay quadratic.

Schedules (DESIGN.md section 3):

- `egnc` (Kang et al., Algorithm 1): SIG kernel; stage 0 at `mu = 0`; factors whose residual
  exceeds the strong-outlier threshold (chi-square quantile 0.9) are flagged strong; at the
  second stage each unflagged factor gets its own convexity boundary `mu*(r_i)` and strong ones
  `mu = 1`; then every factor `mu = 1`. Stops once every `mu` is 1 and that solve converged.
  `threshold="squared"` compares `r^2` with `chi2.ppf(q, d)` (statistically consistent);
  `threshold="distance"` compares `r` itself, as the authors' C++ reference does.
- `risam` (McGann et al.): SIG kernel, one `mu` shared by all factors,
  `mu <- min(1, mu + 1.2 (mu - mu_init + 0.1))` from 0: 0, 0.12, 0.384, 0.965, 1.
- `gnc-gm`, `gnc-tls` (Yang et al. 2020, GTSAM's `GncOptimizer` defaults): stage 0 is plain
  least squares; then weights are fixed per stage from the previous residuals (not IRLS), `mu`
  starts from the least-squares residuals and moves by a factor 1.4 (GM: down to 1; TLS: up);
  stop when the weighted cost `sum w f` changes by less than `rel_cost_tol` relative, when GM's
  `mu` reached 1, or when TLS's weights are all within `weights_tol` of 0 or 1.
- `huber`, `cauchy`, `gm`, `l2`: one stage with a fixed kernel.

References:
    M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)", ICRA 2023.
    S. Kang et al., "Efficient Graduated Non-Convexity for Pose Graph Optimization" (EGNC-PGO).
    H. Yang, P. Antonante, V. Tzoumas, L. Carlone, "Graduated Non-Convexity for Robust Spatial
    Perception", RA-L 2020.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from egnc.errors import EgncError
from egnc.robust.kernels import Kernel, chi2_quantile, gnc_barc2, make_kernel
from egnc.robust.losses import FixedWeightLoss, KernelLoss
from egnc.robust.mu_star import mu_star

METHODS = ("egnc", "risam", "gnc-gm", "gnc-tls", "huber", "cauchy", "gm", "l2")
"""Every method name `egnc.solve` and `egnc-solve --method` accept."""

GRADUATED_METHODS = ("egnc", "risam", "gnc-gm", "gnc-tls")
"""The methods that graduate non-convexity over several stages."""

FIXED_LAST_STAGE_METHODS = ("egnc", "risam")
"""The graduated methods whose last stage is fixed in advance, `mu = 1` on every robust edge
whatever came before (`Schedule.fixed_last_stage`)."""

ThresholdConvention = Literal["squared", "distance"]


@dataclass(frozen=True, eq=False)
class Stage:
    """One GNC stage: the loss to minimize and the per-edge `mu` it uses (`nan` where none)."""

    loss: KernelLoss | FixedWeightLoss
    mu: np.ndarray


class Schedule(Protocol):
    """Chooses the loss of each stage from the residuals of the previous one."""

    def first_stage(self, r: np.ndarray) -> Stage:
        """The first stage, given residual norms `(E,)` at the initial guess."""
        ...

    def next_stage(self, r: np.ndarray, converged: bool) -> Stage | None:
        """The next stage after a solve ending at residual norms `r` `(E,)`, or None to stop."""
        ...

    def fixed_last_stage(self) -> Stage | None:
        """The last stage, when its loss does not depend on any earlier stage's residuals; else None.

        Called after `first_stage`. egnc and riSAM end with `mu = 1` on every robust edge whatever
        came before; Yang et al.'s schedules carry weights from stage to stage (None).
        """
        ...


def exceeds(r: np.ndarray, quantile: float, d: int | np.ndarray, convention: ThresholdConvention) -> np.ndarray:
    """`(E,)` bool: residual norms above the chi-square `quantile` for dimension `d` (an int, or
    `(E,)` per factor, `egnc.robust.factor_set`).

    `"squared"` tests `r^2 > chi2.ppf(quantile, d)`; `"distance"` tests `r > chi2.ppf(quantile, d)`.
    """
    threshold = chi2_quantile(quantile, d)
    return (r * r if convention == "squared" else r) > threshold


@dataclass(eq=False)
class EgncSchedule:
    """Per-factor `mu` from the convexity boundary, with a chi-square rule for strong outliers."""

    robust: np.ndarray
    d: int | np.ndarray
    c: float = 3.0
    strong_quantile: float = 0.9
    threshold: ThresholdConvention = "squared"
    _kernel: Kernel = field(init=False)
    _mu: np.ndarray = field(init=False)
    _step: np.ndarray = field(init=False)
    _strong: np.ndarray = field(init=False)

    def first_stage(self, r: np.ndarray) -> Stage:
        """Stage 0: `mu = 0` (quadratic SIG) on every robust factor; resets the per-factor state."""
        self._kernel = make_kernel("sig", c=self.c)
        self._mu = np.zeros(len(r))
        self._step = np.ones(len(r), dtype=np.int64)  # stage 0 is step 0; the next is step 1
        self._strong = np.zeros(len(r), dtype=bool)
        return self._stage()

    def next_stage(self, r: np.ndarray, converged: bool) -> Stage | None:
        """Strong outliers go to `mu = 1`, the others to `mu*(r)` once, then 1; None when done."""
        if converged and np.all(self._mu[self.robust] == 1.0):
            return None
        above = exceeds(r, self.strong_quantile, self.d, self.threshold)
        self._strong |= above & self.robust
        boundary = np.ones(len(r))
        candidates = self.robust & ~self._strong & (self._step == 1)
        boundary[candidates] = np.minimum(mu_star(r[candidates], self.c), 1.0)
        self._mu = np.where(self.robust, boundary, 0.0)
        self._step += 1
        return self._stage()

    def fixed_last_stage(self) -> Stage:
        """Every robust factor at `mu = 1`: where Algorithm 1 ends, whatever the residuals."""
        self._mu = np.where(self.robust, 1.0, 0.0)
        self._step[:] = 2
        return self._stage()

    def _stage(self) -> Stage:
        return Stage(KernelLoss(self._kernel, self._mu, self.robust), np.where(self.robust, self._mu, np.nan))


@dataclass(eq=False)
class RisamSchedule:
    """One `mu` shared by every robust factor, raised by riSAM's fixed heuristic."""

    robust: np.ndarray
    c: float = 3.0
    mu_init: float = 0.0
    _kernel: Kernel = field(init=False)
    _mu: float = field(init=False)

    def first_stage(self, r: np.ndarray) -> Stage:
        """Stage 0: the shared `mu = mu_init`."""
        self._kernel = make_kernel("sig", c=self.c)
        self._mu = self.mu_init
        return self._stage(len(r))

    def next_stage(self, r: np.ndarray, converged: bool) -> Stage | None:
        """Raise the shared `mu` by riSAM's rule; None once it is 1 and the solve converged."""
        if converged and self._mu == 1.0:
            return None
        self._mu = min(1.0, self._mu + 1.2 * (self._mu - self.mu_init + 0.1))
        return self._stage(len(r))

    def fixed_last_stage(self) -> Stage:
        """The shared `mu = 1`, where the heuristic ends whatever the residuals."""
        self._mu = 1.0
        return self._stage(len(self.robust))

    def _stage(self, num_edges: int) -> Stage:
        mu = np.full(num_edges, self._mu)
        return Stage(KernelLoss(self._kernel, mu, self.robust), np.where(self.robust, mu, np.nan))


@dataclass(eq=False)
class YangGncSchedule:
    """GNC-GM or GNC-TLS with GTSAM's defaults; weights fixed within a stage.

    With factors of mixed dimension (`d` an `(F,)` array, `egnc.robust.factor_set`), each
    factor's threshold is `0.5 chi2.ppf(0.99, d_k)`: the weights and the starting `mu` depend on
    `f / barc2` only, so each `r` is scaled by `sqrt(barc2 / barc2_k)` against the largest
    dimension's `barc2` before they are taken.
    """

    robust: np.ndarray
    d: int | np.ndarray
    kind: Literal["gm", "tls"]
    mu_step: float = 1.4
    rel_cost_tol: float = 1e-5
    weights_tol: float = 1e-4
    _kernel: Kernel = field(init=False)
    _barc2: float = field(init=False)
    _mu: float | None = field(init=False)
    _weights: np.ndarray = field(init=False)
    _previous_cost: float = field(init=False)

    def first_stage(self, r: np.ndarray) -> Stage:
        """Stage 0: plain least squares (all weights 1), whose errors set the initial `mu`."""
        self._barc2 = gnc_barc2(int(np.max(self.d)))
        self._kernel = make_kernel(f"gnc-{self.kind}", barc2=self._barc2)
        self._mu = None
        self._weights = np.ones(len(r))
        self._previous_cost = np.inf
        return Stage(FixedWeightLoss(self._weights), np.full(len(r), np.nan))

    def next_stage(self, r: np.ndarray, converged: bool) -> Stage | None:
        """Update `mu` and the fixed weights; None on GTSAM's stopping rules (cost, `mu`, binary weights)."""
        f = 0.5 * r * r
        if np.ndim(self.d):  # mixed dimensions: each factor against its own threshold (class docstring)
            r = r * np.sqrt(self._barc2 / (0.5 * chi2_quantile(0.99, self.d)))
            f_scaled = 0.5 * r * r
        else:
            f_scaled = f
        if self._mu is None:
            self._mu = self._initial_mu(f_scaled[self.robust])
            if self._mu is None:  # every robust factor is already an inlier
                return None
        else:
            cost = float(np.sum(self._weights * f))
            if abs(cost - self._previous_cost) < self.rel_cost_tol * max(self._previous_cost, 1e-7):
                return None
            if self.kind == "gm" and abs(self._mu - 1.0) < 1e-9:
                return None
            robust_weights = self._weights[self.robust]
            if self.kind == "tls" and np.all(np.abs(robust_weights - np.round(robust_weights)) <= self.weights_tol):
                return None
            self._previous_cost = cost
            self._mu = max(1.0, self._mu / self.mu_step) if self.kind == "gm" else self._mu * self.mu_step
        self._weights = np.where(self.robust, self._kernel.weight(r, self._mu), 1.0)
        return Stage(FixedWeightLoss(self._weights), np.where(self.robust, self._mu, np.nan))

    def _initial_mu(self, f: np.ndarray) -> float | None:
        """Yang et al.'s starting `mu` from the least-squares factor errors, or None if none is needed."""
        if self.kind == "gm":
            mu = 2.0 * float(np.max(f, initial=0.0)) / self._barc2
            return mu if mu > 1.0 else None
        violating = f[2.0 * f > self._barc2]
        if len(violating) == 0:
            return None
        return max(float(np.min(self._barc2 / (2.0 * violating - self._barc2))), 1e-6)

    def fixed_last_stage(self) -> None:
        """None: each stage's weights come from the previous stage's residuals."""
        return None


@dataclass(eq=False)
class SingleStage:
    """A fixed robust kernel (or plain least squares) in one IRLS solve."""

    robust: np.ndarray
    kernel: Kernel

    def first_stage(self, r: np.ndarray) -> Stage:
        """The only stage: the fixed kernel on the robust factors."""
        mu = np.zeros(len(r))
        return Stage(KernelLoss(self.kernel, mu, self.robust), np.full(len(r), np.nan))

    def next_stage(self, r: np.ndarray, converged: bool) -> Stage | None:
        """Always None: there is one stage."""
        return None

    def fixed_last_stage(self) -> None:
        """None: the first stage is the last."""
        return None


def make_schedule(
    method: str,
    robust: np.ndarray,
    d: int | np.ndarray,
    *,
    c: float = 3.0,
    threshold: ThresholdConvention = "squared",
) -> Schedule:
    """The schedule of `method` for edges where `robust` `(E,)` is true, factor dimension `d`.

    Args:
        method: one of `METHODS`.
        robust: `(E,)` bool, the edges a kernel applies to (not known inliers).
        d: residual dimension (3 in 2D, 6 in 3D), or `(E,)` per factor (`egnc.robust.factor_set`).
        c: shape of the SIG kernel (egnc, risam) and of Geman-McClure (gm).
        threshold: egnc's strong-outlier test convention, `"squared"` or `"distance"`.
    """
    if method == "egnc":
        return EgncSchedule(robust, d, c=c, threshold=threshold)
    if method == "risam":
        return RisamSchedule(robust, c=c)
    if method in ("gnc-gm", "gnc-tls"):
        return YangGncSchedule(robust, d, kind=method[4:])  # type: ignore[arg-type]
    if method == "gm":
        return SingleStage(robust, make_kernel("gm", c=c))
    if method in ("huber", "cauchy", "l2"):
        return SingleStage(robust, make_kernel(method))
    raise EgncError(f"unknown method {method!r}: choose one of {', '.join(METHODS)}")
