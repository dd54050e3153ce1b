"""Per-edge losses handed to the IRLS solver: which edges are robust, with which kernel and `mu`.

Both classes implement `egnc.nonlinear.least_squares.EdgeLoss` (`cost(r)` and `weight(r)` over all edges).
Known inliers (odometry, priors) always keep the quadratic `0.5 r^2` and weight 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from egnc.robust.kernels import Kernel


@dataclass(frozen=True, eq=False)
class KernelLoss:
    """Robust edges use `kernel` at a per-edge `mu`; the other edges are plain least squares.

    The solver reweights at every iteration (IRLS), as riSAM and EGNC do within a stage.

    Attributes:
        kernel: the robust kernel.
        mu: `(E,)` kernel parameter per edge (ignored by non-graduated kernels and known inliers).
        robust: `(E,)` bool, edges the kernel applies to.
    """

    kernel: Kernel
    mu: np.ndarray
    robust: np.ndarray

    def cost(self, r: np.ndarray) -> np.ndarray:
        """Per-edge cost `(E,)`; the kernel is evaluated on the robust edges only."""
        cost = 0.5 * r * r
        cost[self.robust] = self.kernel.rho(r[self.robust], self.mu[self.robust])
        return cost

    def weight(self, r: np.ndarray) -> np.ndarray:
        """Per-edge IRLS weight `(E,)`, the kernel's on the robust edges only."""
        weight = np.ones_like(r, dtype=np.float64)
        weight[self.robust] = self.kernel.weight(r[self.robust], self.mu[self.robust])
        return weight

    def subset(self, keep: np.ndarray) -> KernelLoss:
        """The same loss over the edges where `keep` `(E,)` is true."""
        return KernelLoss(self.kernel, self.mu[keep], self.robust[keep])


@dataclass(frozen=True, eq=False)
class FixedWeightLoss:
    """Weighted least squares `0.5 w r^2` with weights held fixed for a whole solve.

    This is the variable-update step of Yang et al.'s GNC (and GTSAM's `GncOptimizer`): weights are
    recomputed only between stages.

    Attributes:
        weights: `(E,)` weight per edge, in [0, 1].
    """

    weights: np.ndarray

    def cost(self, r: np.ndarray) -> np.ndarray:
        """Per-edge cost `(E,)`."""
        return 0.5 * self.weights * r * r

    def weight(self, r: np.ndarray) -> np.ndarray:
        """Per-edge weight `(E,)`, independent of `r`."""
        return self.weights

    def subset(self, keep: np.ndarray) -> FixedWeightLoss:
        """The same loss over the edges where `keep` `(E,)` is true."""
        return FixedWeightLoss(self.weights[keep])
