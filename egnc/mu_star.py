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
root. All factors are solved at once by bisection on the bracket [1/2, 1], halved until it is
narrower than 1e-14 (46 halvings): it tests only the sign of G, which stays exact where G near
the root is far below 1e-300 for huge r, and it costs well under a millisecond for hundreds of
factors.

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

_HALVINGS = math.ceil(math.log2(0.5 / MU_STAR_XATOL))
"""Bisection steps that shrink the bracket [1/2, 1] below `MU_STAR_XATOL`."""


def convexity_margin(mu: ArrayLike, log_r2: ArrayLike, log_c2: ArrayLike) -> np.ndarray:
    """`G(mu; r) = F / (c^2 + u)^2`, whose sign is the sign of SIG's `d2rho/dr2` at r.

    Args:
        mu: SIG shape parameter, broadcastable with the others.
        log_r2: `log(r^2)`.
        log_c2: `log(c^2)`.

    Returns:
        `q^2 + (1 - 2 mu) s ((mu + 2) q + (1 - mu) s)` (bounded for any r), broadcast shape.
    """
    from scipy.special import expit  # here: a least-squares solve never needs scipy.special

    mu = np.asarray(mu, dtype=np.float64)
    z = mu * np.asarray(log_r2, dtype=np.float64) - np.asarray(log_c2, dtype=np.float64)
    q, s = expit(-z), expit(z)
    return q * q + (1.0 - 2.0 * mu) * s * ((mu + 2.0) * q + (1.0 - mu) * s)


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
    log_c2 = 2.0 * math.log(c)
    log_r2 = 2.0 * np.log(flat[active])
    # G(1/2) = q^2 underflows to 0 only when c^2 / r < 1e-160, where mu* = 1/2 to the last bit.
    at_half = convexity_margin(0.5, log_r2, log_c2) == 0.0
    out[active[at_half]] = 0.5
    active, log_r2 = active[~at_half], log_r2[~at_half]
    if active.size:
        low, high = np.full(active.size, 0.5), np.ones(active.size)  # G(low) > 0 > G(high)
        for _ in range(_HALVINGS):
            middle = 0.5 * (low + high)
            convex = convexity_margin(middle, log_r2, log_c2) > 0.0
            low, high = np.where(convex, middle, low), np.where(convex, high, middle)
        out[active] = 0.5 * (low + high)
    return out.reshape(r.shape)
