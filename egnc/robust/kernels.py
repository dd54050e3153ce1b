"""Robust kernels in one registry: value, IRLS weight and second derivative, all vectorized.

Every kernel is a function of `r`, the whitened residual norm (Mahalanobis distance,
`r = sqrt(e^T Omega e) >= 0`), and of a graduation parameter `mu` that non-graduated kernels ignore:

- `rho(r, mu)`: the cost of one factor; every kernel behaves like `0.5 r^2` near `r = 0`.
- `weight(r, mu)`: the IRLS weight `rho'(r) / r`, so that the IRLS normal equations are
  `sum_e w_e J_e^T Omega_e J_e` and the weighted cost is `sum_e 0.5 w_e r_e^2`.
- `d2rho(r, mu)`: the second derivative `d^2 rho / dr^2` (its sign decides local convexity).

Kernels (`make_kernel(name, **params)`):

- `l2`: `0.5 r^2`.
- `huber` (threshold `k`, default 1.345): quadratic up to `k`, linear beyond.
- `cauchy` (scale `k`, default 2.3849): `0.5 k^2 log(1 + r^2 / k^2)`.
- `gm` (shape `c`, default 3): Geman-McClure `0.5 c^2 r^2 / (c^2 + r^2)`, i.e. `sig` at `mu = 1`.
- `sig` (shape `c`, default 3): riSAM's scale-invariant graduated kernel
  `0.5 c^2 r^2 / (c^2 + (r^2)^mu)`, `mu` in [0, 1]: quadratic at 0, Geman-McClure at 1.
- `gnc-gm` and `gnc-tls`: the graduated surrogates of Yang et al. 2020 in the form used by GTSAM's
  `GncOptimizer`. They are written on the factor error `f = 0.5 r^2` with the inlier threshold
  `barc2` (GTSAM's `barcSq`, default `0.5 chi2.ppf(0.99, d)`): a factor is an inlier when
  `f <= barc2`. With `R(f)` the surrogate in `f`, `rho(r) = R(0.5 r^2)` and the IRLS weight is
  exactly `R'(f)`, the GNC weight GTSAM assigns, so an IRLS solver reproduces GTSAM's weighted
  least-squares steps. Their `mu` is Yang's (and GTSAM's) `mu`, not the `[0, 1]` one of `sig`:
  - `gnc-gm`, `a = mu barc2`, `mu` from large (convex) down to 1 (the target Geman-McClure):
    `R = a f / (a + f)`, weight `(a / (a + f))^2`, `d2rho = a^2 (a - 3 f) / (a + f)^3`.
  - `gnc-tls`, `mu` from small (convex) up to infinity (the target truncated quadratic), with
    `lo = mu / (mu + 1) barc2` and `hi = (mu + 1) / mu barc2`:
    `f <= lo`: `R = f`, weight 1, `d2rho = 1`;
    `f >= hi`: `R = barc2`, weight 0, `d2rho = 0`;
    between:   `R = 2 sqrt(barc2 mu (mu + 1) f) - mu (barc2 + f)`,
    weight `sqrt(barc2 mu (mu + 1) / f) - mu` (clipped to [0, 1]), `d2rho = -mu`.
    At `mu = inf`, `lo = hi = barc2` and `f == barc2` counts as an inlier (weight 1).

Numerics: no overflow, NaN or warning for `r` in `[0, 1e150]`, `r = 0` exactly, `mu` in `[0, 1]`
for `sig` and `mu` in `[0, inf]` for `gnc-gm`/`gnc-tls` (underflow to 0 may happen, and is
harmless). `sig` never forms `(c^2 + u)^2` or `(c^2 + u)^3` (which overflow for r above about
1e75): it works with the bounded ratios `q = c^2 / (c^2 + u)` and `s = u / (c^2 + u)`,
`q + s = 1`, e.g. weight `q (q + (1 - mu) s)`.

References:
    - M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)",
      ICRA 2023 (the SIG kernel).
    - H. Yang, P. Antonante, V. Tzoumas, L. Carlone, "Graduated Non-Convexity for Robust Spatial
      Perception: From Non-Minimal Solvers to Global Outlier Rejection", RA-L 2020, eqs. (12), (14).
    - GTSAM, `gtsam/nonlinear/GncOptimizer.h` (thresholds, weights, schedules).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from egnc.errors import EgncError

KernelFunction = Callable[..., np.ndarray]
"""`f(r, mu=None) -> ndarray`; `mu=None` means the kernel's target (most robust) `mu`."""


@dataclass(frozen=True)
class Kernel:
    """A robust kernel: three vectorized functions of `(r, mu)` and the parameters they close over.

    Attributes:
        name: registry name, e.g. `"sig"`.
        params: the kernel's parameters after defaults were applied, e.g. `{"c": 3.0}`.
        rho: `rho(r, mu=None)`, the factor cost, shape `broadcast(r, mu)`.
        weight: `weight(r, mu=None)`, the IRLS weight `rho'(r) / r`, same shape.
        d2rho: `d2rho(r, mu=None)`, `d^2 rho / dr^2`, same shape.
        mu_target: the `mu` at which the kernel is its target robust loss (used when `mu` is
            None): 1 for `sig` and `gnc-gm`, `inf` for `gnc-tls`; None for non-graduated kernels,
            which ignore `mu` and return the shape of `r`.
    """

    name: str
    params: Mapping[str, float]
    rho: KernelFunction
    weight: KernelFunction
    d2rho: KernelFunction
    mu_target: float | None = None

    @property
    def graduated(self) -> bool:
        """True when the kernel depends on `mu`."""
        return self.mu_target is not None


CHI2_QUANTILES: Mapping[tuple[float, int], float] = MappingProxyType(
    {
        (0.99, 3): 11.344866730144373,
        (0.99, 6): 16.811893829770927,
        (0.9999, 3): 21.107513466160444,
        (0.9999, 6): 27.85634123601417,
    }
)
"""`chdtri(d, 1 - quantile)` for the quantiles egnc's defaults use (`GncOptions`), bit for bit
(tests/test_kernels.py): a least-squares solve then never imports `scipy.special` (30-60 ms)."""


def chi2_quantile(quantile: float, d: Any) -> Any:
    """`chi2.ppf(quantile, d)`: `CHI2_QUANTILES`, else `scipy.special` (importing `scipy.stats` costs 0.5 s).

    `d` an int gives a float; `d` an array of factor dimensions `(F,)` gives `(F,)` thresholds
    (factors of mixed dimension, `egnc.robust.factor_set`).
    """
    if np.ndim(d):
        dims, inverse = np.unique(np.asarray(d), return_inverse=True)
        return np.array([chi2_quantile(quantile, int(m)) for m in dims])[inverse.reshape(-1)]
    tabulated = CHI2_QUANTILES.get((quantile, d))
    if tabulated is not None:
        return tabulated
    from scipy.special import chdtri

    return float(chdtri(d, 1.0 - quantile))


def gnc_barc2(d: int, p: float = 0.99) -> float:
    """GTSAM's default GNC inlier threshold `barcSq = 0.5 chi2.ppf(p, d)` on the error `0.5 r^2`.

    Args:
        d: factor dimension (3 for SE(2) edges, 6 for SE(3) edges).
        p: probability that an inlier's `r^2` lies below `chi2.ppf(p, d)`; GTSAM uses 0.99.

    Returns:
        The threshold on the factor error `f = 0.5 r^2` (so `r^2 <= 2 barc2` is an inlier).
    """
    if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 1:
        raise EgncError(f"factor dimension d must be a positive integer, got {d!r}")
    if not 0.0 < p < 1.0:
        raise EgncError(f"inlier probability p must be in (0, 1), got {p!r}")
    return 0.5 * chi2_quantile(p, int(d))


def make_kernel(name: str, **params: float) -> Kernel:
    """Build a kernel from the registry by name.

    Args:
        name: one of `KERNELS` (`"l2"`, `"huber"`, `"cauchy"`, `"gm"`, `"sig"`, `"gnc-gm"`,
            `"gnc-tls"`).
        **params: kernel parameters, see each builder (`c`, `k`, `d`/`barc2`/`p`).

    Returns:
        The `Kernel`.

    Raises:
        EgncError: unknown name (the message lists the valid ones), unknown parameter, or an
            invalid parameter value.
    """
    builder = KERNELS.get(name)
    if builder is None:
        raise EgncError(f"unknown kernel {name!r}; valid kernels: {', '.join(sorted(KERNELS))}")
    signature = inspect.signature(builder)
    try:
        signature.bind(**params)
    except TypeError:
        valid = ", ".join(signature.parameters) or "none"
        raise EgncError(f"kernel {name!r} got parameters {sorted(params)}; valid parameters: {valid}") from None
    return builder(**params)


# ----------------------------------------------------------------------------- helpers


def _positive(name: str, value: float) -> float:
    """Validate a strictly positive, finite scalar parameter."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise EgncError(f"kernel parameter {name} must be a number, got {value!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise EgncError(f"kernel parameter {name} must be positive and finite, got {value!r}")
    return value


def _graduated(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], mu_target: float):
    """Wrap `fn(r, mu)` on float arrays; `mu=None` selects the target `mu`."""

    def call(r: ArrayLike, mu: ArrayLike | None = None) -> np.ndarray:
        r = np.asarray(r, dtype=np.float64)
        mu = np.asarray(mu_target if mu is None else mu, dtype=np.float64)
        return fn(r, mu)

    call.__name__ = call.__qualname__ = fn.__name__.lstrip("_")
    call.__doc__ = fn.__doc__
    return call


def _fixed(fn: Callable[[np.ndarray], np.ndarray]):
    """Wrap `fn(r)` on float arrays; `mu` is accepted and ignored."""

    def call(r: ArrayLike, mu: ArrayLike | None = None) -> np.ndarray:
        return fn(np.asarray(r, dtype=np.float64))

    call.__name__ = call.__qualname__ = fn.__name__.lstrip("_")
    call.__doc__ = fn.__doc__
    return call


def _sig_ratios(r: np.ndarray, mu: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
    """`q = c^2 / (c^2 + u)` and `s = u / (c^2 + u)` for `u = (r^2)^mu`.

    `0^0 = 1` (so `mu = 0` is the quadratic `c^2 r^2 / (2 (c^2 + 1))` even at `r = 0`) and
    `0^mu = 0` for `mu > 0`. For `r <= 1e150`, `u <= max(1, r^2) <= 1e300`, so nothing here
    overflows, and both ratios are formed directly, never as `1 - other`, so neither loses digits.
    """
    u = np.power(r * r, mu)
    d = c * c + u
    return (c * c) / d, u / d


# ----------------------------------------------------------------------------- kernels


def _l2_rho(r: np.ndarray) -> np.ndarray:
    """`0.5 r^2`."""
    return 0.5 * r * r


def _l2_weight(r: np.ndarray) -> np.ndarray:
    """Constant 1."""
    return np.ones_like(r)


def _build_l2() -> Kernel:
    """Plain least squares: `rho = 0.5 r^2`, weight 1, `d2rho = 1`."""
    return Kernel(
        name="l2",
        params=MappingProxyType({}),
        rho=_fixed(_l2_rho),
        weight=_fixed(_l2_weight),
        d2rho=_fixed(_l2_weight),
    )


def _build_huber(k: float = 1.345) -> Kernel:
    """Huber: `0.5 r^2` for `r <= k`, `k (r - k / 2)` beyond; weight `min(1, k / r)`.

    The default `k = 1.345` gives 95% efficiency on Gaussian data.
    """
    k = _positive("k", k)

    def _huber_rho(r: np.ndarray) -> np.ndarray:
        """`0.5 r^2` inside `k`, `k (r - k / 2)` outside."""
        return np.where(r <= k, 0.5 * r * r, k * (r - 0.5 * k))

    def _huber_weight(r: np.ndarray) -> np.ndarray:
        """`min(1, k / r)`."""
        return k / np.maximum(r, k)

    def _huber_d2rho(r: np.ndarray) -> np.ndarray:
        """1 inside `k`, 0 outside."""
        return np.where(r <= k, 1.0, 0.0)

    return Kernel(
        name="huber",
        params=MappingProxyType({"k": k}),
        rho=_fixed(_huber_rho),
        weight=_fixed(_huber_weight),
        d2rho=_fixed(_huber_d2rho),
    )


def _build_cauchy(k: float = 2.3849) -> Kernel:
    """Cauchy: `0.5 k^2 log(1 + r^2 / k^2)`; weight `1 / (1 + r^2 / k^2)`.

    The default `k = 2.3849` gives 95% efficiency on Gaussian data.
    """
    k = _positive("k", k)

    def _cauchy_rho(r: np.ndarray) -> np.ndarray:
        """`0.5 k^2 log1p((r / k)^2)`."""
        t = r / k
        return 0.5 * k * k * np.log1p(t * t)

    def _cauchy_weight(r: np.ndarray) -> np.ndarray:
        """`1 / (1 + (r / k)^2)`."""
        t = r / k
        return 1.0 / (1.0 + t * t)

    def _cauchy_d2rho(r: np.ndarray) -> np.ndarray:
        """`k^2 (k^2 - r^2) / (k^2 + r^2)^2`, written as `w (2 w - 1)`."""
        w = _cauchy_weight(r)
        return w * (2.0 * w - 1.0)

    return Kernel(
        name="cauchy",
        params=MappingProxyType({"k": k}),
        rho=_fixed(_cauchy_rho),
        weight=_fixed(_cauchy_weight),
        d2rho=_fixed(_cauchy_d2rho),
    )


def _sig_functions(c: float):
    """The three SIG functions of `(r, mu)` for shape `c` (DESIGN.md section 2)."""

    def _sig_rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`0.5 c^2 r^2 / (c^2 + u) = 0.5 r^2 q`."""
        q, _ = _sig_ratios(r, mu, c)
        return 0.5 * r * r * q

    def _sig_weight(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`c^2 (c^2 + (1 - mu) u) / (c^2 + u)^2 = q (q + (1 - mu) s)`."""
        q, s = _sig_ratios(r, mu, c)
        return q * (q + (1.0 - mu) * s)

    def _sig_d2rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """EGNC eq. 2 divided through by `D^3`: `q (q^2 + (1 - 2 mu) s ((mu + 2) q + (1 - mu) s))`.

        Uses `q + s = 1` to make the bracket homogeneous, so no term cancels against `1` when `u`
        is large (see `egnc.robust.mu_star`).
        """
        q, s = _sig_ratios(r, mu, c)
        return q * (q * q + (1.0 - 2.0 * mu) * s * ((mu + 2.0) * q + (1.0 - mu) * s))

    return _sig_rho, _sig_weight, _sig_d2rho


def _build_sig(c: float = 3.0) -> Kernel:
    """riSAM's SIG kernel `0.5 c^2 r^2 / (c^2 + (r^2)^mu)`, `mu` in [0, 1]; riSAM uses `c = 3`."""
    c = _positive("c", c)
    rho, weight, d2rho = _sig_functions(c)
    return Kernel(
        name="sig",
        params=MappingProxyType({"c": c}),
        rho=_graduated(rho, 1.0),
        weight=_graduated(weight, 1.0),
        d2rho=_graduated(d2rho, 1.0),
        mu_target=1.0,
    )


def _build_gm(c: float = 3.0) -> Kernel:
    """Geman-McClure `0.5 c^2 r^2 / (c^2 + r^2)` with fixed `c`: SIG at `mu = 1`."""
    c = _positive("c", c)
    rho, weight, d2rho = _sig_functions(c)
    one = np.float64(1.0)

    def _gm_rho(r: np.ndarray) -> np.ndarray:
        """`0.5 c^2 r^2 / (c^2 + r^2)`."""
        return rho(r, one)

    def _gm_weight(r: np.ndarray) -> np.ndarray:
        """`c^4 / (c^2 + r^2)^2`."""
        return weight(r, one)

    def _gm_d2rho(r: np.ndarray) -> np.ndarray:
        """`c^4 (c^2 - 3 r^2) / (c^2 + r^2)^3`."""
        return d2rho(r, one)

    return Kernel(
        name="gm",
        params=MappingProxyType({"c": c}),
        rho=_fixed(_gm_rho),
        weight=_fixed(_gm_weight),
        d2rho=_fixed(_gm_d2rho),
    )


def _gnc_threshold(d: int | None, barc2: float | None, p: float) -> float:
    """Resolve the GNC inlier threshold from exactly one of `d` and `barc2`."""
    if barc2 is not None and d is None:
        return _positive("barc2", barc2)
    if d is not None and barc2 is None:
        return gnc_barc2(d, p)
    raise EgncError("GNC kernels need exactly one of d (factor dimension) or barc2")


def _build_gnc_gm(d: int | None = None, barc2: float | None = None, p: float = 0.99) -> Kernel:
    """Yang et al.'s graduated Geman-McClure on `f = 0.5 r^2` (GTSAM `GncLossType::GM`).

    Args:
        d: factor dimension; sets `barc2 = 0.5 chi2.ppf(p, d)`.
        barc2: the inlier threshold on `f` directly (instead of `d`).
        p: inlier probability used with `d` (GTSAM default 0.99).
    """
    barc2 = _gnc_threshold(d, barc2, p)

    def _scaled_ratio(r: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`f` and `q = a / (a + f)` with `a = mu barc2`, safe for `a` in `{0, inf}`."""
        f = 0.5 * r * r
        a = mu * barc2
        f, a = np.broadcast_arrays(f, a)
        # t = f / a; a = 0 means weight 0 for any f > 0, a = inf means plain least squares.
        t = np.divide(f, a, out=np.where(f > 0.0, np.inf, 0.0), where=a > 0.0)
        return f, 1.0 / (1.0 + t)

    def _gnc_gm_rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`a f / (a + f) = f q`."""
        f, q = _scaled_ratio(r, mu)
        return f * q

    def _gnc_gm_weight(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`(a / (a + f))^2 = q^2` (Yang et al. eq. 12)."""
        _, q = _scaled_ratio(r, mu)
        return q * q

    def _gnc_gm_d2rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`a^2 (a - 3 f) / (a + f)^3 = q^2 (4 q - 3)`."""
        _, q = _scaled_ratio(r, mu)
        return q * q * (4.0 * q - 3.0)

    return Kernel(
        name="gnc-gm",
        params=MappingProxyType({"barc2": barc2}),
        rho=_graduated(_gnc_gm_rho, 1.0),
        weight=_graduated(_gnc_gm_weight, 1.0),
        d2rho=_graduated(_gnc_gm_d2rho, 1.0),
        mu_target=1.0,
    )


def _build_gnc_tls(d: int | None = None, barc2: float | None = None, p: float = 0.99) -> Kernel:
    """Yang et al.'s graduated truncated least squares on `f = 0.5 r^2` (GTSAM `GncLossType::TLS`).

    Args:
        d: factor dimension; sets `barc2 = 0.5 chi2.ppf(p, d)`.
        barc2: the inlier threshold on `f` directly (instead of `d`).
        p: inlier probability used with `d` (GTSAM default 0.99).
    """
    barc2 = _gnc_threshold(d, barc2, p)

    def _regions(r: np.ndarray, mu: np.ndarray):
        """`f`, masks `(inlier, between)`, and `mu` made safe (finite, > 0) inside `between`."""
        f = 0.5 * r * r
        f, mu = np.broadcast_arrays(f, mu)
        # 1 / mu with mu = 0 -> inf (lo = 0, hi = inf) and mu = inf -> 0 (lo = hi = barc2).
        inv_mu = np.divide(1.0, mu, out=np.full(mu.shape, np.inf), where=mu > 0.0)
        lo = barc2 / (1.0 + inv_mu)
        hi = barc2 * (1.0 + inv_mu)
        inlier = f <= lo
        between = ~inlier & (f < hi)
        return f, inlier, between, np.where(between, mu, 1.0), np.where(between, f, 1.0)

    def _gnc_tls_rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """`f`, `2 sqrt(barc2 mu (mu + 1) f) - mu (barc2 + f)`, or `barc2` by region."""
        f, inlier, between, m, fb = _regions(r, mu)
        # The middle piece equals f - (sqrt((mu+1) f) - sqrt(mu barc2))^2 and also
        # barc2 - (sqrt(mu f) - sqrt((mu+1) barc2))^2; use the form whose square is small
        # so nothing cancels at large mu.
        near_lo = fb - (np.sqrt((m + 1.0) * fb) - np.sqrt(m * barc2)) ** 2
        near_hi = barc2 - (np.sqrt(m * fb) - np.sqrt((m + 1.0) * barc2)) ** 2
        middle = np.clip(np.where(fb <= barc2, near_lo, near_hi), 0.0, barc2)
        return np.where(inlier, f, np.where(between, middle, barc2))

    def _gnc_tls_weight(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """1, `sqrt(barc2 mu (mu + 1) / f) - mu` (Yang et al. eq. 14), or 0 by region."""
        _, inlier, between, m, fb = _regions(r, mu)
        middle = np.clip(np.sqrt(barc2 * m / fb) * np.sqrt(m + 1.0) - m, 0.0, 1.0)
        return np.where(inlier, 1.0, np.where(between, middle, 0.0))

    def _gnc_tls_d2rho(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """1, `-mu`, or 0 by region."""
        _, inlier, between, m, _ = _regions(r, mu)
        return np.where(inlier, 1.0, np.where(between, -m, 0.0))

    return Kernel(
        name="gnc-tls",
        params=MappingProxyType({"barc2": barc2}),
        rho=_graduated(_gnc_tls_rho, np.inf),
        weight=_graduated(_gnc_tls_weight, np.inf),
        d2rho=_graduated(_gnc_tls_d2rho, np.inf),
        mu_target=np.inf,
    )


KERNELS: Mapping[str, Callable[..., Kernel]] = MappingProxyType(
    {
        "l2": _build_l2,
        "huber": _build_huber,
        "cauchy": _build_cauchy,
        "gm": _build_gm,
        "sig": _build_sig,
        "gnc-gm": _build_gnc_gm,
        "gnc-tls": _build_gnc_tls,
    }
)
"""Kernel builders by name; `make_kernel(name, **params)` is the validated entry point."""
