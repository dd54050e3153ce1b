"""One graduation stage of an online update: a warm-started IRLS solve at the loops' current `mu`.

A stage solves the whole map (`egnc.nonlinear.least_squares` on the map's problem, CG with the
preconditioner of the trusted edges) or a region's local problem (`egnc.online.region`), whose
poses and residuals it writes back into the map. A region's solve stops by the whole map's rule:
its relative tolerance is scaled by the whole map's cost over the region's, so both stop at the
same absolute decrease.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from egnc.nonlinear.factors import EdgeErrors
from egnc.nonlinear.least_squares import SolverOptions, SolverResult, solve_least_squares
from egnc.online.region import LocalProblem
from egnc.online.state import MapState
from egnc.robust.gnc import StageReport
from egnc.robust.kernels import Kernel
from egnc.robust.losses import KernelLoss

__all__ = ["refresh_costs", "solve_stage"]


def solve_stage(
    state: MapState,
    kernel: Kernel,
    local: LocalProblem | None,
    options: SolverOptions,
    trusted: np.ndarray,
    costs: np.ndarray | None,
    errors: EdgeErrors | None = None,
) -> tuple[StageReport, EdgeErrors | None]:
    """One stage at the current `mu`: the whole map (`local` None), or the local problem's
    poses, written into `state`'s estimate, with `costs` `(E + K,)`, the whole map's per-factor costs
    (`egnc.online.graduation`), kept current. `trusted`: `(E,)` bool, the preconditioner's
    edges. `errors`: the residuals of the same problem's edges at the poses the stage starts
    from, if known (where the stage before it ended).

    Returns:
        The stage's report, and the residuals where it ended.
    """
    started = time.perf_counter()
    if local is None:
        loss = KernelLoss(kernel, state.mu.copy(), state.robust)
        solution = solve_least_squares(
            state.current_problem(), state.T, loss, options, trusted=trusted, errors=errors, keep_errors=True
        )
        state.T, state.r = solution.poses, _factor_norms(solution)
        cost = solution.cost
    else:
        assert costs is not None, "a region's stages keep the whole map's costs"
        edges = local.factors
        # The stop rule of the whole map's solve: a decrease below rel_cost_tol of the whole cost.
        local_cost, whole_cost = float(np.sum(costs[edges])), float(np.sum(costs))
        # A region is small: one factorization of all its edges beats CG's preconditioner analysis.
        scaled = replace(
            options,
            rel_cost_tol=options.rel_cost_tol * whole_cost / max(local_cost, 1e-300),
            linear_method="direct",
        )
        loss = KernelLoss(kernel, state.mu[edges], state.robust[edges])
        solution = solve_least_squares(
            local.problem,
            state.T[local.rows],
            loss,
            scaled,
            trusted=trusted[local.edges],
            errors=errors,
            keep_errors=True,
        )
        state.T[local.rows] = solution.poses
        state.r[edges] = _factor_norms(solution)
        refresh_costs(state, kernel, costs, edges)
        cost = whole_cost - local_cost + solution.cost
    mu_loops = state.mu[state.loops]
    report = StageReport(
        float(mu_loops.min(initial=np.nan)) if len(mu_loops) else np.nan,
        float(mu_loops.mean()) if len(mu_loops) else np.nan,
        float(mu_loops.max(initial=np.nan)) if len(mu_loops) else np.nan,
        iterations=solution.iterations,
        cost=cost,
        time_s=time.perf_counter() - started,
        status=solution.status,
        active_edges=len(state.r) if local is None else len(local.factors),
        cg_iterations=solution.linear.cg_iterations,
    )
    return report, solution.errors


def _factor_norms(solution: SolverResult) -> np.ndarray:
    """The solve's whitened residual norms per factor: `(E,)` edges, then `(K,)` priors if any."""
    if solution.prior_norms is None:
        return solution.residual_norms
    return np.concatenate((solution.residual_norms, solution.prior_norms))


def refresh_costs(state: MapState, kernel: Kernel, costs: np.ndarray, edges: np.ndarray) -> None:
    """Recompute the per-factor kernel costs `costs` `(E + K,)` of `edges` (factor indices) at
    `state`'s current `r` and `mu`."""
    costs[edges] = KernelLoss(kernel, state.mu[edges], state.robust[edges]).cost(state.r[edges])
