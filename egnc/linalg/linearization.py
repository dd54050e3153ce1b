"""The linearization the normal equations are assembled from: residuals and Jacobians of every edge."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
