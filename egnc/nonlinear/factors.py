"""Vectorized between-factors: residuals and Jacobians for all edges at once.

An edge `(i, j, Z_ij, Omega_ij)` has the residual (right perturbation, DESIGN.md section 1)

    e_ij = Log(Z_ij^-1 X_i^-1 X_j)                                        `(d,)`

With `X <- X Exp(delta)` on both poses, writing `E = Z_ij^-1 X_i^-1 X_j`:

    J_e_xj =  Jr^-1(e)                          (perturbing X_j: E Exp(delta_j))
    J_e_xi = -Jr^-1(e) Ad(X_j^-1 X_i)           (perturbing X_i: Exp(-delta_i) moved to the right)

The whitened residual norm is `r = sqrt(e^T Omega e)`.

References:
    J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in robotics",
    2018 (eqs. 41, 44 and the right Jacobians of appendices A-D).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from types import ModuleType

import numpy as np

from egnc.graph import PoseGraph
from egnc.lie import se2, se3
from egnc.linalg.linearization import Linearization


def group_of(dim: int) -> ModuleType:
    """Return the Lie-group module for poses in `dim` = 2 or 3 dimensions."""
    return se2 if dim == 2 else se3


def to_matrices(dim: int, params: np.ndarray) -> np.ndarray:
    """Stored pose parameters `(..., P)` to homogeneous matrices `(..., n, n)`."""
    return se2.from_xytheta(params) if dim == 2 else se3.from_xyz_quat(params)


def from_matrices(dim: int, matrices: np.ndarray) -> np.ndarray:
    """Homogeneous matrices `(..., n, n)` to stored pose parameters `(..., P)`."""
    return se2.to_xytheta(matrices) if dim == 2 else se3.to_xyz_quat(matrices)


@dataclass(frozen=True, eq=False)
class EdgeErrors:
    """Residuals of every edge at one set of poses, with what `linearize` reuses from them.

    Attributes:
        residuals: `(E, d)` tangent-space residuals `e`.
        T_j_i: `(E, n, n)` relative poses `X_j^-1 X_i`.
    """

    residuals: np.ndarray
    T_j_i: np.ndarray


@dataclass(frozen=True, eq=False)
class BetweenFactors:
    """All relative-pose factors of a graph, ready for vectorized evaluation.

    Attributes:
        dim: 2 or 3.
        edges: `(E, 2)` pose row indices `(i, j)`.
        Z_inv: `(E, n, n)` inverses of the measured relative poses.
        information: `(E, d, d)` information matrices `Omega`.
    """

    dim: int
    edges: np.ndarray
    Z_inv: np.ndarray
    information: np.ndarray

    @cached_property
    def _quadratic_form(self) -> np.ndarray:
        """`(d, d, E)` copy of `information` with the off-diagonal entries doubled, for
        `whitened_norms`; made on first use, so that a graph's factors cost nothing to build."""
        d = self.information.shape[-1]
        return np.ascontiguousarray(np.moveaxis(self.information, 0, -1) * (2.0 - np.eye(d)[:, :, None]))

    @classmethod
    def from_graph(cls, graph: PoseGraph) -> BetweenFactors:
        """Precompute measurement inverses for `graph`'s edges."""
        group = group_of(graph.dim)
        Z = to_matrices(graph.dim, graph.measurements)
        return cls(graph.dim, graph.edges, group.inverse(Z), graph.information)

    def subset(self, keep: np.ndarray) -> BetweenFactors:
        """The factors of the edges `keep` selects (an `(E,)` bool mask or increasing indices), in edge order."""
        return BetweenFactors(self.dim, self.edges[keep], self.Z_inv[keep], self.information[keep])

    def evaluate(self, T: np.ndarray) -> EdgeErrors:
        """Residuals `e = Log(Z^-1 X_i^-1 X_j)` at poses `T` `(N, n, n)`, keeping `X_j^-1 X_i` for `linearize`."""
        if self.dim == 2:
            return self._evaluate_se2(T)
        T_j_i = se3.between(T[self.edges[:, 1]], T[self.edges[:, 0]])
        return EdgeErrors(se3.log(self.Z_inv @ se3.inverse(T_j_i)), T_j_i)

    def residuals(self, T: np.ndarray) -> np.ndarray:
        """Residuals `(E, d)` at poses `T` `(N, n, n)`."""
        return self.evaluate(T).residuals

    def whitened_norms(self, residuals: np.ndarray) -> np.ndarray:
        """Mahalanobis norms `r = sqrt(e^T Omega e)` `(E,)` of residuals `(E, d)`."""
        # sum_a e_a (Omega_aa e_a + sum_{b > a} 2 Omega_ab e_b) on `(E,)` columns: no (E, d, d) temporaries.
        e, form = residuals.T, self._quadratic_form
        squared = np.zeros(len(residuals))
        for a in range(len(e)):
            inner = form[a, a] * e[a]
            for b in range(a + 1, len(e)):
                inner += form[a, b] * e[b]
            squared += inner * e[a]
        return np.sqrt(np.maximum(squared, 0.0))

    def linearize(self, T: np.ndarray, errors: EdgeErrors | None = None) -> Linearization:
        """Residuals and both Jacobians at poses `T` `(N, n, n)`.

        Args:
            T: `(N, n, n)` poses.
            errors: `evaluate(T)` if already computed (at these very poses), to reuse.
        """
        errors = self.evaluate(T) if errors is None else errors
        e = errors.residuals
        d = e.shape[1]
        stacked = np.empty((len(e), d, 2 * d + 1))
        if self.dim == 2:
            self._jacobians_se2(errors, stacked)
        else:
            J_e_xj = stacked[:, :, d : 2 * d]
            J_e_xj[...] = se3.right_jacobian_inverse(e)
            np.matmul(J_e_xj, se3.adjoint(errors.T_j_i), out=stacked[:, :, :d])
            np.negative(stacked[:, :, :d], out=stacked[:, :, :d])
        stacked[:, :, 2 * d] = e
        return Linearization(stacked[:, :, 2 * d], stacked[:, :, :d], stacked[:, :, d : 2 * d], stacked)

    # SE(2) has few enough components to write out: working on `(E,)` component arrays skips
    # the (E, 3, 3) temporaries of the generic path (3x less time on city10000).

    def _evaluate_se2(self, T: np.ndarray) -> EdgeErrors:
        """`evaluate` for SE(2), on the components `(cos, sin, x, y)` of the poses."""
        c, s, x, y = T[:, 0, 0], T[:, 1, 0], T[:, 0, 2], T[:, 1, 2]
        i, j = self.edges[:, 0], self.edges[:, 1]
        c_i, s_i, c_j, s_j = c[i], s[i], c[j], s[j]
        dx, dy = x[j] - x[i], y[j] - y[i]
        # X_i^-1 X_j = (R_i^T R_j, R_i^T (t_j - t_i)).
        c_ij, s_ij = c_i * c_j + s_i * s_j, c_i * s_j - s_i * c_j
        x_ij, y_ij = c_i * dx + s_i * dy, c_i * dy - s_i * dx
        # Z^-1 X_i^-1 X_j.
        zc, zs, zx, zy = self.Z_inv[:, 0, 0], self.Z_inv[:, 1, 0], self.Z_inv[:, 0, 2], self.Z_inv[:, 1, 2]
        e = se2.log_components(
            zc * c_ij - zs * s_ij, zs * c_ij + zc * s_ij, zc * x_ij - zs * y_ij + zx, zs * x_ij + zc * y_ij + zy
        )
        # X_j^-1 X_i = (X_i^-1 X_j)^-1 = (R_ij^T, -R_ij^T t_ij).
        T_j_i = np.zeros((len(i), 3, 3))
        T_j_i[:, 0, 0] = T_j_i[:, 1, 1] = c_ij
        T_j_i[:, 0, 1], T_j_i[:, 1, 0] = s_ij, -s_ij
        T_j_i[:, 0, 2] = -(c_ij * x_ij + s_ij * y_ij)
        T_j_i[:, 1, 2] = s_ij * x_ij - c_ij * y_ij
        T_j_i[:, 2, 2] = 1.0
        return EdgeErrors(np.stack(e, axis=1), T_j_i)

    @staticmethod
    def _jacobians_se2(errors: EdgeErrors, stacked: np.ndarray) -> None:
        """Write `J_e_xi` and `J_e_xj` of SE(2) into `stacked[:, :, :6]`."""
        e, T_j_i = errors.residuals, errors.T_j_i
        a, h, p, q = se2.right_jacobian_inverse_components(e[:, 0], e[:, 1], e[:, 2])
        # J_e_xj = Jr^-1 = [[a, -h, p], [h, a, q], [0, 0, 1]].
        stacked[:, 0, 3], stacked[:, 0, 4], stacked[:, 0, 5] = a, -h, p
        stacked[:, 1, 3], stacked[:, 1, 4], stacked[:, 1, 5] = h, a, q
        stacked[:, 2, 3:6] = (0.0, 0.0, 1.0)
        # J_e_xi = -Jr^-1 Ad(X_j^-1 X_i), Ad = [[c, -s, t_y], [s, c, -t_x], [0, 0, 1]] (Sola eq. 159).
        c, s, tx, ty = T_j_i[:, 0, 0], T_j_i[:, 1, 0], T_j_i[:, 0, 2], T_j_i[:, 1, 2]
        stacked[:, 0, 0] = h * s - a * c
        stacked[:, 0, 1] = a * s + h * c
        stacked[:, 0, 2] = -(a * ty + h * tx + p)
        stacked[:, 1, 0] = -(h * c + a * s)
        stacked[:, 1, 1] = h * s - a * c
        stacked[:, 1, 2] = a * tx - h * ty - q
        stacked[:, 2, 0:3] = (0.0, 0.0, -1.0)
