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
from types import ModuleType

import numpy as np

from egnc.graph import PoseGraph
from egnc.lie import se2, se3


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
class Linearization:
    """Residuals and Jacobians of every edge at one linearization point.

    Attributes:
        residuals: `(E, d)` tangent-space residuals `e`.
        J_e_xi: `(E, d, d)` Jacobian of `e` w.r.t. the right perturbation of `X_i`.
        J_e_xj: `(E, d, d)` Jacobian of `e` w.r.t. the right perturbation of `X_j`.
        stacked: `(E, d, 2d + 1)` `[J_e_xi | J_e_xj | e]`, the layout the normal equations are
            assembled from; built from the other three when not given (`linearize` fills it
            directly and the other three are views of it).
    """

    residuals: np.ndarray
    J_e_xi: np.ndarray
    J_e_xj: np.ndarray
    stacked: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.stacked is None:
            stacked = np.concatenate([self.J_e_xi, self.J_e_xj, self.residuals[:, :, None]], axis=2)
            object.__setattr__(self, "stacked", stacked)


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

    @classmethod
    def from_graph(cls, graph: PoseGraph) -> BetweenFactors:
        """Precompute measurement inverses for `graph`'s edges."""
        group = group_of(graph.dim)
        Z = to_matrices(graph.dim, graph.measurements)
        return cls(graph.dim, graph.edges, group.inverse(Z), graph.information)

    def evaluate(self, T: np.ndarray) -> EdgeErrors:
        """Residuals `e = Log(Z^-1 X_i^-1 X_j)` at poses `T` `(N, n, n)`, keeping `X_j^-1 X_i` for `linearize`."""
        group = group_of(self.dim)
        T_j_i = group.between(T[self.edges[:, 1]], T[self.edges[:, 0]])
        return EdgeErrors(group.log(self.Z_inv @ group.inverse(T_j_i)), T_j_i)

    def residuals(self, T: np.ndarray) -> np.ndarray:
        """Residuals `(E, d)` at poses `T` `(N, n, n)`."""
        return self.evaluate(T).residuals

    def whitened_norms(self, residuals: np.ndarray) -> np.ndarray:
        """Mahalanobis norms `r = sqrt(e^T Omega e)` `(E,)` of residuals `(E, d)`."""
        squared = np.einsum("ei,eij,ej->e", residuals, self.information, residuals)
        return np.sqrt(np.maximum(squared, 0.0))

    def linearize(self, T: np.ndarray, errors: EdgeErrors | None = None) -> Linearization:
        """Residuals and both Jacobians at poses `T` `(N, n, n)`.

        Args:
            T: `(N, n, n)` poses.
            errors: `evaluate(T)` if already computed (at these very poses), to reuse.
        """
        group = group_of(self.dim)
        errors = self.evaluate(T) if errors is None else errors
        e = errors.residuals
        d = e.shape[1]
        stacked = np.empty((len(e), d, 2 * d + 1))
        J_e_xj = stacked[:, :, d : 2 * d]
        J_e_xj[...] = group.right_jacobian_inverse(e)
        np.matmul(J_e_xj, group.adjoint(errors.T_j_i), out=stacked[:, :, :d])
        np.negative(stacked[:, :, :d], out=stacked[:, :, :d])
        stacked[:, :, 2 * d] = e
        return Linearization(stacked[:, :, 2 * d], stacked[:, :, :d], J_e_xj, stacked)
