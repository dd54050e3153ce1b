"""mu*: the largest SIG shape parameter that keeps each factor's kernel convex at its residual.

Derivation. The SIG kernel is `rho(r; mu) = 0.5 c^2 r^2 / (c^2 + u)` with `u = r^(2 mu)`.
Write `D = c^2 + u`, `q = c^2 / D` and `s = u / D`, so `q, s` lie in [0, 1] and `q + s = 1`.
EGNC's eq. 2 gives `d2rho/dr2 = c^2 / D^3 * F(mu; r)` with

    F = (c^2 + u - 3 mu u - 2 mu^2 u) (c^2 + u) + 4 mu^2 u^2        (DESIGN.md section 2).

Dividing by `D^2` and replacing the lone `1` by `(q + s)^2` makes every term homogeneous:

    G(mu; r) = F / D^2 = q^2 + (1 - 2 mu) s ((mu + 2) q + (1 - mu) s),
    d2rho/dr2 = q G.

Consequences:

- For `mu <= 1/2` every term of G is non-negative, so SIG is convex for every r: `mu* >= 1/2`.
- `G(1) = q (q - 3 s) < 0` exactly when `u = r^2 > c^2 / 3`. So for `r <= c / sqrt(3)` the
  kernel is convex at r for every mu and `mu* = 1`.
- Otherwise `G(1/2) = q^2 > 0 > G(1)` brackets the sign change, which is unique on (0, 1)
  (checked numerically in the tests for c in {1, 2, 3, 6}, r up to 1e4); `mu*` is that root.
- As r grows, `q -> 0` and `s -> 1`, and G = 0 reads `q^2 ~ (mu - 1/2)`: `mu* -> 1/2`, with
  `mu* - 1/2 = O(c^4 / r^2)`. Where `q^2` underflows (`c^2 / r < 1e-160`) mu* is 1/2 exactly.

Numerics: q and s are logistic functions of `log u - log c^2 = 2 mu log r - 2 log c`, so nothing
overflows for any finite r, and G in this form loses no digits to cancellation away from the
root. All factors are solved at once by Newton steps in mu (`dG/dmu` in closed form) from the
large-r asymptote `mu* ~ 1/2 + c^4 / r^2` (capped below 1), kept in the bracket [1/2, 1]: a step
that would leave it (or is not a number) is a bisection instead. They stop when every step is
below 1e-14. Newton converges quadratically near the root, so that takes four to eight steps
(at most twelve) for residuals up to `30 c^2`, where the asymptote is still far off, and one or
two beyond, each a handful of array operations.

References:
    - M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)",
      ICRA 2023 (the SIG kernel).
    - Kang et al., "Efficient Graduated Non-Convexity for Pose Graph Optimization" (EGNC-PGO),
      eq. 2 and the convexity boundary mu*.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from egnc.errors import EgncError

MU_STAR_XATOL = 1e-14
"""Absolute tolerance on each root mu*."""

_MAX_STEPS = 2 * math.ceil(math.log2(0.5 / MU_STAR_XATOL))
"""Steps after which the solve stops whatever their size: twice the bisection halvings that would
shrink the bracket [1/2, 1] below `MU_STAR_XATOL` (it took at most 12 for c from 0.5 to 10)."""


def convexity_margin(mu: ArrayLike, log_r2: ArrayLike, log_c2: ArrayLike) -> np.ndarray:
    """`G(mu; r) = F / (c^2 + u)^2`, whose sign is the sign of SIG's `d2rho/dr2` at r.

    Args:
        mu: SIG shape parameter, broadcastable with the others.
        log_r2: `log(r^2)`.
        log_c2: `log(c^2)`.

    Returns:
        `q^2 + (1 - 2 mu) s ((mu + 2) q + (1 - mu) s)` (bounded for any r), broadcast shape.
    """
    return _margin_and_slope(mu, log_r2, log_c2)[0]


def _margin_and_slope(mu: ArrayLike, log_r2: ArrayLike, log_c2: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """`convexity_margin` G and its derivative `dG/dmu` (with `dq/dmu = -q s log r^2 = -ds/dmu`)."""
    from scipy.special import expit  # here: a least-squares solve never needs scipy.special

    mu = np.asarray(mu, dtype=np.float64)
    log_r2 = np.asarray(log_r2, dtype=np.float64)
    z = mu * log_r2 - np.asarray(log_c2, dtype=np.float64)
    q, s = expit(-z), expit(z)
    linear = (mu + 2.0) * q + (1.0 - mu) * s
    turn = q * s * log_r2
    margin = q * q + (1.0 - 2.0 * mu) * s * linear
    linear_slope = q - s - (2.0 * mu + 1.0) * turn
    slope = -2.0 * q * turn - 2.0 * s * linear + (1.0 - 2.0 * mu) * (turn * linear + s * linear_slope)
    return margin, slope


def mu_star(r: ArrayLike, c: float = 3.0) -> np.ndarray:
    """The convexity boundary mu* of the SIG kernel for every factor, in one vectorized solve.

    `mu*(r)` is the largest mu in [0, 1] such that `rho(.; mu)` is convex at r (`d2rho >= 0`):
    1 where `r <= c / sqrt(3)`, otherwise the unique root of `G(mu; r)` in (1/2, 1).

    Args:
        r: `(E,)` (any shape) whitened residual norms, finite and >= 0.
        c: SIG shape parameter, > 0 (riSAM uses 3).

    Returns:
        mu*, float64, same shape as `r`, in [1/2, 1], non-increasing in r.

    Raises:
        EgncError: `r` negative or not finite, or `c` not positive and finite.
    """
    r = np.asarray(r, dtype=np.float64)
    c = float(c)
    if not (math.isfinite(c) and c > 0.0):
        raise EgncError(f"SIG shape c must be positive and finite, got {c!r}")
    if not np.all(np.isfinite(r)) or np.any(r < 0.0):
        raise EgncError("residual norms r must be finite and >= 0")

    flat = r.ravel()
    out = np.ones(flat.shape)
    (active,) = np.nonzero(flat > c / math.sqrt(3.0))
    if not active.size:  # every factor inside the always-convex radius (most online updates)
        return out.reshape(r.shape)
    log_c2 = 2.0 * math.log(c)
    log_r2 = 2.0 * np.log(flat[active])
    # G(1/2) = q^2 underflows to 0 only when c^2 / r < 1e-160, where mu* = 1/2 to the last bit.
    at_half = convexity_margin(0.5, log_r2, log_c2) == 0.0
    out[active[at_half]] = 0.5
    active, log_r2 = active[~at_half], log_r2[~at_half]
    if active.size:
        out[active] = _root_in_bracket(log_r2, log_c2)
    return out.reshape(r.shape)


def _root_in_bracket(log_r2: np.ndarray, log_c2: float) -> np.ndarray:
    """`(K,)` the root of `G(mu; r)` in (1/2, 1) for each `log(r^2)` `(K,)` where `G(1/2) > 0 > G(1)`,
    by safeguarded Newton steps (module docstring, "Numerics")."""
    low, high = np.full(log_r2.shape, 0.5), np.ones(log_r2.shape)  # G(low) > 0 > G(high)
    mu = 0.5 + np.minimum(np.exp(2.0 * log_c2 - log_r2), 0.4999)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(_MAX_STEPS):
            margin, slope = _margin_and_slope(mu, log_r2, log_c2)
            convex = margin > 0.0
            low, high = np.where(convex, mu, low), np.where(convex, high, mu)
            newton = mu - margin / slope
            inside = (newton >= low) & (newton <= high)  # False where the step is not a number
            following = np.where(inside, newton, 0.5 * (low + high))
            step, mu = np.abs(following - mu), following
            if np.all(step <= MU_STAR_XATOL):
                break
    return mu
