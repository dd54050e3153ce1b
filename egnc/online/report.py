"""What online updates did: one `UpdateReport` per update, and the `UpdateLog` of them all."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from egnc.robust.gnc import StageReport

__all__ = ["UpdateLog", "UpdateReport"]


@dataclass(frozen=True, eq=False)
class UpdateReport:
    """What one `OnlineSolver.update()` did.

    Attributes:
        step: 1-based number of the update.
        new_poses: poses added by the update.
        new_edges: `(K,)` indices of the edges it added (odometry and loops, in insertion order).
        new_loops: `(L,)` indices of the loop closures it added.
        new_priors: `(Q,)` prior indices of the measurement priors it added (`add_pose_prior`, ...).
        decided_at_arrival: whether the update solved nothing because its stages, predicted from
            the map factorized after the last solve, would end where it started with its new loops
            off (`OnlineOptions.decide_at_arrival`); its new loops are then at `mu = 1`.
        graduated: candidates graduated by the update (the new loop closures and candidate priors
            and, with `regraduate="reference"`, older ones whose `mu_init` is 0).
        stages: one report per solve (empty when nothing needed solving or `decided_at_arrival`).
        mu_history: `(S, L')` `mu` of each new candidate in each stage: the new loop closures,
            then the new candidate priors.
        residual_history: `(S, L')` whitened residual norm `r` of each new candidate after
            each stage (what the next stage's `mu` was chosen from).
        iterations: accepted solver steps over the stages.
        time_s: wall time of the update in seconds.
        reanalysed: whether the whole map's system was re-analysed (ordering and symbolic
            factorization).
        region_poses: poses the update solved as a local region (`egnc.online.region`); 0 when it
            solved nothing or only the whole map.
        whole_map: whether a stage solved the whole map (no region, or a fall-back from one).
        restarted: whether the last stage started from the map before the update, which cost
            less at the last stage's `mu` than the map the earlier stages had bent.
        status: termination code of the last solve (`egnc.nonlinear.least_squares.STATUS_MESSAGES`); -1 when
            nothing was solved.
    """

    step: int
    new_poses: int
    new_edges: np.ndarray
    new_loops: np.ndarray
    new_priors: np.ndarray
    decided_at_arrival: bool
    graduated: int
    stages: tuple[StageReport, ...]
    mu_history: np.ndarray
    residual_history: np.ndarray
    iterations: int
    time_s: float
    reanalysed: bool
    status: int
    region_poses: int = 0
    whole_map: bool = False
    restarted: bool = False


@dataclass
class UpdateLog:
    """The running record of an online solver's updates (what a checkpoint keeps of them).

    Attributes:
        steps: updates started so far.
        update_ms: wall time of every update, milliseconds.
        update_iterations: accepted solver steps of every update.
        last_status: termination code of the last update that solved something; -1 before one.
    """

    steps: int = 0
    update_ms: list[float] = field(default_factory=list)
    update_iterations: list[int] = field(default_factory=list)
    last_status: int = -1

    def record(self, report: UpdateReport) -> None:
        """Add the finished update of `report`."""
        if report.status >= 0:
            self.last_status = report.status
        self.update_ms.append(1e3 * report.time_s)
        self.update_iterations.append(report.iterations)
