"""SO(2): planar rotations as `(..., 2, 2)` matrices; tangent `(..., 1)` = the angle (rad).

SO(2) is commutative, so its adjoint and Jacobians are all 1 (Sola et al., "A micro Lie theory
for state estimation in robotics" (2018), app. A). Angles from `log` lie in (-pi, pi].
"""

from __future__ import annotations

import numpy as np

from egnc.lie._components import as_float_array, broadcast_batch, join, matmul, matvec, split

__all__ = [
    "identity",
    "hat",
    "vee",
    "exp",
    "log",
    "compose",
    "inverse",
    "between",
    "act",
    "adjoint",
    "right_jacobian",
    "right_jacobian_inverse",
    "rplus",
    "rminus",
    "from_angle",
    "to_angle",
    "wrap_angle",
]


def wrap_angle(theta) -> np.ndarray:
    """Return `theta` wrapped to (-pi, pi]: `(...) -> (...)`."""
    theta = np.asarray(theta, dtype=np.float64)
    # Angles already in range (all atan2 outputs but -pi) pass through bit-exact.
    inside = (theta > -np.pi) & (theta <= np.pi)
    wrapped = np.pi - np.mod(np.pi - theta, 2.0 * np.pi)
    return np.where(inside, theta, wrapped)


def identity(batch_shape: tuple[int, ...] = ()) -> np.ndarray:
    """Return identity rotations, `(*batch_shape, 2, 2)`."""
    return np.broadcast_to(np.eye(2), tuple(batch_shape) + (2, 2)).copy()


def _rotation(cos_t, sin_t) -> np.ndarray:
    """Return `[[c, -s], [s, c]]` as `(..., 2, 2)` from `(...)` components."""
    return join(np.stack([np.stack([cos_t, -sin_t]), np.stack([sin_t, cos_t])]), 2)


def from_angle(theta) -> np.ndarray:
    """Return the rotation by `theta` (rad): `(...) -> (..., 2, 2)`."""
    theta = np.asarray(theta, dtype=np.float64)
    return _rotation(np.cos(theta), np.sin(theta))


def to_angle(R) -> np.ndarray:
    """Return the angle of `R` in (-pi, pi]: `(..., 2, 2) -> (...)`."""
    r = split(as_float_array(R, (2, 2), "R"), 2)
    return wrap_angle(np.arctan2(r[1, 0], r[0, 0]))


def hat(theta) -> np.ndarray:
    """Return `[[0, -theta], [theta, 0]]`: `(..., 1) -> (..., 2, 2)`."""
    theta = as_float_array(theta, (1,), "theta")[..., 0]
    zero = np.zeros_like(theta)
    return join(np.stack([np.stack([zero, -theta]), np.stack([theta, zero])]), 2)


def vee(W) -> np.ndarray:
    """Return the angle of the skew part of `W`: `(..., 2, 2) -> (..., 1)`."""
    W = as_float_array(W, (2, 2), "W")
    return 0.5 * (W[..., 1, 0] - W[..., 0, 1])[..., None]


def exp(theta) -> np.ndarray:
    """Return `Exp(theta)`: `(..., 1) -> (..., 2, 2)`."""
    return from_angle(as_float_array(theta, (1,), "theta")[..., 0])


def log(R) -> np.ndarray:
    """Return `Log(R)` in (-pi, pi]: `(..., 2, 2) -> (..., 1)`."""
    return to_angle(R)[..., None]


def compose(A, B) -> np.ndarray:
    """Return `A @ B`, broadcasting batch shapes: `(..., 2, 2)`."""
    a, b = broadcast_batch(as_float_array(A, (2, 2), "A"), 2, as_float_array(B, (2, 2), "B"), 2)
    r = matmul(split(a, 2), split(b, 2))
    return _rotation(r[0, 0], r[1, 0])


def inverse(R) -> np.ndarray:
    """Return `R^T`: `(..., 2, 2)`."""
    return np.ascontiguousarray(np.swapaxes(as_float_array(R, (2, 2), "R"), -1, -2))


def between(A, B) -> np.ndarray:
    """Return `A^-1 B`: `(..., 2, 2)`."""
    a, b = broadcast_batch(as_float_array(A, (2, 2), "A"), 2, as_float_array(B, (2, 2), "B"), 2)
    r = matmul(split(a, 2).swapaxes(0, 1), split(b, 2))
    return _rotation(r[0, 0], r[1, 0])


def act(R, p) -> np.ndarray:
    """Return rotated points `R p`: `(..., 2, 2), (..., 2) -> (..., 2)`."""
    R, p = broadcast_batch(as_float_array(R, (2, 2), "R"), 2, as_float_array(p, (2,), "p"), 1)
    return join(matvec(split(R, 2), split(p, 1)), 1)


def adjoint(R) -> np.ndarray:
    """Return `Ad(R) = 1`: `(..., 2, 2) -> (..., 1, 1)`."""
    return np.ones(as_float_array(R, (2, 2), "R").shape[:-2] + (1, 1))


def right_jacobian(theta) -> np.ndarray:
    """Return `Jr(theta) = 1`: `(..., 1) -> (..., 1, 1)`."""
    return np.ones(as_float_array(theta, (1,), "theta").shape + (1,))


def right_jacobian_inverse(theta) -> np.ndarray:
    """Return `Jr(theta)^-1 = 1`: `(..., 1) -> (..., 1, 1)`."""
    return np.ones(as_float_array(theta, (1,), "theta").shape + (1,))


def rplus(R, theta) -> np.ndarray:
    """Return `R Exp(theta)`: `(..., 2, 2), (..., 1) -> (..., 2, 2)`."""
    return compose(R, exp(theta))


def rminus(A, B) -> np.ndarray:
    """Return `Log(B^-1 A)`, so that `rplus(B, rminus(A, B)) = A`: `(..., 2, 2) -> (..., 1)`."""
    return log(between(B, A))
