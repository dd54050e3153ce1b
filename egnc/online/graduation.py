"""The graduation of an update's loop closures, stage by stage, on a region or the whole map.

The loops an update graduates start at their `mu_init` and move by the schedule's rule
(`risam`: riSAM's shared sequence; `egnc`: `0 -> mu*(r) -> 1`, or `0 -> 1` past the
strong-outlier line), one warm-started stage per `mu` (`egnc.online.stage`). The last stage
starts from the lower of the map the earlier stages bent and the map before the update, by their
cost at its `mu`. An update with a loop closure first graduates on the region around its new
edges (`egnc.online.region`) and falls back to the whole map when a loop ends on the other side
of the strong-outlier line than it began, or goes on over the whole map for its last stage when
the region's boundary would still move (`egnc.online.solver`'s module docstring has the why).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.graph.index_sets import sorted_unique
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE
from egnc.nonlinear.prior_factors import PriorFactors
from egnc.online.options import Settings
from egnc.online.region import LocalProblem, Neighbourhoods, block_jacobi_decrease
from egnc.online.stage import refresh_costs, solve_stage
from egnc.online.state import MapState, Saved
from egnc.robust.gnc import StageReport
from egnc.robust.losses import KernelLoss
from egnc.robust.mu_star import mu_star
from egnc.robust.schedules import exceeds

__all__ = ["WHOLE_MAP_SHARE", "Graduated", "Graduation"]

WHOLE_MAP_SHARE = 0.5
"""An update whose region holds more than this share of the poses solves the whole map instead."""


@dataclass(frozen=True, eq=False)
class Graduated:
    """What the stages of one update did (fields as in `egnc.online.report.UpdateReport`)."""

    reports: tuple[StageReport, ...]
    mu_history: np.ndarray
    residual_history: np.ndarray
    status: int
    cost: float = np.nan  # the whole map's kernel cost after the last stage, at its mu
    analysed: bool = False
    region_poses: int = 0
    whole_map: bool = False
    restarted: bool = False


class Graduation:
    """Graduates the loops of each update on `state`, by the schedule and options of `settings`."""

    def __init__(self, settings: Settings, state: MapState):
        self.settings, self.state = settings, state
        self.neighbourhoods = Neighbourhoods()  # grown with the edges before each region is drawn

    def loops_to_graduate(self, new_loops: np.ndarray) -> np.ndarray:
        """`(G,)` increasing factor indices: the candidates this update graduates from `mu_init`
        (`OnlineOptions.regraduate`), given its new ones `new_loops` (loop closures, then priors,
        `egnc.online.priors`); new candidates strong at arrival start at `mu = 1` instead
        (`OnlineOptions.strong_at_arrival`)."""
        state, online = self.state, self.settings.online_options
        graduating = new_loops
        if self.settings.method == "egnc" and online.strong_at_arrival:
            # EGNC's strong-outlier test after a solve, applied at the converged current estimate.
            strong = self._past(online.high_quantile, new_loops)
            state.mu_init[new_loops[strong]] = state.mu[new_loops[strong]] = 1.0
            graduating = new_loops[~strong]
        if len(new_loops) and online.regraduate == "reference":
            loops = state.loops
            graduating = sorted_unique(np.concatenate((graduating, loops[state.mu_init[loops] == 0.0])))
        return graduating

    def trusted(self) -> np.ndarray:
        """`(E,)` bool: the edges whose IRLS weight is at least `trust_weight` (the kernel is
        evaluated on the loop closures only; the other edges weigh 1). The linear layer trusts
        every prior (`egnc.nonlinear.prior_gauge.with_prior_products`)."""
        state, trust_weight = self.state, self.settings.options.trust_weight
        loops = state.loops[: np.searchsorted(state.loops, len(state.edges))]  # the priors follow
        trusted = np.full(len(state.edges), 1.0 >= trust_weight)
        weights = self.settings.kernel.weight(state.r[loops], state.mu[loops])
        trusted[loops] = weights >= trust_weight
        return trusted

    def run(
        self, graduating: np.ndarray, new_loops: np.ndarray, seeds: np.ndarray | None, trusted: np.ndarray
    ) -> Graduated:
        """Run the stages of one update around `seeds` (pose rows; None: the whole map) with the
        preconditioner of the `trusted` `(E,)` edges; `new_loops`: the update's new candidates
        (factor indices, `loops_to_graduate`)."""
        state, hops = self.state, self.settings.online_options.region_hops
        local = None
        neighbourhoods = self.neighbourhoods
        if seeds is not None and hops is not None:
            neighbourhoods.grow(state.edges, len(state.vertex_ids))
            # Hops go along the edges the map trusts (egnc.online.region.Neighbourhoods.within).
            local = self._local_problem(neighbourhoods.within(seeds, hops, trusted))
        if local is None:
            analysed = state.problem is None
            return replace(self._stages(None, graduating, new_loops, trusted), analysed=analysed, whole_map=True)
        region_poses = int(local.free.sum())
        before, mu_before = state.save(local), state.mu[graduating]  # the stages change mu there only
        was_far = self._far()
        in_region = replace(self._stages(local, graduating, new_loops, trusted), region_poses=region_poses)
        if in_region.status == NUMERICAL_FAILURE:
            return in_region
        if self._crossed(was_far, new_loops):
            state.restore(before)
            state.mu[graduating] = mu_before
            analysed = state.problem is None
            redone = self._stages(None, graduating, new_loops, trusted)
            return replace(
                redone,
                reports=in_region.reports + redone.reports,
                analysed=analysed,
                region_poses=region_poses,
                whole_map=True,
            )
        if self._boundary_strained(local, in_region.cost):
            # The region's boundary pulls on the rest: the whole map takes the last stage's steps
            # from the local optimum.
            analysed = state.problem is None
            last, _ = solve_stage(state, self.settings.kernel, None, self.settings.stage_options()[0], trusted, None)
            return replace(
                in_region, reports=in_region.reports + (last,), status=last.status, analysed=analysed, whole_map=True
            )
        return in_region

    def reset_mu_init(self) -> None:
        """After convergence: loops far off start at `mu = 1` next time, loops that fit at `mu = 0`."""
        state = self.state
        loops = state.loops
        state.mu_init[loops[self._far()]] = 1.0
        state.mu_init[loops[~self._past(self.settings.online_options.low_quantile, loops)]] = 0.0

    def _stages(
        self, local: LocalProblem | None, graduating: np.ndarray, new_loops: np.ndarray, trusted: np.ndarray
    ) -> Graduated:
        """Graduate the loops `graduating` (increasing edge indices) from `mu_init` on `local` (None: the whole map)."""
        state, kernel = self.state, self.settings.kernel
        tight, intermediate = self.settings.stage_options()
        state.mu[graduating] = state.mu_init[graduating]
        before = state.save(local)  # the map before the update
        # A region's stages keep the whole map's per-edge costs current where they change (its
        # edges, the loops whose mu moves), not over every edge of the map per stage.
        costs = None if local is None else KernelLoss(kernel, state.mu, state.robust).cost(state.r)
        restarted = False
        active = graduating[state.mu[graduating] < 1.0]  # loops whose mu still moves this update
        strong = np.zeros(len(active), dtype=bool)
        stage_index = 0
        reports: list[StageReport] = []
        history: list[np.ndarray] = []
        residuals: list[np.ndarray] = []
        errors = None  # the residuals where the last stage ended, which the next starts from
        while True:
            final = not np.any(state.mu[active] < 1.0)
            if final and stage_index > 0:
                restarted = self._start_from_lower(before, costs)
                errors = None if restarted else errors
            options = tight if final else intermediate
            solution, errors = solve_stage(state, kernel, local, options, trusted, costs, errors)
            reports.append(solution)
            history.append(state.mu[new_loops].copy())
            residuals.append(state.r[new_loops].copy())
            if final or solution.status == NUMERICAL_FAILURE:
                break
            stage_index += 1
            # EGNC's strong-outlier test uses the same chi-square 0.9 quantile as the mu_init reset.
            strong |= self._past(self.settings.online_options.high_quantile, active)
            state.mu[active] = self._next_mu(stage_index, active, strong)
            if costs is not None:
                refresh_costs(state, kernel, costs, active)
        shape = (len(history), len(new_loops))
        return Graduated(
            tuple(reports),
            np.array(history).reshape(shape),
            np.array(residuals).reshape(shape),
            reports[-1].status,
            cost=reports[-1].cost if costs is None else float(np.sum(costs)),
            restarted=restarted,
        )

    def _start_from_lower(self, before: Saved, costs: np.ndarray | None) -> bool:
        """Before the last stage: go back to the map `before` the update when it costs less at the
        current `mu` than the map the earlier stages bent (compared over the edges `before` holds:
        the others are the same in both); returns whether it did.

        `costs`: the region's per-edge costs `(E,)` (`_stages`), kept current."""
        state = self.state
        edges = slice(None) if before.factors is None else before.factors
        loss = KernelLoss(self.settings.kernel, state.mu[edges], state.robust[edges])
        if float(np.sum(loss.cost(before.r))) >= float(np.sum(loss.cost(state.r[edges]))):
            return False
        state.restore(before)
        if costs is not None and before.factors is not None:
            refresh_costs(state, self.settings.kernel, costs, before.factors)
        return True

    def _next_mu(self, stage_index: int, active: np.ndarray, strong: np.ndarray) -> np.ndarray:
        """The `mu` of the `active` loops (edge indices) at stage `stage_index` >= 1 of an
        update; `strong`: which of them were found strong outliers."""
        if self.settings.method == "risam":
            shared = 0.0
            for _ in range(stage_index):  # riSAM's heuristic from mu_init = 0
                shared = min(1.0, shared + 1.2 * (shared + 0.1))
            return np.full(len(active), shared)
        if stage_index >= 2:
            return np.ones(len(active))
        r = self.state.r[active]
        mu = np.ones(len(r))
        band = ~strong
        mu[band] = np.minimum(mu_star(r[band], self.settings.gnc_options.c), 1.0)
        return mu

    def _crossed(self, was_far: np.ndarray, new_loops: np.ndarray) -> bool:
        """Whether a region's stages ended a loop on the other side of the strong-outlier line
        than `was_far` (`_far()` before them) had it: an older loop either way, a new loop
        (`new_loops`, the last loops added) outwards. Held at its boundary, a region strains
        where the whole map would turn (`egnc.online.region`), so such a decision is the whole map's to
        make. Asked once the stages are done: a new loop's `mu = 0` stage bends the region and
        pushes older loops past the line for a stage, and the last stage, from the lower map,
        takes them back. A new loop that arrived past the line and ends inside it was taken by
        a region stiffer than the map; the boundary test decides whether the whole map takes
        the last stage on."""
        far = self._far()
        crossed = far != was_far
        new = np.isin(self.state.loops, new_loops)
        crossed[new] &= far[new]
        return bool(np.any(crossed))

    def _far(self) -> np.ndarray:
        """`(L,)` bool per candidate (`loops`): its residual is past the strong-outlier line (`high_quantile`)."""
        return self._past(self.settings.online_options.high_quantile, self.state.loops)

    def _past(self, quantile: float, edges: np.ndarray) -> np.ndarray:
        """`(K,)` bool: which factors `edges` `(K,)` have a residual above the chi-square
        `quantile` (at each factor's own dimension)."""
        state = self.state
        return exceeds(state.r[edges], quantile, state.dims(edges), self.settings.gnc_options.threshold)

    def _local_problem(self, region: np.ndarray) -> LocalProblem | None:
        """The local problem of `region` (pose rows); None (the whole map) when it holds most of it."""
        state = self.state
        if len(region) > WHOLE_MAP_SHARE * len(state.vertex_ids):
            return None
        return LocalProblem.build(
            region,
            self.neighbourhoods,
            state.factors(),
            state.held,
            self.settings.linear_solver,
            state.priors.factors(),
        )

    def _boundary_strained(self, local: LocalProblem, whole_cost: float) -> bool:
        """Whether the boundary poses' own Newton steps would lower the cost by more than
        `OnlineOptions.boundary_share` of the update's tolerance (`egnc.online.region.block_jacobi_decrease`), that
        is of `rel_cost_tol` times `whole_cost`, the whole map's kernel cost."""
        state = self.state
        boundary = local.boundary[local.boundary != state.held]
        if not len(boundary):
            return False
        edges = self.neighbourhoods.edges_of(boundary)
        weights = KernelLoss(self.settings.kernel, state.mu[edges], state.robust[edges]).weight(state.r[edges])
        decrease = block_jacobi_decrease(state.factors(), edges, state.T, weights, boundary, self._priors_on(boundary))
        tolerance = self.settings.stage_options()[0].rel_cost_tol * whole_cost
        return float(decrease.sum()) > self.settings.online_options.boundary_share * tolerance

    def _priors_on(self, rows: np.ndarray) -> tuple[PriorFactors, np.ndarray] | None:
        """The priors on the sorted pose `rows` and their `(Q,)` IRLS weights; None where there are none."""
        state = self.state
        factors = state.priors.factors()
        if factors is None:
            return None
        on = np.flatnonzero(np.isin(factors.rows, rows))
        indices = len(state.edges) + on
        weights = KernelLoss(self.settings.kernel, state.mu[indices], state.robust[indices]).weight(state.r[indices])
        return factors.subset(on), weights
