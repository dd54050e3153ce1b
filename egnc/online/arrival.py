"""An online update's graduation stages, predicted from the map factorized after the last solve.

Between two online updates the map is converged. The loop closures an update brings start at
`mu = 0`, quadratic, and the first stage takes one Gauss-Newton step of the whole map with them.
With the new loops' stacked residual `e`, Jacobian `A` (on their poses), information `Omega` and
IRLS weights `w` (`c^2 / (c^2 + 1)` at `mu = 0`), and the map's information `H`, that step is the
Kalman update of the map by the loops:

    dx = -H^-1 A^T S^-1 e,    S = (w Omega)^-1 + A H^-1 A^T

`ConvergedMap` keeps a factorization of `H` from the end of the last whole-map solve, so the step
costs solves with `K d` right-hand sides instead of a linearization, a factorization and CG of the
grown system. `FirstStage` holds the result: every edge's whitened residual at the stepped poses,
evaluated on the manifold, not linearly (on manhattanOlson3500 the linear model put false loops'
residuals after the step a median 300 times below the solved stage's: the map cannot turn that
far in one real step), from which EGNC's strong-outlier rule reads which new loops the stage
would find strong.

Two more questions need only `C = A H^-1 A^T` (`FirstStage.map_covariance`):
- where the last stage, at `mu = 1` from the bent map, leaves the new loops when the rest of the
  map's loops hold their weights: IRLS of the new loops alone, whose weights `w` pull the map to
  where they keep the residual `e(w) = W^-1 (W^-1 + C)^-1 e`, `W = blockdiag(w_k Omega_k)`
  (`FirstStage.last_stage`);
- what the new loops' pull costs: loops of IRLS weights `w` lower the cost by at most
  `0.5 v^T C v`, `v = w Omega e`, in one step (its decrease without the loops' own curvature).

Poses added after the map was factorized hang off it by odometry alone: the online solver places
a new pose by composing its odometry, so that edge has zero residual and its linearization
`J_p xi_p + J_c xi_c = nu` gives the new pose's tangent `xi_c = M xi_p - J_c^-1 nu`, with
`M = -J_c^-1 J_p` and noise of covariance `Q = J_c^-1 Omega^-1 J_c^-T`, composed along the chain
to a pose of the factorized map: the map's marginal of a dangling chain, exactly. Edges added
since that are not used to place a pose (a loop left at a negligible weight, a zero-residual
odometry edge between placed poses) are left out of `H`. The new loops' ends may hang; when they
hang on more than one pose, or a loop hangs at both ends, the stage is not predicted.

Reference:
    M. Kaess, F. Dellaert, "Covariance recovery from a square root information matrix for data
    association", RAS 2009 (innovation covariances of candidate measurements from a factorization).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from egnc.linalg.linear_solvers import Factorization
from egnc.linalg.normal_equations import NormalEquationsPattern, edge_products
from egnc.nonlinear.factors import BetweenFactors, group_of
from egnc.nonlinear.least_squares import Problem
from egnc.nonlinear.marginals import transposed_jacobians

__all__ = ["ConvergedMap", "FirstStage"]

_LAST_STAGE_ITERATIONS = 100
"""IRLS iterations of `FirstStage.last_stage` at most (each a `K d` solve)."""


@dataclass(frozen=True, eq=False)
class FirstStage:
    """An update's first stage predicted from the converged map (module docstring).

    Attributes:
        residual_norms: `(E,)` whitened residual norm of every edge after the step.
        residuals: `(K, d)` the new loops' residuals before it.
        map_covariance: `(K d, K d)` `A H^-1 A^T` of the new loops, hung chains' noise included.
    """

    residual_norms: np.ndarray
    residuals: np.ndarray
    map_covariance: np.ndarray

    def last_stage(
        self, information: np.ndarray, weight: Callable[[np.ndarray], np.ndarray], start: np.ndarray
    ) -> np.ndarray:
        """`(K,)` the new loops' residual norms where IRLS of them alone settles, in the linear model of the map.

        The map's cost is `0.5 dx^T H dx` around where it stands; each new loop, weighted
        `w_k = weight(r_k)`, pulls it to `dx(w) = -H^-1 A^T S(w)^-1 e` with
        `S(w) = (W)^-1 + A H^-1 A^T`, `W = blockdiag(w_k Omega_k)`, where the loops keep
        `e(w) = W^-1 S(w)^-1 e`. Iterated from the residual norms `start` `(K,)` until the
        weights settle: the last stage of the update with the rest of the map's loops held at
        their weights.

        Args:
            information: `(K, d, d)` the loops' information matrices.
            weight: the IRLS weight of a residual norm at the last stage's `mu`.
            start: `(K,)` residual norms the last stage starts from (after the first stage).
        """
        K, d = self.residuals.shape
        block = np.arange(K)[:, None] * d + np.arange(d)
        covariance = np.linalg.inv(information)
        r, w = start, weight(start)
        for _ in range(_LAST_STAGE_ITERATIONS):
            loose = np.zeros_like(self.map_covariance)
            loose[block[:, :, None], block[:, None, :]] = covariance / np.maximum(w, 1e-300)[:, None, None]
            kept = (loose @ np.linalg.solve(loose + self.map_covariance, self.residuals.ravel())).reshape(K, d)
            r = np.sqrt(np.einsum("ki,kij,kj->k", kept, information, kept))
            settled, w = w, weight(r)
            if np.max(np.abs(w - settled)) <= 1e-9:
                break
        return r

    def largest_decrease(self, weights: np.ndarray, information: np.ndarray) -> float:
        """An upper bound of the cost decrease one step of the map towards the new loops would make.

        Args:
            weights: `(K,)` the loops' IRLS weights.
            information: `(K, d, d)` their information matrices.
        """
        pull = (weights[:, None] * np.einsum("kij,kj->ki", information, self.residuals)).ravel()
        return 0.5 * float(pull @ self.map_covariance @ pull)


@dataclass(frozen=True, eq=False)
class ConvergedMap:
    """The factorization of the map's information `H` as it stood after a whole-map solve.

    It stays valid while no solve of the same problem factorizes its trusted set again: the
    online solver builds a new problem whenever the graph grows, before its next solve.

    Attributes:
        factorization: `x -> H^-1 x` over the unknowns of `pattern`.
        pattern: the map's normal-equations pattern then (its `free_index` and `size`).
        num_poses: poses the map had (the first `num_poses` rows of the growing graph).
        num_edges: edges it had (the first `num_edges`).
        trusted: `(num_edges,)` bool, the edges in `H`, each at its IRLS weight.
    """

    factorization: Factorization = field(repr=False)
    pattern: NormalEquationsPattern = field(repr=False)
    num_poses: int
    num_edges: int
    trusted: np.ndarray = field(repr=False)

    @classmethod
    def factorize(
        cls, problem: Problem, poses: np.ndarray, weights: np.ndarray, trusted: np.ndarray
    ) -> ConvergedMap | None:
        """Factorize `H = sum_trusted w J^T Omega J` of `problem` at `poses` `(N, n, n)`.

        Args:
            problem: the map's problem; its step solver's analysis of `trusted` is reused.
            poses: the converged estimate.
            weights: `(E,)` IRLS weights there.
            trusted: `(E,)` bool, the edges to include (switched-off loops would add almost nothing).

        Returns:
            None when those edges leave a pose unconstrained or `H` is not positive definite.
        """
        factors = problem.factors
        products = edge_products(factors.linearize(poses), factors.information, weights)
        factorization = problem.step_solver.trusted_factorization(products, trusted)
        if factorization is None:
            return None
        return cls(factorization, problem.pattern, len(poses), len(factors.edges), trusted.copy())

    def first_stage(
        self, factors: BetweenFactors, poses: np.ndarray, robust: np.ndarray, loops: np.ndarray, weights: np.ndarray
    ) -> FirstStage | None:
        """Predict the first stage of the new loop closures `loops` `(K,)` (indices into `factors`).

        Args:
            factors: every edge of the grown graph (the map's edges first, in the same order).
            poses: `(N, n, n)` the current estimate: the map's poses where they were factorized,
                the poses added since placed by their odometry.
            robust: `(E,)` bool, loop closures (never used to place a pose).
            loops: the new loop closures.
            weights: `(K,)` their IRLS weights in the first stage (at `mu = 0`, `c^2 / (c^2 + 1)`).

        Returns:
            None where it is not predicted (module docstring).
        """
        root, M, Q = self._hung(factors, poses, robust)
        ends = factors.edges[loops]
        hung = ends[ends >= self.num_poses]
        if np.any(root[ends] < 0) or np.any(np.all(ends >= self.num_poses, axis=1)) or len(np.unique(hung)) > 1:
            return None
        d = factors.information.shape[-1]
        linearization = factors.subset(loops).linearize(poses)
        J = np.stack([linearization.J_e_xi, linearization.J_e_xj], axis=1)  # (K, 2, d, d)
        B = transposed_jacobians(self.pattern, root[ends], J @ M[ends])  # on the roots' tangents
        X = self.factorization(B.toarray()) if self.pattern.size else np.zeros(B.shape)
        # The hung pose's own noise: Cov(J_k n, J_l n) = J_k Q J_l^T for the loops that end on it.
        J_hung = np.where((ends >= self.num_poses)[:, :, None, None], J, 0.0).sum(axis=1)  # (K, d, d)
        slack = Q[hung[0]] if len(hung) else np.zeros((d, d))
        noise = np.einsum("kab,bc,ldc->kald", J_hung, slack, J_hung).reshape(B.shape[1], B.shape[1])
        covariance = np.asarray(B.T @ X) + noise
        covariance = 0.5 * (covariance + covariance.T)
        own = np.zeros_like(covariance)
        block = np.arange(len(loops))[:, None] * d + np.arange(d)
        own[block[:, :, None], block[:, None, :]] = np.linalg.inv(weights[:, None, None] * factors.information[loops])
        e = linearization.residuals
        y = np.linalg.solve(covariance + own, e.ravel())
        step = -(X @ y).reshape(-1, d)  # the map's unknown blocks
        tangents = self._tangents(len(poses), step, root, M)
        if len(hung):
            tangents[hung[0]] -= slack @ (J_hung.reshape(-1, d).T @ y)  # its own noise's share of the step
        moved = group_of(factors.dim).rplus(poses, tangents)
        return FirstStage(factors.whitened_norms(factors.residuals(moved)), e, covariance)

    def _tangents(self, num_poses: int, step: np.ndarray, root: np.ndarray, M: np.ndarray) -> np.ndarray:
        """`(N, d)` tangent steps of every pose for the map's `step` `(m, d)` (one row per unknown
        block): hung poses follow their root through `M`, poses not hung stay."""
        free_index = self.pattern.free_index
        root_step = np.zeros((num_poses, step.shape[1]))
        placed = np.flatnonzero(root >= 0)
        index = free_index[root[placed]]
        root_step[placed[index >= 0]] = step[index[index >= 0]]
        return np.einsum("kab,kb->ka", M, root_step)

    def _hung(self, factors: BetweenFactors, poses: np.ndarray, robust: np.ndarray) -> tuple[np.ndarray, ...]:
        """`(root, M, Q)` of every pose `(N,)`, `(N, d, d)`, `(N, d, d)`: a pose's tangent is
        `M xi_root + n`, `n` of covariance `Q`; `root` -1 for a pose not hung (module docstring)."""
        num_poses, d = len(poses), factors.information.shape[-1]
        root = np.full(num_poses, -1, dtype=np.int64)
        root[: self.num_poses] = np.arange(self.num_poses)
        M = np.zeros((num_poses, d, d))
        M[: self.num_poses] = np.eye(d)
        Q = np.zeros((num_poses, d, d))
        later = np.arange(self.num_edges, len(factors.edges))
        odometry = later[~robust[later]]
        if not len(odometry):
            return root, M, Q
        linearization = factors.subset(odometry).linearize(poses)
        covariance = np.linalg.inv(factors.information[odometry])
        for k, (i, j) in enumerate(factors.edges[odometry].tolist()):
            if root[i] >= 0 and root[j] < 0:
                parent, child, J_parent, J_child = i, j, linearization.J_e_xi[k], linearization.J_e_xj[k]
            elif root[j] >= 0 and root[i] < 0:
                parent, child, J_parent, J_child = j, i, linearization.J_e_xj[k], linearization.J_e_xi[k]
            else:
                continue
            J_child_inv = np.linalg.inv(J_child)
            step = -J_child_inv @ J_parent
            root[child] = root[parent]
            M[child] = step @ M[parent]
            Q[child] = step @ Q[parent] @ step.T + J_child_inv @ covariance[k] @ J_child_inv.T
        return root, M, Q
