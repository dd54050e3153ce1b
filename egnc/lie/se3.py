"""SE(3): 3D poses as homogeneous `(..., 4, 4)` matrices; tangent `(..., 6)` = `[v, omega]`.

Translation first, as in g2o's information matrices and in Sola et al., "A micro Lie theory for
state estimation in robotics" (2018), app. D; GTSAM's Pose3 tangent is the other way round
(`[omega, v]`). `log` is the true group logarithm `[V(omega)^-1 t, omega]`, equal to GTSAM's
`Pose3.Logmap` up to that reordering. Right-perturbation conventions throughout.
"""

from __future__ import annotations

import numpy as np

from egnc.lie._components import (
    as_float_array,
    broadcast_batch,
    cross,
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
from egnc.lie.so3 import from_quaternion

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
    "from_xyz_quat",
    "to_xyz_quat",
]


def _pose(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Return `[[r, t], [0, 1]]` as `(..., 4, 4)` from component-first `(3, 3, ...)` and `(3, ...)`."""
    out = np.zeros((4, 4) + np.broadcast_shapes(r.shape[2:], t.shape[1:]))
    out[:3, :3] = r
    out[:3, 3] = t
    out[3, 3] = 1.0
    return join(out, 2)


def _split_pose(T) -> tuple[np.ndarray, np.ndarray]:
    """Return component-first copies `(R (3, 3, ...), t (3, ...))` of poses `(..., 4, 4)`."""
    top = split(T[..., :3, :], 2)  # the bottom row is constant: skip copying it
    return top[:, :3], top[:, 3]


def identity(batch_shape: tuple[int, ...] = ()) -> np.ndarray:
    """Return identity poses, `(*batch_shape, 4, 4)`."""
    return np.broadcast_to(np.eye(4), tuple(batch_shape) + (4, 4)).copy()


def hat(xi) -> np.ndarray:
    """Return the Lie-algebra matrix `[[ [omega]x, v ], [0, 0]]` (Sola eq. 169): `(..., 6) -> (..., 4, 4)`."""
    xi = split(as_float_array(xi, (6,), "xi"), 1)
    out = np.zeros((4, 4) + xi.shape[1:])
    out[:3, :3] = _hat(xi[3:])
    out[:3, 3] = xi[:3]
    return join(out, 2)


def vee(X) -> np.ndarray:
    """Return `[v, omega]` from a Lie-algebra matrix: `(..., 4, 4) -> (..., 6)`."""
    x = split(as_float_array(X, (4, 4), "X"), 2)
    w = 0.5 * np.stack([x[2, 1] - x[1, 2], x[0, 2] - x[2, 0], x[1, 0] - x[0, 1]])
    return join(np.concatenate([x[:3, 3], w]), 1)


def exp(xi) -> np.ndarray:
    """Return `Exp([v, w]) = [[Exp(w), V(w) v], [0, 1]]` (Sola eqs. 172, 174): `(..., 6) -> (..., 4, 4)`."""
    xi = split(as_float_array(xi, (6,), "xi"), 1)
    v, w = xi[:3], xi[3:]
    theta2 = sq_norm(w)
    f1, f2, f3 = trig_coefficients(theta2, 3, *sincos_half(theta2))
    # V = Jl(w) = I + f2 [w]x + f3 [w]x^2, applied to v without forming it.
    wv = cross(w, v)
    return _pose(skew_poly(w, f1, f2), v + f2 * wv + f3 * cross(w, wv))


def log(T) -> np.ndarray:
    """Return `Log(T) = [V(w)^-1 t, w]` (Sola eq. 173): `(..., 4, 4) -> (..., 6)`."""
    r, t = _split_pose(as_float_array(T, (4, 4), "T"))
    w, theta2, sin_half, cos_half = rotation_log(r)
    f1, f2, f3 = trig_coefficients(theta2, 3, sin_half, cos_half)
    g = jacobian_inverse_coefficient(theta2, f1, f2, f3, sin_half, cos_half)
    # V^-1 = Jl(w)^-1 = I - [w]x / 2 + g [w]x^2 (Sola eq. 146), finite at t = pi.
    wt = cross(w, t)
    return join(np.concatenate([t - 0.5 * wt + g * cross(w, wt), w]), 1)


def compose(A, B) -> np.ndarray:
    """Return `A @ B`, broadcasting batch shapes: `(..., 4, 4)`."""
    A, B = broadcast_batch(as_float_array(A, (4, 4), "A"), 2, as_float_array(B, (4, 4), "B"), 2)
    ra, ta = _split_pose(A)
    rb, tb = _split_pose(B)
    return _pose(matmul(ra, rb), matvec(ra, tb) + ta)


def inverse(T) -> np.ndarray:
    """Return `[[R^T, -R^T t], [0, 1]]`: `(..., 4, 4)`."""
    r, t = _split_pose(as_float_array(T, (4, 4), "T"))
    rt = r.swapaxes(0, 1)
    return _pose(rt, -matvec(rt, t))


def between(A, B) -> np.ndarray:
    """Return `A^-1 B`: `(..., 4, 4)`."""
    A, B = broadcast_batch(as_float_array(A, (4, 4), "A"), 2, as_float_array(B, (4, 4), "B"), 2)
    ra, ta = _split_pose(A)
    rb, tb = _split_pose(B)
    rat = ra.swapaxes(0, 1)
    return _pose(matmul(rat, rb), matvec(rat, tb - ta))


def act(T, p) -> np.ndarray:
    """Return transformed points `R p + t`: `(..., 4, 4), (..., 3) -> (..., 3)`."""
    T, p = broadcast_batch(as_float_array(T, (4, 4), "T"), 2, as_float_array(p, (3,), "p"), 1)
    r, t = _split_pose(T)
    return join(matvec(r, split(p, 1)) + t, 1)


def adjoint(T) -> np.ndarray:
    """Return `Ad(T) = [[R, [t]x R], [0, R]]` (Sola eq. 175): `(..., 4, 4) -> (..., 6, 6)`."""
    r, t = _split_pose(as_float_array(T, (4, 4), "T"))
    out = np.zeros((6, 6) + r.shape[2:])
    out[:3, :3] = r
    out[3:, 3:] = r
    out[:3, 3:] = cross(t[:, None], r)  # column j: t x R[:, j]
    return join(out, 2)


def _q_block(v: np.ndarray, w: np.ndarray, f3: np.ndarray, f4: np.ndarray, f5: np.ndarray) -> np.ndarray:
    """Return Sola's `Q(v, w)` (eq. 180), the top-right block of the SE(3) left Jacobian: `(3, 3, ...)`.

    The skew products of eq. 180 collapse with `[a]x [b]x = b a^T - (a.b) I` to
        Q = [v/2 + f4 w x (w x v) + (f4 - f3) s w]x + p w^T + w p^T + s (c |w|^2 - 2 f3) I,
    with s = w.v, c = f4 - 3 f5, p = f3 v - (c s / 2) w. Here f3 = (t - sin t)/t^3,
    f4 = (t^2 + 2 cos t - 2)/(2 t^4), and c / 2 is the last coefficient of eq. 180,
    (2t - 3 sin t + t cos t)/(2 t^5). Component-first `v`, `w`: `(3, ...)`.
    """
    s = w[0] * v[0] + w[1] * v[1] + w[2] * v[2]
    cs = (f4 - 3.0 * f5) * s
    p = f3 * v - (0.5 * cs) * w
    pw = p[:, None] * w[None, :]
    out = pw + pw.swapaxes(0, 1)
    diag = cs * sq_norm(w) - 2.0 * f3 * s
    for i in range(3):
        out[i, i] += diag
    a = 0.5 * v + f4 * cross(w, cross(w, v)) + ((f4 - f3) * s) * w
    out[0, 1] -= a[2]
    out[1, 0] += a[2]
    out[0, 2] += a[1]
    out[2, 0] -= a[1]
    out[1, 2] -= a[0]
    out[2, 1] += a[0]
    return out


def right_jacobian(xi) -> np.ndarray:
    """Return `Jr([v, w]) = Jl(-[v, w]) = [[Jr(w), Q(-v, -w)], [0, Jr(w)]]` (Sola eqs. 179-180).

    Shapes: `(..., 6) -> (..., 6, 6)`.
    """
    xi = split(as_float_array(xi, (6,), "xi"), 1)
    v, w = xi[:3], xi[3:]
    theta2 = sq_norm(w)
    _, f2, f3, f4, f5 = trig_coefficients(theta2, 5, *sincos_half(theta2))
    J = skew_poly(w, -f2, f3)
    out = np.zeros((6, 6) + xi.shape[1:])
    out[:3, :3] = J
    out[3:, 3:] = J
    out[:3, 3:] = _q_block(-v, -w, f3, f4, f5)
    return join(out, 2)


def right_jacobian_inverse(xi) -> np.ndarray:
    """Return `Jr(xi)^-1 = [[Jr(w)^-1, -Jr(w)^-1 Q Jr(w)^-1], [0, Jr(w)^-1]]`, Q as in `right_jacobian`.

    Shapes: `(..., 6) -> (..., 6, 6)`.
    """
    xi = split(as_float_array(xi, (6,), "xi"), 1)
    v, w = xi[:3], xi[3:]
    theta2 = sq_norm(w)
    half = sincos_half(theta2)
    f1, f2, f3, f4, f5 = trig_coefficients(theta2, 5, *half)
    J_inv = skew_poly(w, 0.5, jacobian_inverse_coefficient(theta2, f1, f2, f3, *half))
    out = np.zeros((6, 6) + xi.shape[1:])
    out[:3, :3] = J_inv
    out[3:, 3:] = J_inv
    out[:3, 3:] = -matmul(J_inv, matmul(_q_block(-v, -w, f3, f4, f5), J_inv))
    return join(out, 2)


def rplus(T, xi) -> np.ndarray:
    """Return `T Exp(xi)`: `(..., 4, 4), (..., 6) -> (..., 4, 4)`."""
    return compose(T, exp(xi))


def rminus(A, B) -> np.ndarray:
    """Return `Log(B^-1 A)`, so that `rplus(B, rminus(A, B)) = A`: `(..., 4, 4) -> (..., 6)`."""
    return log(between(B, A))


def from_xyz_quat(a) -> np.ndarray:
    """Return poses from g2o's `[x, y, z, qx, qy, qz, qw]` (q normalized): `(..., 7) -> (..., 4, 4)`."""
    a = as_float_array(a, (7,), "a")
    return _pose(split(from_quaternion(a[..., 3:]), 2), split(a[..., :3], 1))


def to_xyz_quat(T) -> np.ndarray:
    """Return `[x, y, z, qx, qy, qz, qw]` with `qw >= 0`: `(..., 4, 4) -> (..., 7)`."""
    r, t = _split_pose(as_float_array(T, (4, 4), "T"))
    return join(np.concatenate([t, rotation_to_quaternion(r)]), 1)
