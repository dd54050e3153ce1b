"""SO(3): 3D rotations as `(..., 3, 3)` matrices; tangent `(..., 3)` = rotation vector (rad).

Right-perturbation conventions of Sola et al., "A micro Lie theory for state estimation in
robotics" (2018), app. B: `rplus(R, w) = R Exp(w)`, `Exp(w + dw) ~ Exp(w) Exp(Jr(w) dw)`.
Quaternions are `[qx, qy, qz, qw]` (g2o's storage order).
"""

from __future__ import annotations

import numpy as np

from egnc.lie._components import (
    as_float_array,
    broadcast_batch,
    hat as _hat,
    join,
    matmul,
    matvec,
    rotation_log,
    rotation_to_quaternion,
    skew_poly,
    split,
    sq_norm,
)
from egnc.lie._safe import jacobian_inverse_coefficient, sincos_half, trig_coefficients

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
    "from_quaternion",
    "to_quaternion",
]


def identity(batch_shape: tuple[int, ...] = ()) -> np.ndarray:
    """Return identity rotations, `(*batch_shape, 3, 3)`."""
    return np.broadcast_to(np.eye(3), tuple(batch_shape) + (3, 3)).copy()


def hat(omega) -> np.ndarray:
    """Return the skew matrix `[w]x`: `(..., 3) -> (..., 3, 3)`."""
    return join(_hat(split(as_float_array(omega, (3,), "omega"), 1)), 2)


def vee(W) -> np.ndarray:
    """Return `w` from the skew part of `W`: `(..., 3, 3) -> (..., 3)`."""
    w = split(as_float_array(W, (3, 3), "W"), 2)
    return join(0.5 * np.stack([w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1]]), 1)


def exp(omega) -> np.ndarray:
    """Return `Exp(w) = I + sin(t)/t [w]x + (1 - cos t)/t^2 [w]x^2` (Sola eq. 132).

    Shapes: `(..., 3) -> (..., 3, 3)`; `t = |w|`.
    """
    w = split(as_float_array(omega, (3,), "omega"), 1)
    theta2 = sq_norm(w)
    f1, f2 = trig_coefficients(theta2, 2, *sincos_half(theta2))
    return join(skew_poly(w, f1, f2), 2)


def log(R) -> np.ndarray:
    """Return `Log(R)`, angle in [0, pi], via the quaternion (accurate near pi): `(..., 3, 3) -> (..., 3)`."""
    return join(rotation_log(split(as_float_array(R, (3, 3), "R"), 2))[0], 1)


def compose(A, B) -> np.ndarray:
    """Return `A @ B`, broadcasting batch shapes: `(..., 3, 3)`."""
    a, b = broadcast_batch(as_float_array(A, (3, 3), "A"), 2, as_float_array(B, (3, 3), "B"), 2)
    return join(matmul(split(a, 2), split(b, 2)), 2)


def inverse(R) -> np.ndarray:
    """Return `R^T`: `(..., 3, 3)`."""
    return np.ascontiguousarray(np.swapaxes(as_float_array(R, (3, 3), "R"), -1, -2))


def between(A, B) -> np.ndarray:
    """Return `A^-1 B`: `(..., 3, 3)`."""
    a, b = broadcast_batch(as_float_array(A, (3, 3), "A"), 2, as_float_array(B, (3, 3), "B"), 2)
    return join(matmul(split(a, 2).swapaxes(0, 1), split(b, 2)), 2)


def act(R, p) -> np.ndarray:
    """Return rotated points `R p`: `(..., 3, 3), (..., 3) -> (..., 3)`."""
    R, p = broadcast_batch(as_float_array(R, (3, 3), "R"), 2, as_float_array(p, (3,), "p"), 1)
    return join(matvec(split(R, 2), split(p, 1)), 1)


def adjoint(R) -> np.ndarray:
    """Return `Ad(R) = R` (Sola app. B): `(..., 3, 3)`."""
    return np.array(as_float_array(R, (3, 3), "R"))


def right_jacobian(omega) -> np.ndarray:
    """Return `Jr(w) = I - f2 [w]x + f3 [w]x^2` (Sola eq. 143): `(..., 3) -> (..., 3, 3)`."""
    w = split(as_float_array(omega, (3,), "omega"), 1)
    theta2 = sq_norm(w)
    _, f2, f3 = trig_coefficients(theta2, 3, *sincos_half(theta2))
    return join(skew_poly(w, -f2, f3), 2)


def right_jacobian_inverse(omega) -> np.ndarray:
    """Return `Jr(w)^-1 = I + [w]x / 2 + g [w]x^2` (Sola eq. 144): `(..., 3) -> (..., 3, 3)`."""
    w = split(as_float_array(omega, (3,), "omega"), 1)
    theta2 = sq_norm(w)
    half = sincos_half(theta2)
    f1, f2, f3 = trig_coefficients(theta2, 3, *half)
    g = jacobian_inverse_coefficient(theta2, f1, f2, f3, *half)
    return join(skew_poly(w, 0.5, g), 2)


def rplus(R, omega) -> np.ndarray:
    """Return `R Exp(w)`: `(..., 3, 3), (..., 3) -> (..., 3, 3)`."""
    return compose(R, exp(omega))


def rminus(A, B) -> np.ndarray:
    """Return `Log(B^-1 A)`, so that `rplus(B, rminus(A, B)) = A`: `(..., 3, 3) -> (..., 3)`."""
    return log(between(B, A))


def from_quaternion(q) -> np.ndarray:
    """Return the rotation of quaternion `[qx, qy, qz, qw]` (normalized first): `(..., 4) -> (..., 3, 3)`."""
    q = split(as_float_array(q, (4,), "q"), 1)
    norm2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if not np.all(np.isfinite(norm2) & (norm2 > 0.0)):
        raise ValueError("quaternion must be finite and nonzero")
    x, y, z, w = q / np.sqrt(norm2)
    return join(
        np.stack(
            [
                np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)]),
                np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)]),
                np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]),
            ]
        ),
        2,
    )


def to_quaternion(R) -> np.ndarray:
    """Return unit quaternions `[qx, qy, qz, qw]`, `qw >= 0` (Shepperd's method): `(..., 3, 3) -> (..., 4)`."""
    return join(rotation_to_quaternion(split(as_float_array(R, (3, 3), "R"), 2)), 1)
