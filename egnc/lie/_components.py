"""Component-first array layout and the SO(3) kernels shared by `so3` and `se3`.

Public functions take and return `(..., n, m)` arrays. Inside, they `split` them into
component-first views `(n, m, ...)`, so every arithmetic operation runs over the whole batch in
its inner loop; operations whose inner loop is a trailing axis of length 3 (`sum(-1)`, block
copies, `(..., 3, 3)` broadcasting) cost 10-50x more per element in NumPy. Results are `join`ed
back into one contiguous array.
"""

from __future__ import annotations

import numpy as np

from egnc.lie._safe import atan2_ratio


def as_float_array(x, trailing: tuple[int, ...], name: str) -> np.ndarray:
    """Return `x` as a float64 array whose last dimensions are `trailing`, or raise ValueError."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < len(trailing) or a.shape[a.ndim - len(trailing) :] != trailing:
        raise ValueError(f"{name} must have shape (..., {', '.join(map(str, trailing))}), got {a.shape}")
    return a


def broadcast_batch(a: np.ndarray, a_dims: int, b: np.ndarray, b_dims: int) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast the batch shapes of `a` (with `a_dims` element axes) and `b` against each other (views)."""
    batch = np.broadcast_shapes(a.shape[: a.ndim - a_dims], b.shape[: b.ndim - b_dims])
    return (
        np.broadcast_to(a, batch + a.shape[a.ndim - a_dims :]),
        np.broadcast_to(b, batch + b.shape[b.ndim - b_dims :]),
    )


def split(x: np.ndarray, dims: int) -> np.ndarray:
    """Return `(..., d_1..d_dims)` as a contiguous component-first `(d_1..d_dims, ...)` copy.

    The copy matters: ufuncs lay out their results in the memory order of their inputs, so a
    mere transposed view would keep every later operation's inner loop over the components.
    """
    # `transpose` with the axes spelled out: `np.moveaxis` normalizes its axis tuples in Python,
    # about 8 us a call, which a small batch (an online region) feels.
    return np.ascontiguousarray(x.transpose((*range(x.ndim - dims, x.ndim), *range(x.ndim - dims))))


def join(y: np.ndarray, dims: int) -> np.ndarray:
    """Return component-first `(d_1..d_dims, ...)` as a contiguous `(..., d_1..d_dims)` array."""
    return np.ascontiguousarray(y.transpose((*range(dims, y.ndim), *range(dims))))


def sq_norm(v: np.ndarray) -> np.ndarray:
    """Return `|v|^2` of a component-first `(3, ...)` vector: `(...)`."""
    return v[0] * v[0] + v[1] * v[1] + v[2] * v[2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return `a x b` for component-first `(3, ...)` vectors."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return `a @ b` for component-first `(n, k, ...)` and `(k, m, ...)` matrices: `(n, m, ...)`."""
    out = a[:, 0, None] * b[None, 0]
    for j in range(1, a.shape[1]):
        out += a[:, j, None] * b[None, j]
    return out


def matvec(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return `a @ v` for component-first `(n, k, ...)` and `(k, ...)`: `(n, ...)`."""
    out = a[:, 0] * v[0]
    for j in range(1, a.shape[1]):
        out += a[:, j] * v[j]
    return out


def hat(w: np.ndarray) -> np.ndarray:
    """Return `[w]x`, component-first: `(3, ...) -> (3, 3, ...)`."""
    zero = np.zeros_like(w[0])
    rows = [[zero, -w[2], w[1]], [w[2], zero, -w[0]], [-w[1], w[0], zero]]
    return np.stack([np.stack(row) for row in rows])


def skew_poly(w: np.ndarray, a, b) -> np.ndarray:
    """Return `I + a [w]x + b [w]x^2` via `[w]x^2 = w w^T - |w|^2 I`: `(3, ...) -> (3, 3, ...)`.

    `a` and `b` broadcast against the batch shape `(...)`.
    """
    out = b * (w[:, None] * w[None, :])
    diag = 1.0 - b * sq_norm(w)
    for i in range(3):
        out[i, i] += diag
    aw = a * w
    out[0, 1] -= aw[2]
    out[1, 0] += aw[2]
    out[0, 2] += aw[1]
    out[2, 0] -= aw[1]
    out[1, 2] -= aw[0]
    out[2, 1] += aw[0]
    return out


def rotation_to_quaternion(r: np.ndarray) -> np.ndarray:
    """Return `[qx, qy, qz, qw]` with `qw >= 0` from component-first `(3, 3, ...)`: `(4, ...)`.

    Shepperd's method: of the four expressions for `4 q_k q`, use the one whose `q_k^2` is
    largest (always >= 1/4 for a rotation), so no division by a small number; then normalize,
    which also absorbs a slightly non-orthogonal input.
    """
    tx = 1.0 + r[0, 0] - r[1, 1] - r[2, 2]  # 4 qx^2
    ty = 1.0 - r[0, 0] + r[1, 1] - r[2, 2]
    tz = 1.0 - r[0, 0] - r[1, 1] + r[2, 2]
    tw = 1.0 + r[0, 0] + r[1, 1] + r[2, 2]
    sxy, sxz, syz = r[0, 1] + r[1, 0], r[0, 2] + r[2, 0], r[1, 2] + r[2, 1]
    dx, dy, dz = r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]
    use_w = (tw >= tx) & (tw >= ty) & (tw >= tz)
    use_x = ~use_w & (tx >= ty) & (tx >= tz)
    use_y = ~use_w & ~use_x & (ty >= tz)

    def pick(if_w, if_x, if_y, if_z):
        return np.where(use_w, if_w, np.where(use_x, if_x, np.where(use_y, if_y, if_z)))

    q = np.stack([pick(dx, tx, sxy, sxz), pick(dy, sxy, ty, syz), pick(dz, sxz, syz, tz), pick(tw, dx, dy, dz)])
    # The sign flip for qw >= 0 rides along with the normalization.
    q *= np.where(q[3] < 0.0, -1.0, 1.0) / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q


def rotation_log(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return `(w, |w|^2, sin(|w|/2), cos(|w|/2))` for `w = Log(r)`, angle in [0, pi].

    Goes through the quaternion, which stays accurate near pi, where the textbook
    `t / (2 sin t) (R - R^T)^vee` (Sola eq. 133) loses the axis. `q = [sin(t/2) u, cos(t/2)]`,
    so the half-angle sine and cosine come for free.

    Args:
        r: component-first rotation matrices, `(3, 3, ...)`.

    Returns:
        `(3, ...)` and three `(...)` arrays.
    """
    q = rotation_to_quaternion(r)
    n = np.sqrt(sq_norm(q[:3]))
    w = (2.0 * atan2_ratio(n, q[3])) * q[:3]
    return w, sq_norm(w), n, q[3]
