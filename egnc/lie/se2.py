"""SE(2): planar poses as homogeneous `(..., 3, 3)` matrices; tangent `(..., 3)` = `[v_x, v_y, omega]`.

Right-perturbation conventions of Sola et al., "A micro Lie theory for state estimation in
robotics" (2018), app. C. `log` is the true group logarithm `[V(omega)^-1 t, omega]`, the same
as GTSAM's `Pose2.Logmap`; it is not `[x, y, theta]` (that is `to_xytheta`).
"""

from __future__ import annotations

import numpy as np

from egnc.lie._components import as_float_array, broadcast_batch, join, matmul, matvec, split
from egnc.lie._safe import (
    jacobian_inverse_coefficient,
    sincos_half,
    sincos_half_from_cos_sin,
    trig_coefficients,
)
from egnc.lie.so2 import wrap_angle

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
    "from_xytheta",
    "to_xytheta",
    "exp_components",
    "log_components",
    "right_jacobian_inverse_components",
]


def _pose(cos_t, sin_t, tx, ty) -> np.ndarray:
    """Return `[[c, -s, tx], [s, c, ty], [0, 0, 1]]` as `(..., 3, 3)` from `(...)` components."""
    shape = np.broadcast_shapes(np.shape(cos_t), np.shape(sin_t), np.shape(tx), np.shape(ty))
    out = np.empty(shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = cos_t, -sin_t, tx
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = sin_t, cos_t, ty
    out[..., 2, :] = (0.0, 0.0, 1.0)
    return out


def _split_pose(T) -> tuple[np.ndarray, np.ndarray]:
    """Return component-first copies `(R (2, 2, ...), t (2, ...))` of poses `(..., 3, 3)`."""
    top = split(T[..., :2, :], 2)  # the bottom row is constant: skip copying it
    return top[:, :2], top[:, 2]


def _matrix3(rows) -> np.ndarray:
    """Return a `(..., 3, 3)` array from a 3x3 nested list of `(...)` arrays or scalars."""
    entries = np.broadcast_arrays(*[e for row in rows for e in row])
    return join(np.stack(entries).reshape((3, 3) + entries[0].shape), 2)


def identity(batch_shape: tuple[int, ...] = ()) -> np.ndarray:
    """Return identity poses, `(*batch_shape, 3, 3)`."""
    return np.broadcast_to(np.eye(3), tuple(batch_shape) + (3, 3)).copy()


def from_xytheta(a) -> np.ndarray:
    """Return poses from `[x, y, theta]` (theta in rad): `(..., 3) -> (..., 3, 3)`."""
    x, y, theta = split(as_float_array(a, (3,), "a"), 1)
    return _pose(np.cos(theta), np.sin(theta), x, y)


def to_xytheta(T) -> np.ndarray:
    """Return `[x, y, theta]` with theta in (-pi, pi]: `(..., 3, 3) -> (..., 3)`."""
    r, t = _split_pose(as_float_array(T, (3, 3), "T"))
    return join(np.stack([t[0], t[1], wrap_angle(np.arctan2(r[1, 0], r[0, 0]))]), 1)


def hat(xi) -> np.ndarray:
    """Return `[[0, -w, v_x], [w, 0, v_y], [0, 0, 0]]` (Sola eq. 153): `(..., 3) -> (..., 3, 3)`."""
    vx, vy, w = split(as_float_array(xi, (3,), "xi"), 1)
    zero = np.zeros_like(w)
    return _matrix3([[zero, -w, vx], [w, zero, vy], [zero, zero, zero]])


def vee(X) -> np.ndarray:
    """Return `[v_x, v_y, w]` from a Lie-algebra matrix: `(..., 3, 3) -> (..., 3)`."""
    x = split(as_float_array(X, (3, 3), "X"), 2)
    return join(np.stack([x[0, 2], x[1, 2], 0.5 * (x[1, 0] - x[0, 1])]), 1)


def exp(xi) -> np.ndarray:
    """Return `Exp([v, w]) = [[R(w), V(w) v], [0, 1]]` (Sola eqs. 156, 158): `(..., 3) -> (..., 3, 3)`."""
    return _pose(*exp_components(*split(as_float_array(xi, (3,), "xi"), 1)))


def exp_components(vx, vy, w) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return `(cos w, sin w, t_x, t_y)` of `Exp([v_x, v_y, w])`, all `(...)`; see `exp`."""
    sin_half, cos_half = sincos_half(w * w)
    f1, f2 = trig_coefficients(w * w, 2, sin_half, cos_half)
    # V = [[sin w / w, -(1 - cos w) / w], [(1 - cos w) / w, sin w / w]].
    b = w * f2
    sin_w = np.where(w < 0.0, -2.0, 2.0) * sin_half * cos_half  # sin w = sign(w) sin|w|
    return 1.0 - 2.0 * sin_half * sin_half, sin_w, f1 * vx - b * vy, b * vx + f1 * vy


def log(T) -> np.ndarray:
    """Return `Log(T) = [V(w)^-1 t, w]` with w in (-pi, pi] (Sola eq. 157): `(..., 3, 3) -> (..., 3)`."""
    r, (tx, ty) = _split_pose(as_float_array(T, (3, 3), "T"))
    return join(np.stack(log_components(r[0, 0], r[1, 0], tx, ty)), 1)


def log_components(cos_t, sin_t, tx, ty) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return `(v_x, v_y, w)` of the log of the pose with rotation `(cos t, sin t)` and translation `(t_x, t_y)`.

    See `log`.
    """
    w = wrap_angle(np.arctan2(sin_t, cos_t))
    # V^-1 = [[a, w/2], [-w/2, a]], a = (w/2) cot(w/2); half-angle terms straight from R, no trig calls.
    sin_half, cos_half = sincos_half_from_cos_sin(cos_t, sin_t)
    f1, f2, f3 = trig_coefficients(w * w, 3, sin_half, cos_half)
    a = _half_angle_cot(w * w, f1, f2, f3, sin_half, cos_half)
    h = 0.5 * w
    return a * tx + h * ty, a * ty - h * tx, w


def _half_angle_cot(theta2, f1, f2, f3, sin_half, cos_half) -> np.ndarray:
    """Return `(t/2) cot(t/2) = 1 - t^2 g`, g from `jacobian_inverse_coefficient`. Shape `(...)`."""
    return 1.0 - theta2 * jacobian_inverse_coefficient(theta2, f1, f2, f3, sin_half, cos_half)


def compose(A, B) -> np.ndarray:
    """Return `A @ B`, broadcasting batch shapes: `(..., 3, 3)`."""
    A, B = broadcast_batch(as_float_array(A, (3, 3), "A"), 2, as_float_array(B, (3, 3), "B"), 2)
    ra, ta = _split_pose(A)
    rb, tb = _split_pose(B)
    r = matmul(ra, rb)
    t = matvec(ra, tb) + ta
    return _pose(r[0, 0], r[1, 0], t[0], t[1])


def inverse(T) -> np.ndarray:
    """Return `[[R^T, -R^T t], [0, 1]]`: `(..., 3, 3)`."""
    r, t = _split_pose(as_float_array(T, (3, 3), "T"))
    rt = r.swapaxes(0, 1)
    t_inv = -matvec(rt, t)
    return _pose(r[0, 0], r[0, 1], t_inv[0], t_inv[1])


def between(A, B) -> np.ndarray:
    """Return `A^-1 B`: `(..., 3, 3)`."""
    A, B = broadcast_batch(as_float_array(A, (3, 3), "A"), 2, as_float_array(B, (3, 3), "B"), 2)
    ra, ta = _split_pose(A)
    rb, tb = _split_pose(B)
    rat = ra.swapaxes(0, 1)
    r = matmul(rat, rb)
    t = matvec(rat, tb - ta)
    return _pose(r[0, 0], r[1, 0], t[0], t[1])


def act(T, p) -> np.ndarray:
    """Return transformed points `R p + t`: `(..., 3, 3), (..., 2) -> (..., 2)`."""
    T, p = broadcast_batch(as_float_array(T, (3, 3), "T"), 2, as_float_array(p, (2,), "p"), 1)
    r, t = _split_pose(T)
    return join(matvec(r, split(p, 1)) + t, 1)


def adjoint(T) -> np.ndarray:
    """Return `Ad(T) = [[R, [t_y, -t_x]^T], [0, 1]]` (Sola eq. 159): `(..., 3, 3) -> (..., 3, 3)`."""
    r, t = _split_pose(as_float_array(T, (3, 3), "T"))
    return _pose(r[0, 0], r[1, 0], t[1], -t[0])


def right_jacobian(xi) -> np.ndarray:
    """Return `Jr([v, w])` (Sola eq. 163): `(..., 3) -> (..., 3, 3)`."""
    vx, vy, w = split(as_float_array(xi, (3,), "xi"), 1)
    f1, f2, f3 = trig_coefficients(w * w, 3, *sincos_half(w * w))
    b, c = w * f2, w * f3  # (1 - cos w) / w and (w - sin w) / w^2
    zero, one = np.zeros_like(w), np.ones_like(w)
    return _matrix3([[f1, b, c * vx - f2 * vy], [-b, f1, f2 * vx + c * vy], [zero, zero, one]])


def right_jacobian_inverse(xi) -> np.ndarray:
    """Return `Jr([v, w])^-1`, inverting the blocks of eq. 163 in closed form: `(..., 3) -> (..., 3, 3)`."""
    vx, vy, w = split(as_float_array(xi, (3,), "xi"), 1)
    a, h, p, q = right_jacobian_inverse_components(vx, vy, w)
    zero, one = np.zeros_like(w), np.ones_like(w)
    return _matrix3([[a, -h, p], [h, a, q], [zero, zero, one]])


def right_jacobian_inverse_components(vx, vy, w) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return `(a, h, p, q)` with `Jr([v, w])^-1 = [[a, -h, p], [h, a, q], [0, 0, 1]]`, all `(...)`."""
    sin_half, cos_half = sincos_half(w * w)
    f1, f2, f3 = trig_coefficients(w * w, 3, sin_half, cos_half)
    # Jr = [[A, u], [0, 1]] with A = V(-w), so A^-1 = [[a, -w/2], [w/2, a]], a = (w/2) cot(w/2).
    a = _half_angle_cot(w * w, f1, f2, f3, sin_half, cos_half)
    h = 0.5 * w
    c = w * f3
    ux, uy = c * vx - f2 * vy, f2 * vx + c * vy
    return a, h, h * uy - a * ux, -(h * ux + a * uy)


def rplus(T, xi) -> np.ndarray:
    """Return `T Exp(xi)`: `(..., 3, 3), (..., 3) -> (..., 3, 3)`."""
    T, xi = broadcast_batch(as_float_array(T, (3, 3), "T"), 2, as_float_array(xi, (3,), "xi"), 1)
    cos_e, sin_e, tx_e, ty_e = exp_components(*split(xi, 1))
    # compose(T, exp(xi)) on components, in the same order of operations; T's entries are read
    # in place (products and sums give the same bits on any memory layout).
    r00, r01, r10, r11 = T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1]
    return _pose(
        r00 * cos_e + r01 * sin_e,
        r10 * cos_e + r11 * sin_e,
        r00 * tx_e + r01 * ty_e + T[..., 0, 2],
        r10 * tx_e + r11 * ty_e + T[..., 1, 2],
    )


def rminus(A, B) -> np.ndarray:
    """Return `Log(B^-1 A)`, so that `rplus(B, rminus(A, B)) = A`: `(..., 3, 3) -> (..., 3)`."""
    return log(between(B, A))
