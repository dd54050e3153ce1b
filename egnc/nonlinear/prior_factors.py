"""Vectorized unary factors: residuals and Jacobians of every prior at once (`egnc.graph.priors`).

With the right perturbation `X <- X Exp(delta)`, `delta = [v, omega]` (translation first):

- pose prior, `e = Log(Z^-1 X)` `(d,)`: `J_e_x = Jr^-1(e)` (Sola et al. eq. 41 with `Z^-1` constant);
- position prior, `e = t - z` `(dim,)`: `t <- t + R v`, so `J_e_x = [R, 0]`.

Residuals are padded to `d` (a position prior's trailing entries are zero, its Jacobian rows
zero too, and so is its information there: `Priors`), so that every prior is one row of the same
arrays and enters the normal equations like an edge from a fixed virtual pose: `linearize`
returns the between-factor layout `[J_e_xi | J_e_xj | e]` with `J_e_xi = 0`.

References:
    J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in robotics", 2018.
    F. Dellaert et al., GTSAM: `PriorFactor<Pose3>` and `GPSFactor` residuals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.graph.priors import POSE, Priors
from egnc.lie import se2, se3
from egnc.linalg.linearization import Linearization
from egnc.nonlinear.factors import to_matrices


@dataclass(frozen=True, eq=False)
class PriorFactors:
    """All priors of a graph, ready for vectorized evaluation.

    Attributes:
        dim: 2 or 3.
        rows: `(K,)` pose row of each prior.
        is_pose: `(K,)` bool, pose priors (the others are position priors).
        Z_inv: `(K, n, n)` inverses of the measured poses (identity for a position prior).
        z: `(K, dim)` measured positions (a pose prior's translation; unused for it).
        information: `(K, d, d)` padded information matrices.
    """

    dim: int
    rows: np.ndarray
    is_pose: np.ndarray
    Z_inv: np.ndarray
    z: np.ndarray
    information: np.ndarray

    @classmethod
    def from_priors(cls, priors: Priors) -> PriorFactors:
        """Precompute measurement inverses."""
        dim = priors.dim
        is_pose = priors.kinds == POSE
        measurements = priors.measurements.copy()
        if dim == 3:
            measurements[~is_pose, 6] = 1.0  # a position prior's unused quaternion: the identity
        else:
            measurements[~is_pose, 2] = 0.0
        group = se2 if dim == 2 else se3
        Z_inv = group.inverse(to_matrices(dim, measurements))
        return cls(dim, priors.rows, is_pose, Z_inv, priors.measurements[:, :dim], priors.information)

    def __len__(self) -> int:
        return len(self.rows)

    def subset(self, keep: np.ndarray, rows: np.ndarray | None = None) -> PriorFactors:
        """The priors `keep` selects (`(K,)` bool mask or indices), on the pose rows `rows` of
        another numbering (e.g. a local problem's; default: their own)."""
        rows = self.rows[keep] if rows is None else rows
        return PriorFactors(self.dim, rows, self.is_pose[keep], self.Z_inv[keep], self.z[keep], self.information[keep])

    @property
    def tangent_dim(self) -> int:
        """Tangent dimension d: 3 in 2D, 6 in 3D."""
        return 3 if self.dim == 2 else 6

    def residuals(self, T: np.ndarray) -> np.ndarray:
        """Padded residuals `(K, d)` at poses `T` `(N, n, n)`."""
        d, dim = self.tangent_dim, self.dim
        X = T[self.rows]
        e = np.zeros((len(self.rows), d))
        group = se2 if dim == 2 else se3
        e[self.is_pose] = group.log(self.Z_inv[self.is_pose] @ X[self.is_pose])
        position = ~self.is_pose
        e[position, :dim] = X[position, :dim, dim] - self.z[position]
        return e

    def whitened_norms(self, residuals: np.ndarray) -> np.ndarray:
        """Mahalanobis norms `r = sqrt(e^T Omega e)` `(K,)` of padded residuals `(K, d)`."""
        squared = np.einsum("ka,kab,kb->k", residuals, self.information, residuals)
        return np.sqrt(np.maximum(squared, 0.0))

    def linearize(self, T: np.ndarray) -> Linearization:
        """Residuals and Jacobians at poses `T` `(N, n, n)`, laid out as edges from a fixed pose:
        `J_e_xi = 0` `(K, d, d)`, `J_e_xj` the prior's Jacobian."""
        d, dim = self.tangent_dim, self.dim
        e = self.residuals(T)
        stacked = np.zeros((len(e), d, 2 * d + 1))
        J = stacked[:, :, d : 2 * d]
        group = se2 if dim == 2 else se3
        J[self.is_pose] = group.right_jacobian_inverse(e[self.is_pose])
        position = ~self.is_pose
        J[position, :dim, :dim] = T[self.rows[position], :dim, :dim]
        stacked[:, :, 2 * d] = e
        return Linearization(stacked[:, :, 2 * d], stacked[:, :, :d], J, stacked)


def prior_cost(priors: Priors, poses: np.ndarray) -> float:
    """`0.5 sum r^2` of `priors` at stored pose parameters `poses` `(N, P)`; 0.0 without priors."""
    if not len(priors):
        return 0.0
    factors = PriorFactors.from_priors(priors)
    return float(0.5 * np.sum(factors.whitened_norms(factors.residuals(to_matrices(priors.dim, poses))) ** 2))
