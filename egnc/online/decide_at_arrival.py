"""`OnlineOptions.decide_at_arrival`: end an update where it starts when its stages would.

An update whose only change is new loop closures has its first stage predicted from the map
factorized after the last whole-map solve (`egnc.online.arrival`). When that stage would leave
every new loop strong, the bent map would cost no less at `mu = 1` than the map before it, the
last stage predicted from there lets the new loops go, and their pull on the map is below the
update's tolerance, the update is decided at arrival: its new loops are set to `mu = 1` and
nothing is solved.
"""

from __future__ import annotations

import numpy as np

from egnc.nonlinear.least_squares import Problem
from egnc.online.arrival import ConvergedMap, FirstStage
from egnc.online.options import Settings
from egnc.online.state import MapState
from egnc.robust.losses import KernelLoss
from egnc.robust.schedules import exceeds

__all__ = ["ArrivalDecision"]


class ArrivalDecision:
    """Predicts updates from the factorized map of `state` and decides them where it can.

    Attributes:
        converged: the map as factorized after its last whole-map solve (or before the first
            update predicted), None where there is none.
    """

    def __init__(self, settings: Settings, state: MapState):
        self.settings, self.state = settings, state
        self.converged: ConvergedMap | None = None

    def first_stage(self, new_loops: np.ndarray, num_old_poses: int, num_old_edges: int) -> FirstStage | None:
        """The update's first stage predicted from the map factorized after the last whole-map
        solve, or, when there is none, from the map as it was before this update (its first
        `num_old_poses` poses and `num_old_edges` edges); None where not predicted."""
        state, kernel = self.state, self.settings.kernel
        if not len(new_loops) or not self.settings.predicts_first_stage or state.num_priors:
            return None  # a map with priors is not predicted: `ConvergedMap` factorizes edges only
        if self.converged is None and not num_old_edges:  # no map to predict from yet
            return None
        if self.converged is None:
            old = np.arange(num_old_edges)
            weights = KernelLoss(kernel, state.mu[old], state.robust[old]).weight(state.r[old])
            problem = state.prefix_problem(num_old_poses, num_old_edges)
            self.converged = self.factorize(weights >= self.settings.options.trust_weight, problem)
        if self.converged is None:
            return None
        weights = kernel.weight(state.r[new_loops], np.zeros(len(new_loops)))
        return self.converged.first_stage(state.factors(), state.T, state.robust, new_loops, weights)

    def decided(self, new_loops: np.ndarray, first: FirstStage) -> bool:
        """Whether the update would end where it starts, with its new loops off: the predicted
        first stage finds every new loop strong (EGNC then weighs them at `mu = 1` from the stage's
        bent map), the bent map costs no less at `mu = 1` than the map before it (the last stage
        would not descend from lower ground than the start), the new loops' IRLS from there with
        the rest of the map held lets them go (`FirstStage.last_stage`), and their pull on the map
        as it stands would lower the cost by less than the last stage's tolerance."""
        state, settings = self.state, self.settings
        high, threshold = settings.online_options.high_quantile, settings.gnc_options.threshold
        far = exceeds(first.residual_norms, high, settings.d, threshold)
        if not far[new_loops].all():
            return False
        mu = state.mu.copy()
        mu[new_loops] = 1.0
        loss = KernelLoss(settings.kernel, mu, state.robust)
        cost = float(np.sum(loss.cost(state.r)))
        if float(np.sum(loss.cost(first.residual_norms))) < cost:
            return False
        information = state.information[new_loops]
        settled = first.last_stage(information, loss.subset(new_loops).weight, first.residual_norms[new_loops])
        if not exceeds(settled, high, settings.d, threshold).all():
            return False
        weights = loss.subset(new_loops).weight(state.r[new_loops])
        bound = first.largest_decrease(weights, information)
        return bound <= settings.stage_options()[0].rel_cost_tol * cost

    def factorize(self, trusted: np.ndarray, problem: Problem | None = None) -> ConvergedMap | None:
        """The map's information factorized at the current estimate over the `trusted` `(E',)`
        edges (its first `E'`), for the next updates' predictions; `problem`: the map's (default:
        the current one). None when updates are not predicted (nor once the map holds priors)."""
        state = self.state
        if not self.settings.predicts_first_stage or state.num_priors:
            return None
        problem = problem or state.current_problem()
        num_edges = len(trusted)
        weights = KernelLoss(self.settings.kernel, state.mu[:num_edges], state.robust[:num_edges]).weight(
            state.r[:num_edges]
        )
        return ConvergedMap.factorize(problem, state.T[: problem.num_poses], weights, trusted)
