"""An online robust solver: poses and loop closures arrive over time, each update graduates the new loops.

riSAM and EGNC-PGO are incremental back-ends. Between two updates the map is converged; an
update adds poses, odometry and loop closures, and the loop closures it adds start at `mu = 0`
(quadratic SIG) and are graduated towards `mu = 1` (Geman-McClure) from the current estimate,
by the schedule's rule (`egnc.robust.schedules`, DESIGN.md sections 3 and 7):

- `risam`: the graduating loops share riSAM's sequence `0, 0.12, 0.384, 0.965, 1`;
- `egnc`: each graduating loop goes `0 -> mu*(r) -> 1`, or `0 -> 1` once its residual passed the
  strong-outlier threshold (chi-square 0.9); with `OnlineOptions.strong_at_arrival`, a new loop
  already past it at the current estimate starts at `mu = 1`.

Each stage of the graduation is a warm-started IRLS solve (`egnc.nonlinear.least_squares`) of the whole
current graph, or of the poses around the change (below), with the other loops at their own `mu`.
The last stage (every graduating loop at `mu = 1`) starts from the lower of two maps, by their
cost at its `mu`: the one the earlier stages left, or the one before the update. A false loop,
quadratic at its `mu = 0` stage, bends the map towards itself; weighed at Geman-McClure, that
map costs more than the one it came from, and IRLS from it takes many steps to undo the bend
(docs/online.md). A true loop the map had drifted from keeps the bent map, which costs less.
After the last stage every loop's `mu_init` is reset by its residual, as the reference
implementations do after convergence: above the chi-square 0.9 quantile a loop starts at `mu = 1`
the next time it is graduated (it stays switched off), below the 0.25 quantile at `mu = 0`. With
`regraduate="reference"` (default) the next update that brings loop closures graduates, with the new
loops, every older loop whose `mu_init` is 0, as riSAM re-graduates the loops its update touches:
the loops that fit are then quadratic again while a new loop is weighed, and hold the map against
it. With `"new"` only the new loops graduate and the older ones keep `mu = 1`; their Geman-McClure
weights give way when a false loop bends the map at its `mu = 0` stage: fewer iterations, but a
running estimate that went astray on some logs (docs/online.md has the measurements).

Every loop stays in every solve with its IRLS weight, so a loop rejected early comes back when
later evidence pulls the map towards it (its Geman-McClure weight grows as its residual falls,
and its `mu_init` returns to 0), and a false loop accepted early leaves when later loops pull
the map away from it. `result()` makes the batch decision (`egnc.robust.decision`: least squares on the
accepted loops, re-test, re-admission by innovation) on the current estimate.

What an update costs follows what changed: new poses are placed by composing their odometry from
the current estimate, so an update that only extends the trajectory leaves every residual
at the optimum and solves nothing. An update with a loop closure first solves the poses within
`OnlineOptions.region_hops` (8) trusted edges of the new edges' ends, the poses around them held
(`egnc.online.region`), and falls back to the whole map when the region's result is in doubt: when its
stages end a loop closure on the other side of the strong-outlier line than it began (an older
one either way, a new one outwards), the update is redone on the whole map from its start; when
the region's boundary would still move (its poses' own Newton steps would lower the cost by more
than `OnlineOptions.boundary_share` of the update's tolerance), the last stage goes on over the
whole map.
A whole-map solve analyses the preconditioner of the edges the map trusts (ordering and symbolic
factorization, `egnc.linalg.step_solver`); CG's operator is that system plus the other loops' own
terms, so no pattern of the whole grown system is built unless a step falls back to it.
With `OnlineOptions(decide_at_arrival=True)` (`egnc` schedule) an update may solve nothing: its
first stage (one Gauss-Newton step with the new loops at `mu = 0`) is predicted from a
factorization of the map kept from the last whole-map solve (`egnc.online.arrival`), and when that
stage would leave every new loop strong, the bent map would cost no less at `mu = 1` than the
map before it, the last stage predicted from there (the new loops' IRLS with the rest of the map
held) lets them go, and their pull on the map is below the update's tolerance, the update ends
where it starts: the new loops are set to `mu = 1` and nothing is solved.

Gauge: the pose of the first `add_prior` is held fixed at the prior's value (as `egnc.io.irl`
does: the only absolute factor is satisfied exactly at the optimum, whatever its covariance);
without a prior, the first pose added is held fixed where it was placed.

Measurement priors (`add_pose_prior`, `add_position_prior`: GNSS fixes, pose priors) may come at
any time (`egnc.online.priors`): candidates, graduated like new loops with their chi-square tests
at their own dimension, or known inliers (`known_inliers="odometry,priors"`, as `egnc.solve`
names them). Until they pin the map, the first pose stays held and the map is moved onto the
fixes as they come (the batch's trimmed fit); the update whose priors pin it moves it once more
and frees the held pose, unless `add_prior` holds one.

`OnlineSolver` runs the protocol over parts that each do one job: `egnc.online.intake` checks
what the `add_*` calls give and holds it until the update, `egnc.online.state` is the graph and
its estimate, `egnc.online.graduation` (over `egnc.online.stage`) graduates an update's loops,
`egnc.online.decide_at_arrival` decides an update without a solve, `egnc.online.result` makes the
batch decision, `egnc.online.checkpoint` saves and restores the state, `egnc.online.report` keeps
the record of the updates, and `egnc.online.options` their settings.

References:
    M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)", ICRA 2023.
    S. Kang et al., "Efficient Graduated Non-Convexity for Pose Graph Optimization" (EGNC-PGO).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from egnc.api import Result
from egnc.errors import EgncError
from egnc.graph.checks import check_bool, check_callable, check_choice
from egnc.graph.priors import KIND_NAMES
from egnc.nonlinear.factors import from_matrices
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, SolverOptions
from egnc.online.checkpoint import check_destination, read_state, restore_state, solver_arguments, write_state
from egnc.online.decide_at_arrival import ArrivalDecision
from egnc.online.graduation import Graduated, Graduation
from egnc.online.intake import Intake, id_pair, one_row
from egnc.online.options import OnlineOptions, Settings
from egnc.online.report import UpdateLog, UpdateReport
from egnc.online.result import online_result
from egnc.online.state import MapState
from egnc.robust.gnc import GncOptions, classify_inliers

__all__ = ["OnlineSolver", "UpdateCallback"]

UpdateCallback = Callable[["OnlineSolver", UpdateReport], None]
"""Receives the solver and its `UpdateReport` at the end of every update (`OnlineSolver.on_update`)."""

_RESIDUAL_AT_REST = 1e-9
"""A new edge whose whitened residual is below this at the current estimate changes no optimum."""


class OnlineSolver:
    """Robust pose-graph optimization as data arrives (module docstring).

    Use: `add_pose` / `add_odometry` / `add_prior` / `add_loop` / `add_pose_prior` /
    `add_position_prior` (or their batch forms), then `update()`; read `poses`, `inliers` /
    `rejected`, `prior_inliers` / `rejected_priors` and `result()` at any moment.

    Args:
        dim: 2 (SE(2)) or 3 (SE(3)).
        method: `"egnc"` (per-loop `mu*` and the strong-outlier rule) or `"risam"`.
        linear_solver: `"auto"` or a backend of `egnc.linalg.linear_solvers.LINEAR_SOLVERS`.
        options: options of each GN/LM solve.
        gnc_options: kernel shape `c`, threshold conventions, outlier and re-admission quantiles
            (`warm_start`, `every_stage` and `max_stages` do not apply: online stages are always
            warm-started).
        online_options: the update protocol (`OnlineOptions`).
        on_update: called with `(solver, report)` at the end of every `update()` (e.g. to record
            it, `egnc.rerun.OnlineRecorder`); also the attribute `on_update`, which a checkpoint
            does not keep.
        known_inliers: the kinds held quadratic, as `egnc.solve` names them: `"odometry"`
            (default: measurement priors are candidates, graduated like new loop closures and
            rejected when they do not fit) or `"odometry,priors"` (priors held quadratic, never
            rejected). Only the priors' role is set here: an edge's is that of the call adding it.

    Raises:
        OptionError: an unknown `dim`, method or backend, or an options argument of the wrong class.
        EgncError: an option of the `egnc` schedule (`strong_at_arrival`, `decide_at_arrival`)
            asked of the `risam` one.

    The `add_*` calls check what they are given (integer ids within int64, finite numbers of
    the right shape, symmetric positive-definite information, quaternions that normalize, known
    poses) and raise `GraphError` before taking anything in; `NumericalError` for a new edge a
    double cannot represent at the current estimate (`egnc.online.intake`). Empty batches add nothing.
    """

    def __init__(
        self,
        dim: int,
        method: str = "egnc",
        *,
        linear_solver: str = "auto",
        options: SolverOptions | None = None,
        gnc_options: GncOptions | None = None,
        online_options: OnlineOptions | None = None,
        on_update: UpdateCallback | None = None,
        known_inliers: str | Sequence[str] = "odometry",
    ):
        check_callable("on_update", on_update)
        settings = Settings.make(dim, method, linear_solver, options, gnc_options, online_options, known_inliers)
        self._settings = settings  # shared by every part: the settings below, assigned, apply to all
        self._intake = Intake(settings.dim)  # the add_* calls' entries until the next update
        self._map = MapState(settings)
        self._graduation = Graduation(settings, self._map)
        self._arrival = ArrivalDecision(settings, self._map)  # egnc.online.decide_at_arrival
        self._log = UpdateLog()
        self.last_update: UpdateReport | None = None
        self.on_update = on_update

    # ------------------------------------------------------------------ adding data

    def add_pose(self, vertex_id: int, pose: ArrayLike | None = None) -> None:
        """Add a pose; `pose` `(P,)` (`x y theta` or `x y z qx qy qz qw`) is its initial guess.

        Without `pose`, the pose must be reached by an odometry edge added before the next update,
        which places it by composing the measurement from the other end's current estimate; where
        no odometry of the update reaches it from a placed pose, the first loop closure that does
        places it the same way (the loop is graduated as any other).
        """
        self.add_poses([vertex_id], None if pose is None else one_row(pose))

    def add_poses(self, vertex_ids: ArrayLike, poses: ArrayLike | None = None) -> None:
        """Batch `add_pose`: `vertex_ids` `(K,)`, `poses` `(K, P)` or None."""
        self._intake.add_poses(vertex_ids, poses)

    def add_prior(self, vertex_id: int, pose: ArrayLike) -> None:
        """Hold pose `vertex_id` at `pose` `(P,)`: the gauge of the map (module docstring); one per solver."""
        self._intake.add_prior(vertex_id, pose, self._map.has_prior, self._map)

    def add_pose_prior(
        self, vertex_id: int, pose: ArrayLike, information: ArrayLike, known_inlier: bool | None = None
    ) -> int:
        """Add a measurement of pose `vertex_id` in the world frame; returns its prior index.

        Residual `Log(Z^-1 X)`, as GTSAM's `PriorFactor` (`egnc.graph.priors`). Unlike
        `add_prior` (the gauge) it may come at any time, as often as wanted, and be rejected.

        Args:
            vertex_id: a known pose (added before, or in this update).
            pose: `(P,)` the measured pose in the stored parametrization.
            information: `(d, d)` information matrix, translation first.
            known_inlier: hold it quadratic (True) or make it a candidate (False); None: as the
                solver's `known_inliers` says.
        """
        return int(self.add_priors("pose", [vertex_id], one_row(pose), one_row(information), known_inlier)[0])

    def add_position_prior(
        self, vertex_id: int, position: ArrayLike, information: ArrayLike, known_inlier: bool | None = None
    ) -> int:
        """Add a measured position of pose `vertex_id` (a GNSS fix, metres, world frame); returns
        its prior index. Residual `t - z`, as GTSAM's `GPSFactor`; `information` `(dim, dim)`;
        the other arguments as for `add_pose_prior`."""
        return int(self.add_priors("position", [vertex_id], one_row(position), one_row(information), known_inlier)[0])

    def add_priors(
        self,
        kind: str,
        vertex_ids: ArrayLike,
        values: ArrayLike,
        information: ArrayLike,
        known_inlier: bool | None = None,
    ) -> np.ndarray:
        """Batch `add_pose_prior` (`kind` `"pose"`: `values` `(K, P)`, `information` `(K, d, d)`)
        or `add_position_prior` (`"position"`: `(K, dim)`, `(K, dim, dim)`); `vertex_ids` `(K,)`.
        Returns the prior indices `(K,)`, in the order the priors were added."""
        code = KIND_NAMES.index(check_choice("prior kind", kind, KIND_NAMES))
        known = self._settings.priors_known if known_inlier is None else check_bool("known_inlier", known_inlier)
        first = self._map.num_priors
        return self._intake.add_measurement_priors(code, vertex_ids, values, information, known, first)

    def add_odometry(self, i: int, j: int, measurement: ArrayLike, information: ArrayLike) -> int:
        """Add a known-inlier edge measuring `X_i^-1 X_j`; returns its edge index.

        Args:
            i, j: vertex ids; at least one must be known (added before); the other, if new, is
                placed by composing `measurement` from it.
            measurement: `(P,)` relative pose in the stored parametrization.
            information: `(d, d)` information matrix, translation first (g2o order).
        """
        return int(self.add_odometry_batch(id_pair(i, j), one_row(measurement), one_row(information))[0])

    def add_loop(self, a: int, b: int, measurement: ArrayLike, information: ArrayLike) -> int:
        """Add a loop closure (a candidate outlier) measuring `X_a^-1 X_b`; both poses must be known."""
        return int(self.add_loops(id_pair(a, b), one_row(measurement), one_row(information))[0])

    def add_odometry_batch(self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike) -> np.ndarray:
        """Batch `add_odometry`: `ids` `(K, 2)`, `measurements` `(K, P)`, `information` `(K, d, d)`."""
        return self._intake.add_edges(ids, measurements, information, False, self._map)

    def add_loops(self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike) -> np.ndarray:
        """Batch `add_loop`: `ids` `(K, 2)`, `measurements` `(K, P)`, `information` `(K, d, d)`."""
        return self._intake.add_edges(ids, measurements, information, True, self._map)

    # ------------------------------------------------------------------ updating

    def update(self) -> UpdateReport:
        """Take in everything added since the last update and re-optimize what it changed.

        Returns:
            The `UpdateReport` (also kept in `last_update`).
        """
        started = time.perf_counter()
        self._log.steps += 1
        state = self._map
        num_old_edges, num_old_poses, num_old_priors = len(state.edges), len(state.vertex_ids), state.num_priors
        prior_moved = state.integrate(self._intake.take())
        new_edges = np.arange(num_old_edges, len(state.edges))
        new_loops = new_edges[state.robust[new_edges]]
        new_priors = np.arange(num_old_priors, state.num_priors)
        new_factors = np.concatenate((new_edges, len(state.edges) + new_priors))  # egnc.online.priors
        new_candidates = new_factors[state.robust[new_factors]]  # graduated like new loops
        moving = new_factors[state.r[new_factors] > _RESIDUAL_AT_REST]
        # Without edges there is nothing to solve (a prior has moved the map onto itself already).
        needs_solve = len(state.edges) > 0 and (prior_moved or len(new_candidates) > 0 or len(moving) > 0)
        graduating = np.zeros(0, dtype=np.int64)
        outcome = Graduated((), np.zeros((0, len(new_candidates))), np.zeros((0, len(new_candidates))), -1)
        # New loops alone have moved nothing yet: the map factorized after the last solve holds.
        only_loops = needs_solve and not prior_moved and bool(np.all(state.robust[moving]))
        first = self._arrival.first_stage(new_loops, num_old_poses, num_old_edges) if only_loops else None
        decided = first is not None and self._arrival.decided(new_loops, first)
        if decided:
            state.mu_init[new_loops] = state.mu[new_loops] = 1.0
        elif needs_solve:
            graduating = self._graduation.loops_to_graduate(new_candidates)
            # A moved gauge moves the whole map; otherwise the change starts at the poses of the new factors.
            seeds = None if prior_moved else state.factor_rows(np.concatenate((new_candidates, moving)))
            # One preconditioner for all stages of the update (one analysis): the edges whose weight
            # is at least trust_weight at its start, the new loops (at mu_init) included, so that CG
            # has only the switched-off loops left to resolve.
            trusted = self._graduation.trusted()
            outcome = self._graduation.run(graduating, new_candidates, seeds, trusted)
            self._graduation.reset_mu_init()
            solved_whole = outcome.whole_map and outcome.status != NUMERICAL_FAILURE
            self._arrival.converged = self._arrival.factorize(trusted) if solved_whole else None
        report = UpdateReport(
            step=self._log.steps,
            new_poses=len(state.vertex_ids) - num_old_poses,
            new_edges=new_edges,
            new_loops=new_loops,
            new_priors=new_priors,
            decided_at_arrival=decided,
            graduated=len(graduating),
            stages=outcome.reports,
            mu_history=outcome.mu_history,
            residual_history=outcome.residual_history,
            iterations=sum(stage.iterations for stage in outcome.reports),
            time_s=time.perf_counter() - started,
            reanalysed=outcome.analysed,
            status=outcome.status,
            region_poses=outcome.region_poses,
            whole_map=outcome.whole_map,
            restarted=outcome.restarted,
        )
        self._log.record(report)
        self.last_update = report
        if self.on_update is not None:
            self.on_update(self, report)
        return report

    # ------------------------------------------------------------------ settings

    @property
    def dim(self) -> int:
        """2 (SE(2)) or 3 (SE(3))."""
        return self._settings.dim

    @property
    def method(self) -> str:
        """The schedule (`egnc.online.options.ONLINE_METHODS`); assigned, it applies from the next update."""
        return self._settings.method

    @method.setter
    def method(self, method: str) -> None:
        self._settings.method = method

    @property
    def linear_solver(self) -> str:
        """The backend's resolved name; assigned, it applies to the next problems built."""
        return self._settings.linear_solver

    @linear_solver.setter
    def linear_solver(self, linear_solver: str) -> None:
        self._settings.linear_solver = linear_solver

    @property
    def options(self) -> SolverOptions:
        """Options of each GN/LM solve; assigned, they apply from the next update."""
        return self._settings.options

    @options.setter
    def options(self, options: SolverOptions) -> None:
        self._settings.options = options

    @property
    def gnc_options(self) -> GncOptions:
        """Threshold conventions and quantiles (the kernel's `c` is fixed when the solver is made)."""
        return self._settings.gnc_options

    @gnc_options.setter
    def gnc_options(self, gnc_options: GncOptions) -> None:
        self._settings.gnc_options = gnc_options

    @property
    def online_options(self) -> OnlineOptions:
        """The update protocol; assigned, it applies from the next update."""
        return self._settings.online_options

    @online_options.setter
    def online_options(self, online_options: OnlineOptions) -> None:
        self._settings.online_options = online_options

    # ------------------------------------------------------------------ reading

    @property
    def num_poses(self) -> int:
        """Poses taken in by the updates so far."""
        return len(self._map.vertex_ids)

    @property
    def num_edges(self) -> int:
        """Edges (odometry and loop closures) taken in by the updates so far."""
        return len(self._map.edges)

    @property
    def num_priors(self) -> int:
        """Measurement priors (`add_pose_prior`, `add_position_prior`) taken in by the updates so far."""
        return self._map.num_priors

    @property
    def steps(self) -> int:
        """Updates run so far."""
        return self._log.steps

    @property
    def vertex_ids(self) -> np.ndarray:
        """`(N,)` vertex ids in the order the poses were added (the row order of `poses`)."""
        return self._map.vertex_ids.copy()

    @property
    def poses(self) -> np.ndarray:
        """`(N, P)` current estimate, rows in `vertex_ids` order, in the stored parametrization."""
        return from_matrices(self.dim, self._map.T)

    @property
    def positions(self) -> np.ndarray:
        """`(N, dim)` translations of the current estimate, rows in `vertex_ids` order (no rotation
        is converted: cheaper than `poses` for a display after every update)."""
        n = self._map.T.shape[-1]
        return self._map.T[:, : n - 1, n - 1].copy()

    @property
    def edge_ids(self) -> np.ndarray:
        """`(E, 2)` vertex ids of every edge, in insertion order."""
        return self._map.vertex_ids[self._map.edges]

    @property
    def measurements(self) -> np.ndarray:
        """`(E, P)` measurement of every edge, in insertion order."""
        return self._map.measurements.copy()

    @property
    def information(self) -> np.ndarray:
        """`(E, d, d)` information matrix of every edge, in insertion order."""
        return self._map.information.copy()

    @property
    def is_loop_closure(self) -> np.ndarray:
        """`(E,)` bool: edges added as loop closures."""
        return self._map.robust[: self.num_edges].copy()

    @property
    def mu(self) -> np.ndarray:
        """`(E,)` current `mu` of each loop closure (nan for odometry)."""
        return self._per_factor(np.where(self._map.robust, self._map.mu, np.nan), edges=True)

    @property
    def residual_norms(self) -> np.ndarray:
        """`(E,)` whitened residual norms `r` at the current estimate."""
        return self._per_factor(self._map.r.copy(), edges=True)

    @property
    def inliers(self) -> np.ndarray:
        """`(E,)` bool, the decision right now: a loop is out when `r^2 > chi2.ppf(outlier_quantile, d)`
        at the current (robust) estimate. `result()` makes the batch decision instead."""
        return self._per_factor(self._classified(), edges=True)

    @property
    def rejected(self) -> np.ndarray:
        """Indices of the loop closures rejected right now (see `inliers`)."""
        return np.flatnonzero(~self.inliers)

    @property
    def prior_ids(self) -> np.ndarray:
        """`(K,)` vertex id each measurement prior measures, in the order they were added."""
        return self._map.vertex_ids[self._map.priors.rows]

    @property
    def prior_residual_norms(self) -> np.ndarray:
        """`(K,)` whitened residual norms of the measurement priors at the current estimate."""
        return self._per_factor(self._map.r.copy(), edges=False)

    @property
    def prior_candidates(self) -> np.ndarray:
        """`(K,)` bool: the measurement priors that may be rejected (not known inliers)."""
        return self._per_factor(self._map.robust.copy(), edges=False)

    @property
    def prior_inliers(self) -> np.ndarray:
        """`(K,)` bool, the decision on the priors right now, as `inliers` on the loops (each at
        its own dimension: a position prior's is `dim`). Known-inlier priors are always in."""
        return self._per_factor(self._classified(), edges=False)

    @property
    def rejected_priors(self) -> np.ndarray:
        """Prior indices of the measurement priors rejected right now (see `prior_inliers`)."""
        return np.flatnonzero(~self.prior_inliers)

    def _classified(self) -> np.ndarray:
        """`(E + K,)` bool, the outlier test of every factor at the current estimate."""
        state = self._map
        return classify_inliers(state.r, state.robust, state.dims(np.arange(len(state.r))), self.gnc_options)

    def _per_factor(self, values: np.ndarray, edges: bool) -> np.ndarray:
        """The edges' `(E,)` (`edges`) or the priors' `(K,)` part of a per-factor array `(E + K,)`."""
        return values[: self.num_edges] if edges else values[self.num_edges :]

    @property
    def update_ms(self) -> np.ndarray:
        """`(steps,)` wall time of every update so far, in milliseconds."""
        return np.array(self._log.update_ms)

    @property
    def update_iterations(self) -> np.ndarray:
        """`(steps,)` accepted solver steps of every update so far."""
        return np.array(self._log.update_iterations, dtype=np.int64)

    def result(self, decide: bool = True) -> Result:
        """The current state as an `egnc.api.Result`, poses sorted by vertex id.

        Args:
            decide: make the batch decision (`egnc.robust.decision.decide_outliers`) on the current
                estimate (least squares on the accepted edges, re-test, re-admission), and again
                by `egnc.solve` on the whole graph from its odometry (`init="odometry"`); keep
                the batch one only where its truncated cost (`egnc.robust.decision.truncated_cost`) is
                lower by more than rounding (`lower_by_more_than_rounding`), as `egnc.solve`
                chooses between its starts. The result's poses are that
                decision's least-squares map. False: the current robust estimate and the
                decision of `inliers`, at no cost.

        The result's `stages` are one summary of all updates (iterations, time; status of the last
        solve), the decision rounds from the online estimate (start `"online"`), then the batch
        solve's stages; `iterations` counts all. `start` says which decision was kept.
        """
        check_bool("decide", decide)
        if self._intake.pending:
            raise EgncError("entries were added after the last update: call update() first")
        if not len(self._map.vertex_ids):
            raise EgncError("the online solver holds no pose yet")
        return online_result(self._settings, self._map, self._log, decide)

    # ------------------------------------------------------------------ checkpoints

    def save(self, path: str | Path, meta: dict | None = None) -> None:
        """Write the whole state to `path` (NumPy `.npz`), atomically: the file is complete or untouched.

        Args:
            path: the checkpoint file.
            meta: JSON-serializable data stored alongside (e.g. how far a replay got).

        Raises:
            OptionError: `path` is not a file path, or `meta` not a dict of JSON data (nothing is written).
            EgncError: entries were added after the last update (update first).
        """
        check_destination(path, meta)
        if self._intake.pending:
            raise EgncError("entries were added after the last update: call update() before save()")
        write_state(path, meta, self._settings, self._map, self._log, self._arrival.converged)

    @classmethod
    def load(cls, path: str | Path) -> tuple[OnlineSolver, dict]:
        """Restore a solver written by `save`; returns it and the `meta` saved with it.

        Raises:
            OptionError: `path` is not a file path.
            EgncError: the file cannot be read, is not an egnc checkpoint of this version, its
                entries do not fit together, or its content is not that of its digest (edited
                after it was written; `egnc.io.checkpoint.read_checkpoint`).
        """
        saved, arrays = read_state(path)
        try:
            solver = cls(**solver_arguments(saved))
        except (EgncError, TypeError) as error:  # an unknown method or option, or options that are not a mapping
            raise EgncError(f"{path}: invalid checkpoint settings ({error})") from None
        restore_state(saved, arrays, solver._map, solver._log)
        solver._intake.known_ids = set(solver._map.row)
        if saved.get("converged_poses") is not None:
            trusted = arrays["converged_trusted"]
            problem = solver._map.prefix_problem(saved["converged_poses"], len(trusted))
            solver._arrival.converged = solver._arrival.factorize(trusted, problem)
        return solver, saved["meta"]
