"""Safe-theta coefficients: every angle-dependent 0/0 in `egnc.lie` is resolved here.

Each coefficient is computed on both sides of a threshold: a Taylor series where the closed form
cancels, the closed form (with a denominator that cannot be zero) elsewhere, selected with
`np.where`. No warning or NaN can leak from the unused branch (jaxlie's "safe theta" pattern).
A branch that no entry of the batch uses is not computed at all: the kernels run on an online
region's few edges as often as on a whole map's, and there the NumPy calls, not the elements,
are the cost. Every entry gets the same bits either way.

The closed forms take `sin(t/2)` and `cos(t/2)` from the caller: `exp` gets them from
`sincos_half`, while SO(3) `log` already has them as the quaternion's `|v|` and `w`, so it needs
no further transcendental calls (they dominate the cost on large batches).
"""

from __future__ import annotations

import functools
import math

import numpy as np

# Below this squared angle (rad^2) the coefficients use their Taylor series. The closed form of f_n
# cancels about n! eps / t^(n-1) relative there, i.e. <= 3e-14 for n <= 5 at t = 1.
_SERIES_MAX_THETA2 = 1.0
# Taylor terms kept; the series are only summed for orders n >= 2, whose first omitted term at
# t = 1 is at most 2!/18! ~ 3e-16 relative.
_SERIES_TERMS = 8
_MAX_ORDER = 5


def sincos_half(theta2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return `(sin(t/2), cos(t/2))` for `t = sqrt(theta2)`. Shapes `(...)`."""
    half = 0.5 * np.sqrt(theta2)
    return np.sin(half), np.cos(half)


def sincos_half_from_cos_sin(cos_t: np.ndarray, sin_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return `(sin(t/2), cos(t/2))` for `t = |atan2(sin_t, cos_t)|` in [0, pi], without trig calls.

    Of `sqrt((1 -+ cos t)/2)` only the one without cancellation is used (>= sqrt(1/2)); the
    other half-angle function follows from `sin t = 2 sin(t/2) cos(t/2)`.
    """
    use_cos = np.asarray(cos_t >= 0.0)
    abs_sin = np.abs(sin_t)
    c = np.asarray(np.sqrt(np.maximum(0.5 * (1.0 + cos_t), 0.0)))
    if use_cos.all():  # every angle within pi/2: the usual case, one branch
        return np.asarray(abs_sin / (2.0 * c)), c
    s = np.sqrt(np.maximum(0.5 * (1.0 - cos_t), 0.0))
    sin_half = np.where(use_cos, abs_sin / (2.0 * np.where(use_cos, c, 1.0)), s)
    cos_half = np.where(use_cos, c, abs_sin / (2.0 * np.where(use_cos, 1.0, s)))
    return sin_half, cos_half


@functools.cache
def _pair_coefficients(n: int, ndim: int) -> np.ndarray:
    """`(K, 2, 1, ..., 1)` Taylor coefficients: row `k` holds `(-1)^k / (2k + m)!` for `m = n` and
    `n - 1`, shaped to broadcast against `ndim` batch axes (read-only, cached)."""
    table = np.array([[(-1.0) ** k / math.factorial(2 * k + m) for m in (n, n - 1)] for k in range(_SERIES_TERMS)])
    table = table.reshape((_SERIES_TERMS, 2) + (1,) * ndim)
    table.flags.writeable = False
    return table


def _series_pair(theta2: np.ndarray, n: int) -> np.ndarray:
    """Return the Taylor sums `sum_k (-1)^k theta2^k / (2k + m)!` for `m = n` and `n - 1`, stacked
    `(2, ...)`, by Horner's rule: one pass of NumPy calls for both orders."""
    coefficients = _pair_coefficients(n, theta2.ndim)
    out = coefficients[_SERIES_TERMS - 1] * theta2
    out += coefficients[_SERIES_TERMS - 2]
    for k in range(_SERIES_TERMS - 3, -1, -1):
        out *= theta2
        out += coefficients[k]
    return out


def trig_coefficients(
    theta2: np.ndarray, n_max: int, sin_half: np.ndarray, cos_half: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Return `(f_1, ..., f_n_max)` with `f_n(t) = sum_k (-1)^k t^(2k) / (2k + n)!`.

    That is `f_1 = sin(t)/t`, `f_2 = (1 - cos t)/t^2`, `f_3 = (t - sin t)/t^3`,
    `f_4 = (cos t - 1 + t^2/2)/t^4`, `f_5 = (sin t - t + t^3/6)/t^5`: the coefficients of the
    exponential map, its Jacobians and the SE(3) Q block (Sola et al. eqs. 132, 143, 174, 180).

    Args:
        theta2: squared angle `t^2`, `(...)`, rad^2.
        n_max: highest order wanted, 1..5.
        sin_half, cos_half: `sin(t/2)` and `cos(t/2)`, `(...)`.

    Returns:
        tuple of `n_max` arrays of shape `(...)`.
    """
    assert 1 <= n_max <= _MAX_ORDER
    theta2 = np.asarray(theta2, dtype=np.float64)
    small = theta2 < _SERIES_MAX_THETA2
    all_small = bool(small.all())
    none_small = not all_small and not small.any()

    if not none_small:
        # Series: sum the two highest orders, then step down with f_n = 1/n! - t^2 f_(n+2),
        # which does not cancel for t < 1.
        top = max(n_max, 3)
        series = dict(zip((top, top - 1), _series_pair(theta2, top)))
        for n in range(top - 2, 0, -1):
            series[n] = 1.0 / math.factorial(n) - theta2 * series[n + 2]
        if all_small:
            return tuple(np.asarray(series[n]) for n in range(1, n_max + 1))

    # Closed forms through the half angle: sin t = 2 s c and 1 - cos t = 2 s^2 do not cancel.
    t2 = theta2 if none_small else np.where(small, 1.0, theta2)
    t = np.sqrt(t2)
    closed = {1: 2.0 * sin_half * cos_half / t, 2: 2.0 * sin_half * sin_half / t2}
    for n in range(3, n_max + 1):
        closed[n] = (1.0 / math.factorial(n - 2) - closed[n - 2]) / t2
    if none_small:
        return tuple(np.asarray(closed[n]) for n in range(1, n_max + 1))
    return tuple(np.where(small, series[n], closed[n]) for n in range(1, n_max + 1))


def jacobian_inverse_coefficient(
    theta2: np.ndarray,
    f1: np.ndarray,
    f2: np.ndarray,
    f3: np.ndarray,
    sin_half: np.ndarray,
    cos_half: np.ndarray,
) -> np.ndarray:
    """Return `g = 1/t^2 - (1 + cos t) / (2 t sin t)`, the `[w]x^2` coefficient of SO(3) Jr^-1.

    Sola et al. eq. 144. Near 0 it equals `(f_2 - 2 f_3) / (2 f_1)` (no 1/t^2 cancellation);
    elsewhere `(1 - (t/2) cot(t/2)) / t^2`, finite at t = pi where the textbook form is 0/0. It
    diverges only at t = 2 pi, where Jr itself is singular. Also `(t/2) cot(t/2) = 1 - t^2 g`,
    the diagonal of the SE(2) `V^-1`.

    Args:
        theta2: squared angle, `(...)`, rad^2.
        f1, f2, f3: from `trig_coefficients`.
        sin_half, cos_half: `sin(t/2)` and `cos(t/2)`, `(...)`.

    Returns:
        `(...)`.
    """
    small = np.asarray(theta2 < _SERIES_MAX_THETA2)
    if small.all():
        return np.asarray((f2 - 2.0 * f3) / (2.0 * f1))
    near_zero = (f2 - 2.0 * f3) / (2.0 * np.where(small, f1, 1.0))
    t2 = np.where(small, 1.0, theta2)
    safe_sin_half = np.where(sin_half == 0.0, 1.0, sin_half)
    far = (1.0 - 0.5 * np.sqrt(t2) * cos_half / safe_sin_half) / t2
    return np.where(small, near_zero, far)


def atan2_ratio(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Return `atan2(n, w) / n` for a unit quaternion with `n = |v| >= 0`, `w >= 0`. Shape `(...)`.

    atan2 is accurate to a few ulp for any n > 0, so only n = 0 needs the limit `1 / w` = 1.
    """
    positive = n > 0.0
    return np.where(positive, np.arctan2(n, w) / np.where(positive, n, 1.0), 1.0)
