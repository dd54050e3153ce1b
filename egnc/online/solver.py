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

References:
    M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)", ICRA 2023.
    S. Kang et al., "Efficient Graduated Non-Convexity for Pose Graph Optimization" (EGNC-PGO).
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Literal, cast

import numpy as np
from numpy.typing import ArrayLike

from egnc.api import Result, decided_fields, solve
from egnc.errors import EgncError, GraphError, OptionError
from egnc.graph import POSE_SIZE, TANGENT_SIZE, PoseGraph, is_dim
from egnc.graph.checks import check_bool, check_choice, check_float, check_instance, check_int, describe
from egnc.graph.index_sets import sorted_unique
from egnc.graph.validity import first_bad_quaternion
from egnc.io.checkpoint import CHECKPOINT_VERSION, read_checkpoint, write_checkpoint
from egnc.linalg.linear_solvers import resolve_name
from egnc.nonlinear.factors import BetweenFactors, EdgeErrors, from_matrices, group_of, to_matrices
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, STATUS_MESSAGES, Problem, SolverOptions, solve_least_squares
from egnc.online.arrival import ConvergedMap, FirstStage
from egnc.online.region import LocalProblem, Neighbourhoods, block_jacobi_decrease
from egnc.robust.decision import decide_outliers, lower_by_more_than_rounding
from egnc.robust.gnc import GncOptions, StageReport, classify_inliers
from egnc.robust.kernels import make_kernel
from egnc.robust.losses import KernelLoss
from egnc.robust.mu_star import mu_star
from egnc.robust.schedules import exceeds

__all__ = ["ONLINE_METHODS", "OnlineOptions", "OnlineSolver", "UpdateReport"]

ONLINE_METHODS = ("egnc", "risam")
"""Schedules the online solver graduates new loop closures with."""

_RESIDUAL_AT_REST = 1e-9
"""A new edge whose whitened residual is below this at the current estimate changes no optimum."""

WHOLE_MAP_SHARE = 0.5
"""An update whose region holds more than this share of the poses solves the whole map instead."""


@dataclass(frozen=True)
class OnlineOptions:
    """Options of the online protocol.

    Attributes:
        regraduate: which loops an update with new loop closures graduates: `"reference"`
            (default) the new ones and every older loop whose `mu_init` is 0, as riSAM
            re-graduates the loops its update touches; `"new"` only the new ones (older loops keep
            their `mu`, 1 once graduated): fewer iterations, but the running estimate went
            astray on some logs (docs/online.md).
        low_quantile: after an update's graduation, a loop with `r^2` (or `r`, by
            `GncOptions.threshold`) below `chi2.ppf(low_quantile, d)` gets `mu_init = 0`.
        high_quantile: ... and above `chi2.ppf(high_quantile, d)` gets `mu_init = 1`: it is not
            graduated again and keeps its Geman-McClure weight, which comes back by itself if the
            map moves towards it.
        stage_iterations: at most this many solver steps per graduation stage but the last,
            which converges (to `rel_cost_tol`); None: every stage converges. riSAM and EGNC-PGO
            take one step per `mu` value (one iSAM2 update each).
        strong_at_arrival: `egnc` only: a new loop whose residual at the current (converged)
            estimate is above the strong-outlier threshold (`high_quantile`) is a strong outlier
            at once and starts at `mu = 1`, as EGNC's Algorithm 1 treats a factor found strong
            after a solve; it skips the `mu = 0` stage, where a false loop would bend the map.
            Off by default (EGNC-PGO starts every new loop at 0): drifted odometry puts true
            loops far off at arrival too (docs/online.md has the measurements).
        decide_at_arrival: `egnc` only: predict an update's first stage (one Gauss-Newton step
            with its new loops at `mu = 0`) from the map factorized after the last whole-map solve
            (`egnc.online.arrival`), and solve nothing when the update would end where it starts, with
            its new loops off (module docstring): fewer iterations and the same decisions, for a
            factorization of the map after every whole-map solve (docs/online.md says when
            that pays).
        rel_cost_tol: the last stage of an update stops when an accepted step lowers the cost
            by at most this fraction (riSAM stops at 1e-2; docs/online.md says how the default
            was chosen).
        region_hops: an update with loop closures first solves the poses within this many
            trusted edges of its new edges' ends, with their other neighbours held
            (`egnc.online.region`), and falls back to the whole map when the region's stages end a
            loop on the other side of the strong-outlier line or its boundary would still move
            (module docstring; docs/online.md has the measurements). None: every update solves
            the whole map.
        boundary_share: a region's update goes on over the whole map for its last stage when its
            boundary poses' own Newton steps (block Jacobi) would lower the cost by more than this
            share of the update's tolerance (`rel_cost_tol` times the cost). One pose at a time
            underestimates what the map's long, soft modes release, hence a small share. Larger:
            fewer whole-map stages and a lower latency, for a running estimate further from the
            whole map's optimum (docs/online.md has the measurements).
    """

    regraduate: Literal["reference", "new"] = "reference"
    low_quantile: float = 0.25
    high_quantile: float = 0.9
    stage_iterations: int | None = 1
    strong_at_arrival: bool = False
    decide_at_arrival: bool = False
    rel_cost_tol: float = 1e-4
    region_hops: int | None = 8
    boundary_share: float = 1e-3

    def __post_init__(self) -> None:
        """Check every field's type and range (`egnc.graph.checks`), storing plain Python values."""
        name = "OnlineOptions."
        checked: dict[str, object] = {
            "regraduate": check_choice(name + "regraduate", self.regraduate, ("reference", "new")),
            "rel_cost_tol": check_float(name + "rel_cost_tol", self.rel_cost_tol, 0.0, 1.0, open_high=True),
            "boundary_share": check_float(name + "boundary_share", self.boundary_share, 0.0, 1.0),
        }
        low, high = (
            check_float(name + field_name, getattr(self, field_name), 0.0, 1.0, open_low=True, open_high=True)
            for field_name in ("low_quantile", "high_quantile")
        )
        if not low < high:
            raise OptionError(f"need {name}low_quantile < {name}high_quantile, got {low} and {high}")
        checked["low_quantile"], checked["high_quantile"] = low, high
        for field_name in ("strong_at_arrival", "decide_at_arrival"):
            checked[field_name] = check_bool(name + field_name, getattr(self, field_name))
        for field_name in ("stage_iterations", "region_hops"):  # None: no limit / no region
            value = getattr(self, field_name)
            checked[field_name] = None if value is None else check_int(name + field_name, value, 1)
        for field_name, value in checked.items():
            object.__setattr__(self, field_name, value)


@dataclass(frozen=True, eq=False)
class UpdateReport:
    """What one `OnlineSolver.update()` did.

    Attributes:
        step: 1-based number of the update.
        new_poses: poses added by the update.
        new_edges: `(K,)` indices of the edges it added (odometry and loops, in insertion order).
        new_loops: `(L,)` indices of the loop closures it added.
        decided_at_arrival: whether the update solved nothing because its stages, predicted from
            the map factorized after the last solve, would end where it started with its new loops
            off (`OnlineOptions.decide_at_arrival`); its new loops are then at `mu = 1`.
        graduated: loop closures graduated by the update (the new ones and, with
            `regraduate="reference"`, older ones whose `mu_init` is 0).
        stages: one report per solve (empty when nothing needed solving or `decided_at_arrival`).
        mu_history: `(S, L)` `mu` of each new loop closure in each stage.
        residual_history: `(S, L)` whitened residual norm `r` of each new loop closure after
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


@dataclass(frozen=True, eq=False)
class _Graduation:
    """What the stages of one update did (fields as in `UpdateReport`)."""

    reports: tuple[StageReport, ...]
    mu_history: np.ndarray
    residual_history: np.ndarray
    status: int
    cost: float = np.nan  # the whole map's kernel cost after the last stage, at its mu
    analysed: bool = False
    region_poses: int = 0
    whole_map: bool = False
    restarted: bool = False


@dataclass(frozen=True, eq=False)
class _Saved:
    """The part of the estimate a solve may change, as it was before: a region's pose rows and
    edges (its solves write into them), or the whole map's arrays (its solves replace them).

    Attributes:
        rows: `(M,)` pose rows, or None for every row.
        T: `(M, n, n)` (or `(N, n, n)`) their poses.
        edges: `(K,)` edges, or None for every edge.
        r: `(K,)` (or `(E,)`) their whitened residual norms.
    """

    rows: np.ndarray | None
    T: np.ndarray
    edges: np.ndarray | None
    r: np.ndarray


@dataclass
class _Pending:
    """Entries added since the last update, in arrival order."""

    pose_ids: list[int] = field(default_factory=list)
    pose_values: list[np.ndarray | None] = field(default_factory=list)
    edge_ids: list[tuple[int, int]] = field(default_factory=list)
    measurements: list[np.ndarray] = field(default_factory=list)
    information: list[np.ndarray] = field(default_factory=list)
    robust: list[bool] = field(default_factory=list)
    prior: tuple[int, np.ndarray] | None = None

    def __bool__(self) -> bool:
        return bool(self.pose_ids or self.edge_ids or self.prior is not None)


class OnlineSolver:
    """Robust pose-graph optimization as data arrives (module docstring).

    Use: `add_pose` / `add_odometry` / `add_prior` / `add_loop` (or their batch forms), then
    `update()`; read `poses`, `inliers` / `rejected` and `result()` at any moment.

    Args:
        dim: 2 (SE(2)) or 3 (SE(3)).
        method: `"egnc"` (per-loop `mu*` and the strong-outlier rule) or `"risam"`.
        linear_solver: `"auto"` or a backend of `egnc.linalg.linear_solvers.LINEAR_SOLVERS`.
        options: options of each GN/LM solve.
        gnc_options: kernel shape `c`, threshold conventions, outlier and re-admission quantiles
            (`warm_start`, `every_stage` and `max_stages` do not apply: online stages are always
            warm-started).
        online_options: the update protocol (`OnlineOptions`).

    Raises:
        OptionError: an unknown `dim`, method or backend, or an options argument of the wrong class.
        EgncError: an option of the `egnc` schedule (`strong_at_arrival`, `decide_at_arrival`)
            asked of the `risam` one.

    The `add_*` calls check what they are given (integer ids, finite numbers of the right
    shape, symmetric positive-definite information, quaternions that normalize, known poses)
    and raise `GraphError` before taking anything in.
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
    ):
        if not is_dim(dim):
            raise OptionError(f"dim must be 2 or 3, got {describe(dim)}")
        check_choice("online method", method, ONLINE_METHODS)
        for name, value, kind in (
            ("options", options, SolverOptions),
            ("gnc_options", gnc_options, GncOptions),
            ("online_options", online_options, OnlineOptions),
        ):
            if value is not None:
                check_instance(name, value, kind)
        rules = ("strong_at_arrival", "decide_at_arrival")
        egnc_only = [name for name in rules if getattr(online_options, name, False)]
        if method != "egnc" and egnc_only:
            raise EgncError(f"OnlineOptions.{egnc_only[0]} applies to the egnc schedule (EGNC's strong-outlier rule)")
        self.dim, self.method = int(dim), method
        self.linear_solver = resolve_name(linear_solver)
        self.options = options or SolverOptions()
        self.gnc_options = gnc_options or GncOptions()
        self.online_options = online_options or OnlineOptions()
        self._d = TANGENT_SIZE[dim]
        self._n = dim + 1
        self._group = group_of(dim)
        self._kernel = make_kernel("sig", c=self.gnc_options.c)
        self._row: dict[int, int] = {}
        self._vertex_ids = np.zeros(0, dtype=np.int64)
        self._T = np.zeros((0, self._n, self._n))
        self._T_initial = np.zeros((0, self._n, self._n))
        self._gauge = -1  # row held fixed; -1 before the first pose
        self._has_prior = False
        self._edges = np.zeros((0, 2), dtype=np.int64)
        self._measurements = np.zeros((0, POSE_SIZE[dim]))
        self._Z_inv = np.zeros((0, self._n, self._n))
        self._information = np.zeros((0, self._d, self._d))
        self._robust = np.zeros(0, dtype=bool)
        self._loops = np.zeros(0, dtype=np.int64)  # indices of the robust edges, increasing
        self._mu = np.zeros(0)
        self._mu_init = np.zeros(0)
        self._r = np.zeros(0)
        self._steps = 0
        self._update_ms: list[float] = []
        self._update_iterations: list[int] = []
        self._pending = _Pending()
        self._known_ids: set[int] = set()
        self._problem: Problem | None = None
        self._factors: BetweenFactors | None = None
        self._buffers: dict[str, np.ndarray] = {}  # the arrays _grow appends to, with room to spare
        self._neighbourhoods = Neighbourhoods()  # grown with the edges before each region is drawn
        self._converged: ConvergedMap | None = None  # the map after its last whole-map solve (egnc.online.arrival)
        self._last_status = -1
        self.last_update: UpdateReport | None = None

    # ------------------------------------------------------------------ adding data

    def add_pose(self, vertex_id: int, pose: ArrayLike | None = None) -> None:
        """Add a pose; `pose` `(P,)` (`x y theta` or `x y z qx qy qz qw`) is its initial guess.

        Without `pose`, the pose must be reached by an odometry edge added before the next update,
        which places it by composing the measurement from the other end's current estimate.
        """
        self.add_poses([vertex_id], None if pose is None else _one(pose))

    def add_poses(self, vertex_ids: ArrayLike, poses: ArrayLike | None = None) -> None:
        """Batch `add_pose`: `vertex_ids` `(K,)`, `poses` `(K, P)` or None."""
        ids = _ids(vertex_ids, 1)
        values = None if poses is None else self._poses_array(poses, len(ids), "poses")
        if len(set(ids.tolist())) < len(ids) or self._known_ids.intersection(ids.tolist()):
            raise GraphError(f"a pose among {ids[:5].tolist()} was already added")
        for k, vertex_id in enumerate(ids.tolist()):
            self._known_ids.add(vertex_id)
            self._pending.pose_ids.append(vertex_id)
            self._pending.pose_values.append(None if values is None else values[k])

    def add_prior(self, vertex_id: int, pose: ArrayLike) -> None:
        """Hold pose `vertex_id` at `pose` `(P,)`: the gauge of the map (module docstring); one per solver."""
        if self._has_prior or self._pending.prior is not None:
            raise GraphError("a second prior: the online solver uses one prior as the gauge")
        value = self._poses_array(_one(pose), 1, "prior pose")[0]
        vertex_id = _vertex_id(vertex_id)
        if vertex_id not in self._known_ids:
            self.add_pose(vertex_id, value)
        self._pending.prior = (vertex_id, value)

    def add_odometry(self, i: int, j: int, measurement: ArrayLike, information: ArrayLike) -> int:
        """Add a known-inlier edge measuring `X_i^-1 X_j`; returns its edge index.

        Args:
            i, j: vertex ids; at least one must be known (added before); the other, if new, is
                placed by composing `measurement` from it.
            measurement: `(P,)` relative pose in the stored parametrization.
            information: `(d, d)` information matrix, translation first (g2o order).
        """
        return int(self.add_odometry_batch(_pair(i, j), _one(measurement), _one(information))[0])

    def add_loop(self, a: int, b: int, measurement: ArrayLike, information: ArrayLike) -> int:
        """Add a loop closure (a candidate outlier) measuring `X_a^-1 X_b`; both poses must be known."""
        return int(self.add_loops(_pair(a, b), _one(measurement), _one(information))[0])

    def add_odometry_batch(self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike) -> np.ndarray:
        """Batch `add_odometry`: `ids` `(K, 2)`, `measurements` `(K, P)`, `information` `(K, d, d)`."""
        return self._add_edges(ids, measurements, information, robust=False)

    def add_loops(self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike) -> np.ndarray:
        """Batch `add_loop`: `ids` `(K, 2)`, `measurements` `(K, P)`, `information` `(K, d, d)`."""
        return self._add_edges(ids, measurements, information, robust=True)

    def _add_edges(self, ids: ArrayLike, measurements: ArrayLike, information: ArrayLike, robust: bool) -> np.ndarray:
        pairs = _ids(ids, 2)
        k = len(pairs)
        values = self._poses_array(measurements, k, "measurements")
        info = _array(information, (k, self._d, self._d), "information")
        if not np.allclose(info, info.swapaxes(1, 2), rtol=1e-9, atol=0.0):
            raise GraphError("information matrices must be symmetric")
        if k and np.any(np.linalg.eigvalsh(0.5 * (info + info.swapaxes(1, 2)))[:, 0] <= 0.0):
            raise GraphError("information matrices must be positive definite")
        reached: set[int] = set()  # ends of this batch's edges so far: an edge may start where an earlier one ends
        for i, j in pairs.tolist():
            if i == j:
                raise GraphError(f"an edge joins pose {i} to itself")
            known_i = i in self._known_ids or i in reached
            known_j = j in self._known_ids or j in reached
            if robust and not (known_i and known_j):
                missing = j if known_i else i
                raise GraphError(f"loop closure ({i}, {j}): pose {missing} is not known; add it or its odometry first")
            if not robust and not known_i and not known_j:
                raise GraphError(f"odometry ({i}, {j}) joins two unknown poses: one end must be known")
            reached.update((i, j))
        first = len(self._edges) + len(self._pending.edge_ids)
        for (i, j), value, matrix in zip(pairs.tolist(), values, info):
            for vertex_id in (i, j):
                if vertex_id not in self._known_ids:
                    self._known_ids.add(vertex_id)
                    self._pending.pose_ids.append(vertex_id)
                    self._pending.pose_values.append(None)
            self._pending.edge_ids.append((i, j))
            self._pending.measurements.append(value)
            self._pending.information.append(matrix)
            self._pending.robust.append(robust)
        return np.arange(first, first + k)

    def _poses_array(self, values: ArrayLike, count: int, name: str) -> np.ndarray:
        """`values` as `(count, P)` float64 poses, finite, with quaternions that normalize in 3D."""
        array = _array(values, (count, POSE_SIZE[self.dim]), name)
        found = first_bad_quaternion(array[:, 3:7]) if self.dim == 3 else None
        if found:
            where = f" row {found[0]}" if count > 1 else ""
            raise GraphError(f"{name}{where}: {found[1]}")
        return array

    # ------------------------------------------------------------------ updating

    def update(self) -> UpdateReport:
        """Take in everything added since the last update and re-optimize what it changed.

        Returns:
            The `UpdateReport` (also kept in `last_update`).
        """
        started = time.perf_counter()
        self._steps += 1
        num_old_edges, num_old_poses = len(self._edges), len(self._vertex_ids)
        prior_moved = self._integrate()
        new_edges = np.arange(num_old_edges, len(self._edges))
        new_loops = new_edges[self._robust[new_edges]]
        added = self._current_factors().subset(new_edges)
        new_r = added.whitened_norms(added.residuals(self._T))
        self._grow("_r", new_r)
        moving = new_edges[new_r > _RESIDUAL_AT_REST]
        # Without edges there is nothing to solve (a prior has moved the map onto itself already).
        needs_solve = len(self._edges) > 0 and (prior_moved or len(new_loops) > 0 or len(moving) > 0)
        graduating = np.zeros(0, dtype=np.int64)
        outcome = _Graduation((), np.zeros((0, len(new_loops))), np.zeros((0, len(new_loops))), -1)
        # New loops alone have moved nothing yet: the map factorized after the last solve holds.
        only_loops = needs_solve and not prior_moved and bool(np.all(self._robust[moving]))
        first = self._first_stage(new_loops, num_old_poses, num_old_edges) if only_loops else None
        decided = first is not None and self._decided_at_arrival(new_loops, first)
        if decided:
            self._mu_init[new_loops] = self._mu[new_loops] = 1.0
        elif needs_solve:
            graduating = self._graduating(new_loops)
            # A moved gauge moves the whole map; otherwise the change starts at the ends of the new edges.
            seeds = None if prior_moved else sorted_unique(self._edges[np.concatenate((new_loops, moving))].ravel())
            # One preconditioner for all stages of the update (one analysis): the edges whose weight
            # is at least trust_weight at its start, the new loops (at mu_init) included, so that CG
            # has only the switched-off loops left to resolve.
            trusted = self._trusted()
            outcome = self._graduate(graduating, new_loops, seeds, trusted)
            self._reset_mu_init()
            solved_whole = outcome.whole_map and outcome.status != NUMERICAL_FAILURE
            self._converged = self._factorize_map(trusted) if solved_whole else None
        stages, status = outcome.reports, outcome.status
        report = UpdateReport(
            step=self._steps,
            new_poses=len(self._vertex_ids) - num_old_poses,
            new_edges=new_edges,
            new_loops=new_loops,
            decided_at_arrival=decided,
            graduated=len(graduating),
            stages=stages,
            mu_history=outcome.mu_history,
            residual_history=outcome.residual_history,
            iterations=sum(stage.iterations for stage in stages),
            time_s=time.perf_counter() - started,
            reanalysed=outcome.analysed,
            status=status,
            region_poses=outcome.region_poses,
            whole_map=outcome.whole_map,
            restarted=outcome.restarted,
        )
        if status >= 0:
            self._last_status = status
        self._update_ms.append(1e3 * report.time_s)
        self._update_iterations.append(report.iterations)
        self.last_update = report
        return report

    def _integrate(self) -> bool:
        """Move the pending entries into the graph; place new poses. Returns whether the gauge moved."""
        pending, self._pending = self._pending, _Pending()
        if not pending:
            return False
        n = self._n
        # Poses: explicit values now, the others by composing odometry in arrival order.
        start = len(self._vertex_ids)
        for vertex_id in pending.pose_ids:
            self._row[vertex_id] = len(self._row)
        self._grow("_vertex_ids", np.array(pending.pose_ids, dtype=np.int64))
        new_T = np.zeros((len(pending.pose_ids), n, n))
        placed = np.zeros(len(pending.pose_ids), dtype=bool)  # of the new poses; the others are placed
        for k, value in enumerate(pending.pose_values):
            if value is not None:
                new_T[k] = to_matrices(self.dim, value)
                placed[k] = True
        if start == 0 and len(placed) and not placed[0]:  # the very first pose, placed by nothing: at the identity
            new_T[0] = np.eye(n)
            placed[0] = True
        if self._gauge < 0 and len(self._vertex_ids):
            self._gauge = 0
        Z = to_matrices(self.dim, np.array(pending.measurements).reshape(-1, POSE_SIZE[self.dim]))
        rows = np.array([[self._row[i], self._row[j]] for i, j in pending.edge_ids], dtype=np.int64).reshape(-1, 2)
        robust = np.array(pending.robust, dtype=bool)
        for (i, j), Z_ij, is_loop in zip(rows.tolist(), Z, robust.tolist()):
            placed_i, placed_j = i < start or placed[i - start], j < start or placed[j - start]
            if is_loop or placed_i == placed_j:
                continue
            if placed_i:
                new_T[j - start] = (self._T[i] if i < start else new_T[i - start]) @ Z_ij
                placed[j - start] = True
            else:
                new_T[i - start] = (self._T[j] if j < start else new_T[j - start]) @ self._group.inverse(Z_ij)
                placed[i - start] = True
        if not placed.all():
            unplaced = self._vertex_ids[start:][~placed][:5].tolist()
            raise GraphError(f"poses {unplaced} have no value and no odometry from a placed pose")
        self._grow("_T", new_T)
        self._grow("_T_initial", new_T)
        self._grow("_edges", rows)
        self._grow("_measurements", np.array(pending.measurements).reshape(len(rows), POSE_SIZE[self.dim]))
        self._grow("_Z_inv", self._group.inverse(Z))
        self._grow("_information", np.array(pending.information).reshape(len(rows), self._d, self._d))
        self._grow("_robust", robust)
        self._grow("_loops", len(self._robust) - len(robust) + np.flatnonzero(robust))
        self._grow("_mu", np.zeros(len(rows)))
        self._grow("_mu_init", np.zeros(len(rows)))
        if len(rows) or len(pending.pose_ids):
            self._problem = self._factors = None
        if pending.prior is None:
            return False
        # The prior's pose becomes the gauge: move the map rigidly onto it (relative residuals unchanged).
        row = self._row[pending.prior[0]]
        target = to_matrices(self.dim, pending.prior[1])
        self._T = target @ self._group.inverse(self._T[row]) @ self._T
        self._gauge, self._has_prior = row, True
        self._problem = None
        return True

    def _grow(self, name: str, rows: np.ndarray) -> None:
        """Append `rows` to the array attribute `name` in time that follows `rows`: the array is
        kept as the first rows of a buffer with an eighth of room to spare (a new buffer when
        full: about nine copies per row on average). An attribute a solve has replaced by another
        array is copied into a new buffer first."""
        current = getattr(self, name)
        size, grown = len(current), len(current) + len(rows)
        buffer = self._buffers.get(name)
        if (
            buffer is None
            or current.base is not buffer
            or current.ctypes.data != buffer.ctypes.data  # not a prefix of its buffer
            or grown > len(buffer)
        ):
            buffer = np.empty((grown + max(16, grown // 8), *current.shape[1:]), dtype=current.dtype)
            buffer[:size] = current
            self._buffers[name] = buffer
        buffer[size:grown] = rows
        setattr(self, name, buffer[:grown])

    def _current_factors(self) -> BetweenFactors:
        if self._factors is None:
            self._factors = BetweenFactors(self.dim, self._edges, self._Z_inv, self._information)
        return self._factors

    def _graph(self) -> PoseGraph:
        """The current graph in insertion (row) order, poses at the current estimate. Its vertex
        ids are the rows: poses may arrive in any id order, and a `PoseGraph` keeps its ids sorted."""
        return PoseGraph(
            dim=self.dim,
            vertex_ids=np.arange(len(self._vertex_ids)),
            poses=from_matrices(self.dim, self._T),
            edges=self._edges,
            measurements=self._measurements,
            information=self._information,
            fixed=self._fixed(len(self._vertex_ids)),
        )

    def _fixed(self, num_poses: int) -> np.ndarray:
        """`(num_poses,)` bool: the gauge's row (the solver fixes row 0 itself when none is)."""
        fixed = np.zeros(num_poses, dtype=bool)
        fixed[self._gauge] = self._gauge != 0
        return fixed

    def _current_problem(self) -> Problem:
        if self._problem is None:
            # Its whole system is solved by CG with the trusted preconditioner; only a fallback factorizes it.
            # Every entry was checked when added: no PoseGraph to check them again.
            self._problem = Problem.from_factors(
                self._current_factors(), self._fixed(len(self._vertex_ids)), self.linear_solver, fill_reducing=False
            )
        return self._problem

    def _first_stage(self, new_loops: np.ndarray, num_old_poses: int, num_old_edges: int) -> FirstStage | None:
        """The update's first stage predicted from the map factorized after the last whole-map
        solve (`egnc.online.arrival`), or, when there is none, from the map as it was before this update
        (its first `num_old_poses` poses and `num_old_edges` edges); None where not predicted."""
        if not len(new_loops) or not self._predicts_first_stage():
            return None
        if self._converged is None and not num_old_edges:  # no map to predict from yet
            return None
        if self._converged is None:
            old = np.arange(num_old_edges)
            weights = KernelLoss(self._kernel, self._mu[old], self._robust[old]).weight(self._r[old])
            problem = self._prefix_problem(num_old_poses, num_old_edges)
            self._converged = self._factorize_map(weights >= self.options.trust_weight, problem)
        if self._converged is None:
            return None
        weights = self._kernel.weight(self._r[new_loops], np.zeros(len(new_loops)))
        return self._converged.first_stage(self._current_factors(), self._T, self._robust, new_loops, weights)

    def _predicts_first_stage(self) -> bool:
        return self.method == "egnc" and self.online_options.decide_at_arrival

    def _decided_at_arrival(self, new_loops: np.ndarray, first: FirstStage) -> bool:
        """Whether the update would end where it starts, with its new loops off: the predicted
        first stage finds every new loop strong (EGNC then weighs them at `mu = 1` from the stage's
        bent map), the bent map costs no less at `mu = 1` than the map before it (the last stage
        would not descend from lower ground than the start), the new loops' IRLS from there with
        the rest of the map held lets them go (`FirstStage.last_stage`), and their pull on the map
        as it stands would lower the cost by less than the last stage's tolerance."""
        far = exceeds(first.residual_norms, self.online_options.high_quantile, self._d, self.gnc_options.threshold)
        if not far[new_loops].all():
            return False
        mu = self._mu.copy()
        mu[new_loops] = 1.0
        loss = KernelLoss(self._kernel, mu, self._robust)
        cost = float(np.sum(loss.cost(self._r)))
        if float(np.sum(loss.cost(first.residual_norms))) < cost:
            return False
        information = self._information[new_loops]
        settled = first.last_stage(information, loss.subset(new_loops).weight, first.residual_norms[new_loops])
        if not exceeds(settled, self.online_options.high_quantile, self._d, self.gnc_options.threshold).all():
            return False
        weights = loss.subset(new_loops).weight(self._r[new_loops])
        bound = first.largest_decrease(weights, information)
        return bound <= self._stage_options()[0].rel_cost_tol * cost

    def _prefix_problem(self, num_poses: int, num_edges: int) -> Problem:
        """The problem of the graph's first `num_poses` poses and `num_edges` edges, as
        `_current_problem` built it when the graph had those."""
        edges = slice(num_edges)
        factors = BetweenFactors(self.dim, self._edges[edges], self._Z_inv[edges], self._information[edges])
        return Problem.from_factors(factors, self._fixed(num_poses), self.linear_solver, fill_reducing=False)

    def _graduating(self, new_loops: np.ndarray) -> np.ndarray:
        """`(G,)` increasing edge indices: the loops this update graduates from `mu_init` (module docstring)."""
        graduating = new_loops
        if self.method == "egnc" and self.online_options.strong_at_arrival:
            # EGNC's strong-outlier test after a solve, applied at the converged current estimate.
            strong = self._past(self.online_options.high_quantile, new_loops)
            self._mu_init[new_loops[strong]] = self._mu[new_loops[strong]] = 1.0
            graduating = new_loops[~strong]
        if len(new_loops) and self.online_options.regraduate == "reference":
            loops = self._loops
            graduating = sorted_unique(np.concatenate((graduating, loops[self._mu_init[loops] == 0.0])))
        return graduating

    def _factorize_map(self, trusted: np.ndarray, problem: Problem | None = None) -> ConvergedMap | None:
        """The map's information factorized at the current estimate over the `trusted` edges, for
        the next updates' first-stage predictions; `problem`: the map's (default: the current one)."""
        if not self._predicts_first_stage():
            return None
        problem = problem or self._current_problem()
        num_edges = len(trusted)
        weights = KernelLoss(self._kernel, self._mu[:num_edges], self._robust[:num_edges]).weight(self._r[:num_edges])
        return ConvergedMap.factorize(problem, self._T[: problem.num_poses], weights, trusted)

    def _graduate(
        self, graduating: np.ndarray, new_loops: np.ndarray, seeds: np.ndarray | None, trusted: np.ndarray
    ) -> _Graduation:
        """Run the stages of one update around `seeds` (pose rows; None: the whole map) with the
        preconditioner of the `trusted` `(E,)` edges."""
        hops = self.online_options.region_hops
        local = None
        neighbourhoods = self._neighbourhoods
        if seeds is not None and hops is not None:
            neighbourhoods.grow(self._edges, len(self._vertex_ids))
            # Hops go along the edges the map trusts (egnc.online.region.Neighbourhoods.within).
            local = self._local_problem(neighbourhoods.within(seeds, hops, trusted), neighbourhoods)
        if local is None:
            analysed = self._problem is None
            return replace(self._stages(None, graduating, new_loops, trusted), analysed=analysed, whole_map=True)
        region_poses = int(local.free.sum())
        before, mu_before = self._save(local), self._mu[graduating]  # the stages change mu there only
        was_far = self._far()
        in_region = replace(self._stages(local, graduating, new_loops, trusted), region_poses=region_poses)
        if in_region.status == NUMERICAL_FAILURE:
            return in_region
        if self._crossed(was_far, new_loops):
            self._restore(before)
            self._mu[graduating] = mu_before
            analysed = self._problem is None
            redone = self._stages(None, graduating, new_loops, trusted)
            return replace(
                redone,
                reports=in_region.reports + redone.reports,
                analysed=analysed,
                region_poses=region_poses,
                whole_map=True,
            )
        if self._boundary_strained(local, neighbourhoods, in_region.cost):
            # The region's boundary pulls on the rest: the whole map takes the last stage's steps
            # from the local optimum.
            analysed = self._problem is None
            last, _ = self._solve_stage(None, self._stage_options()[0], trusted, None)
            return replace(
                in_region, reports=in_region.reports + (last,), status=last.status, analysed=analysed, whole_map=True
            )
        return in_region

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
        new = slice(len(far) - len(new_loops), None)
        crossed[new] &= far[new]
        return bool(np.any(crossed))

    def _far(self) -> np.ndarray:
        """`(L,)` bool per loop closure (`_loops`): its residual is past the strong-outlier line (`high_quantile`)."""
        return self._past(self.online_options.high_quantile, self._loops)

    def _past(self, quantile: float, edges: np.ndarray) -> np.ndarray:
        """`(K,)` bool: which `edges` `(K,)` have a residual above the chi-square `quantile`."""
        return exceeds(self._r[edges], quantile, self._d, self.gnc_options.threshold)

    def _trusted(self) -> np.ndarray:
        """`(E,)` bool: the edges whose IRLS weight is at least `trust_weight` (the kernel is
        evaluated on the loop closures only; the other edges weigh 1)."""
        loops = self._loops
        trusted = np.full(len(self._edges), 1.0 >= self.options.trust_weight)
        weights = self._kernel.weight(self._r[loops], self._mu[loops])
        trusted[loops] = weights >= self.options.trust_weight
        return trusted

    def _stage_options(self) -> tuple[SolverOptions, SolverOptions]:
        """Options of the last stage (converged to `rel_cost_tol`) and of the stages before it."""
        tight = replace(self.options, rel_cost_tol=max(self.options.rel_cost_tol, self.online_options.rel_cost_tol))
        if self.online_options.stage_iterations is None:
            return tight, tight
        return tight, replace(tight, max_iterations=self.online_options.stage_iterations)

    def _stages(
        self,
        local: LocalProblem | None,
        graduating: np.ndarray,
        new_loops: np.ndarray,
        trusted: np.ndarray,
    ) -> _Graduation:
        """Graduate the loops `graduating` (increasing edge indices) from `mu_init` on `local` (None: the whole map)."""
        tight, intermediate = self._stage_options()
        self._mu[graduating] = self._mu_init[graduating]
        before = self._save(local)  # the map before the update
        # A region's stages keep the whole map's per-edge costs current where they change (its
        # edges, the loops whose mu moves), not over every edge of the map per stage.
        costs = None if local is None else KernelLoss(self._kernel, self._mu, self._robust).cost(self._r)
        restarted = False
        active = graduating[self._mu[graduating] < 1.0]  # loops whose mu still moves this update
        strong = np.zeros(len(active), dtype=bool)
        stage_index = 0
        reports: list[StageReport] = []
        history: list[np.ndarray] = []
        residuals: list[np.ndarray] = []
        errors = None  # the residuals where the last stage ended, which the next starts from
        while True:
            final = not np.any(self._mu[active] < 1.0)
            if final and stage_index > 0:
                restarted = self._start_from_lower(before, costs)
                errors = None if restarted else errors
            solution, errors = self._solve_stage(local, tight if final else intermediate, trusted, costs, errors)
            reports.append(solution)
            history.append(self._mu[new_loops].copy())
            residuals.append(self._r[new_loops].copy())
            if final or solution.status == NUMERICAL_FAILURE:
                break
            stage_index += 1
            # EGNC's strong-outlier test uses the same chi-square 0.9 quantile as the mu_init reset.
            strong |= self._past(self.online_options.high_quantile, active)
            self._mu[active] = self._next_mu(stage_index, active, strong)
            if costs is not None:
                self._refresh_costs(costs, active)
        shape = (len(history), len(new_loops))
        return _Graduation(
            tuple(reports),
            np.array(history).reshape(shape),
            np.array(residuals).reshape(shape),
            reports[-1].status,
            cost=reports[-1].cost if costs is None else float(np.sum(costs)),
            restarted=restarted,
        )

    def _start_from_lower(self, before: _Saved, costs: np.ndarray | None) -> bool:
        """Before the last stage: go back to the map `before` the update when it costs less at the
        current `mu` than the map the earlier stages bent (compared over the edges `before` holds:
        the others are the same in both); returns whether it did (module docstring).

        `costs`: the region's per-edge costs `(E,)` (`_stages`), kept current."""
        edges = slice(None) if before.edges is None else before.edges
        loss = KernelLoss(self._kernel, self._mu[edges], self._robust[edges])
        if float(np.sum(loss.cost(before.r))) >= float(np.sum(loss.cost(self._r[edges]))):
            return False
        self._restore(before)
        if costs is not None and before.edges is not None:
            self._refresh_costs(costs, before.edges)
        return True

    def _save(self, local: LocalProblem | None) -> _Saved:
        """What the stages on `local` (None: the whole map) may change of the estimate (`_Saved`)."""
        if local is None:  # whole-map solves replace the arrays, never write into them
            return _Saved(None, self._T, None, self._r)
        return _Saved(local.rows, self._T[local.rows], local.edges, self._r[local.edges])

    def _restore(self, saved: _Saved) -> None:
        """Put the estimate back as `saved` holds it."""
        if saved.rows is None or saved.edges is None:
            self._T, self._r = saved.T, saved.r
        else:
            self._T[saved.rows] = saved.T
            self._r[saved.edges] = saved.r

    def _refresh_costs(self, costs: np.ndarray, edges: np.ndarray) -> None:
        """Recompute the per-edge kernel costs `costs` `(E,)` of `edges` at the current `r` and `mu`."""
        costs[edges] = KernelLoss(self._kernel, self._mu[edges], self._robust[edges]).cost(self._r[edges])

    def _solve_stage(
        self,
        local: LocalProblem | None,
        options: SolverOptions,
        trusted: np.ndarray,
        costs: np.ndarray | None,
        errors: EdgeErrors | None = None,
    ) -> tuple[StageReport, EdgeErrors | None]:
        """One stage at the current `mu`: the whole map (`local` None), or the local problem's
        poses, written into the estimate, with `costs` `(E,)`, the whole map's per-edge costs
        (`_stages`), kept current. `errors`: the residuals of the same problem's edges at the
        poses the stage starts from, if known (where the stage before it ended).

        Returns:
            The stage's report, and the residuals where it ended.
        """
        started = time.perf_counter()
        if local is None:
            loss = KernelLoss(self._kernel, self._mu.copy(), self._robust)
            solution = solve_least_squares(
                self._current_problem(), self._T, loss, options, trusted=trusted, errors=errors, keep_errors=True
            )
            self._T, self._r = solution.poses, solution.residual_norms
            cost = solution.cost
        else:
            assert costs is not None, "a region's stages keep the whole map's costs"
            edges = local.edges
            # The stop rule of the whole map's solve: a decrease below rel_cost_tol of the whole cost.
            local_cost, whole_cost = float(np.sum(costs[edges])), float(np.sum(costs))
            # A region is small: one factorization of all its edges beats CG's preconditioner analysis.
            scaled = replace(
                options,
                rel_cost_tol=options.rel_cost_tol * whole_cost / max(local_cost, 1e-300),
                linear_method="direct",
            )
            loss = KernelLoss(self._kernel, self._mu[edges], self._robust[edges])
            solution = solve_least_squares(
                local.problem,
                self._T[local.rows],
                loss,
                scaled,
                trusted=trusted[edges],
                errors=errors,
                keep_errors=True,
            )
            self._T[local.rows] = solution.poses
            self._r[edges] = solution.residual_norms
            self._refresh_costs(costs, edges)
            cost = whole_cost - local_cost + solution.cost
        mu_loops = self._mu[self._loops]
        report = StageReport(
            float(mu_loops.min(initial=np.nan)) if len(mu_loops) else np.nan,
            float(mu_loops.mean()) if len(mu_loops) else np.nan,
            float(mu_loops.max(initial=np.nan)) if len(mu_loops) else np.nan,
            iterations=solution.iterations,
            cost=cost,
            time_s=time.perf_counter() - started,
            status=solution.status,
            active_edges=len(self._edges) if local is None else len(local.edges),
            cg_iterations=solution.linear.cg_iterations,
        )
        return report, solution.errors

    def _local_problem(self, region: np.ndarray, neighbourhoods: Neighbourhoods) -> LocalProblem | None:
        """The local problem of `region` (pose rows); None (the whole map) when it holds most of it."""
        if len(region) > WHOLE_MAP_SHARE * len(self._vertex_ids):
            return None
        return LocalProblem.build(region, neighbourhoods, self._current_factors(), self._gauge, self.linear_solver)

    def _boundary_strained(self, local: LocalProblem, neighbourhoods: Neighbourhoods, whole_cost: float) -> bool:
        """Whether the boundary poses' own Newton steps would lower the cost by more than
        `OnlineOptions.boundary_share` of the update's tolerance (`egnc.online.region.block_jacobi_decrease`), that
        is of `rel_cost_tol` times `whole_cost`, the whole map's kernel cost."""
        boundary = local.boundary[local.boundary != self._gauge]
        if not len(boundary):
            return False
        edges = neighbourhoods.edges_of(boundary)
        weights = KernelLoss(self._kernel, self._mu[edges], self._robust[edges]).weight(self._r[edges])
        decrease = block_jacobi_decrease(self._current_factors(), edges, self._T, weights, boundary)
        tolerance = self._stage_options()[0].rel_cost_tol * whole_cost
        return float(decrease.sum()) > self.online_options.boundary_share * tolerance

    def _next_mu(self, stage_index: int, active: np.ndarray, strong: np.ndarray) -> np.ndarray:
        """The `mu` of the `active` loops (edge indices) at stage `stage_index` >= 1 of an
        update; `strong`: which of them were found strong outliers."""
        if self.method == "risam":
            shared = 0.0
            for _ in range(stage_index):  # riSAM's heuristic from mu_init = 0
                shared = min(1.0, shared + 1.2 * (shared + 0.1))
            return np.full(len(active), shared)
        if stage_index >= 2:
            return np.ones(len(active))
        r = self._r[active]
        mu = np.ones(len(r))
        band = ~strong
        mu[band] = np.minimum(mu_star(r[band], self.gnc_options.c), 1.0)
        return mu

    def _reset_mu_init(self) -> None:
        """After convergence: loops far off start at `mu = 1` next time, loops that fit at `mu = 0`."""
        loops = self._loops
        self._mu_init[loops[self._far()]] = 1.0
        self._mu_init[loops[~self._past(self.online_options.low_quantile, loops)]] = 0.0

    # ------------------------------------------------------------------ reading

    @property
    def num_poses(self) -> int:
        """Poses taken in by the updates so far."""
        return len(self._vertex_ids)

    @property
    def num_edges(self) -> int:
        """Edges (odometry and loop closures) taken in by the updates so far."""
        return len(self._edges)

    @property
    def steps(self) -> int:
        """Updates run so far."""
        return self._steps

    @property
    def vertex_ids(self) -> np.ndarray:
        """`(N,)` vertex ids in the order the poses were added (the row order of `poses`)."""
        return self._vertex_ids.copy()

    @property
    def poses(self) -> np.ndarray:
        """`(N, P)` current estimate, rows in `vertex_ids` order, in the stored parametrization."""
        return from_matrices(self.dim, self._T)

    @property
    def edge_ids(self) -> np.ndarray:
        """`(E, 2)` vertex ids of every edge, in insertion order."""
        return self._vertex_ids[self._edges]

    @property
    def is_loop_closure(self) -> np.ndarray:
        """`(E,)` bool: edges added as loop closures."""
        return self._robust.copy()

    @property
    def mu(self) -> np.ndarray:
        """`(E,)` current `mu` of each loop closure (nan for odometry)."""
        return np.where(self._robust, self._mu, np.nan)

    @property
    def residual_norms(self) -> np.ndarray:
        """`(E,)` whitened residual norms `r` at the current estimate."""
        return self._r.copy()

    @property
    def inliers(self) -> np.ndarray:
        """`(E,)` bool, the decision right now: a loop is out when `r^2 > chi2.ppf(outlier_quantile, d)`
        at the current (robust) estimate. `result()` makes the batch decision instead."""
        return classify_inliers(self._r, self._robust, self._d, self.gnc_options)

    @property
    def rejected(self) -> np.ndarray:
        """Indices of the loop closures rejected right now (see `inliers`)."""
        return np.flatnonzero(~self.inliers)

    @property
    def update_ms(self) -> np.ndarray:
        """`(steps,)` wall time of every update so far, in milliseconds."""
        return np.array(self._update_ms)

    @property
    def update_iterations(self) -> np.ndarray:
        """`(steps,)` accepted solver steps of every update so far."""
        return np.array(self._update_iterations, dtype=np.int64)

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
        if self._pending:
            raise EgncError("entries were added after the last update: call update() first")
        if not len(self._vertex_ids):
            raise EgncError("the online solver holds no pose yet")
        started = time.perf_counter()
        graph = self._graph()
        factors = self._current_factors()
        robust = self._robust.copy()
        mu_loops = self._mu[robust]
        online_stage = StageReport(
            float(mu_loops.min()) if len(mu_loops) else np.nan,
            float(mu_loops.mean()) if len(mu_loops) else np.nan,
            float(mu_loops.max()) if len(mu_loops) else np.nan,
            iterations=int(sum(self._update_iterations)),
            cost=float(np.sum(KernelLoss(self._kernel, self._mu, robust).cost(self._r))),
            time_s=1e-3 * float(sum(self._update_ms)),
            status=self._last_status if self._last_status >= 0 else 1,
            active_edges=len(self._edges),
        )
        stages: tuple[StageReport, ...] = (online_stage,)
        poses = self._T
        robust_r = self._r.copy()
        weights = KernelLoss(self._kernel, self._mu, robust).weight(robust_r)
        status = online_stage.status
        settled, start, note = True, "online", ""
        disputed: np.ndarray | None = None
        # Rows sorted by vertex id, as every PoseGraph egnc reads; edges keep insertion order.
        order = np.argsort(self._vertex_ids, kind="stable")
        new_row = np.empty_like(order)
        new_row[order] = np.arange(len(order))
        fixed = np.zeros(len(order), dtype=bool)
        fixed[new_row[self._gauge]] = new_row[self._gauge] != 0
        sorted_graph = PoseGraph(
            dim=self.dim,
            vertex_ids=self._vertex_ids[order],
            poses=from_matrices(self.dim, self._T_initial)[order],
            edges=new_row[self._edges],
            measurements=self._measurements,
            information=self._information,
            fixed=fixed,
        )
        if decide and robust.any():
            decision = decide_outliers(
                graph, poses, robust, self.options, self.gnc_options, self.linear_solver, factors, start="online"
            )
            poses, inliers, settled = decision.poses, decision.inliers, decision.settled
            stages += decision.reports
            if decision.reports:
                status = decision.reports[-1].status
            batch = self._batch_solve(sorted_graph, robust)
            stages += batch.stages
            disputed = robust & ~inliers & batch.inliers
            if lower_by_more_than_rounding(batch.truncated_cost, decision.truncated_cost):
                note = (
                    f"; decision from the batch solve of the whole graph (truncated cost {batch.truncated_cost:.6g},"
                    f" against {decision.truncated_cost:.6g} from the online estimate)"
                )
                disputed = robust & ~batch.inliers & inliers
                poses = to_matrices(self.dim, batch.graph.poses)[new_row]
                inliers, settled, start, status = batch.inliers, batch.settled, batch.start, batch.status
        r = factors.whitened_norms(factors.residuals(poses))
        if not (decide and robust.any()):
            inliers = classify_inliers(r, robust, self._d, self.gnc_options)
        initial_r = factors.whitened_norms(factors.residuals(self._T_initial))
        result_poses = from_matrices(self.dim, poses)[order]
        return Result(
            graph=sorted_graph.with_poses(result_poses),
            method=self.method,
            linear_solver=self.linear_solver,
            residual_norms=r,
            weights=weights,
            mu=self.mu,
            known_inliers=~robust,
            inliers=inliers,
            stages=stages,
            status=status,
            message=STATUS_MESSAGES.get(status, "no solve needed") + note,
            time_s=online_stage.time_s + time.perf_counter() - started,
            timings={},
            robust_residual_norms=robust_r,
            init="online",
            **decided_fields(
                sorted_graph,
                result_poses,
                initial_r,
                r,
                inliers,
                robust,
                stages,
                self.gnc_options,
                start=start,
                settled=settled,
                disputed=disputed,
            ),
        )

    def _batch_solve(self, graph: PoseGraph, robust: np.ndarray) -> Result:
        """`egnc.solve` of `graph` (vertex-sorted) from its odometry composed from the gauge, or
        from the poses as placed at arrival where odometry does not reach every pose."""

        def batch(init: str) -> Result:
            return solve(
                graph,
                self.method,
                known_inliers=~robust,
                linear_solver=self.linear_solver,
                options=self.options,
                gnc_options=self.gnc_options,
                init=init,
            )

        try:
            return batch("odometry")
        except GraphError:  # a pose no odometry reaches
            return batch("file")

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
        check_instance("path", path, (str, os.PathLike), "a file path")
        if not os.fspath(path):
            raise OptionError("path must name a file, got ''")
        check_instance("meta", {} if meta is None else meta, dict)
        if self._pending:
            raise EgncError("entries were added after the last update: call update() before save()")
        settings = {
            "version": CHECKPOINT_VERSION,
            "dim": self.dim,
            "method": self.method,
            "linear_solver": self.linear_solver,
            "options": asdict(self.options),
            "gnc_options": asdict(self.gnc_options),
            "online_options": asdict(self.online_options),
            "gauge": self._gauge,
            "has_prior": self._has_prior,
            "steps": self._steps,
            "last_status": self._last_status,
            # The factorized map is rebuilt on load from the state it was factorized at (its first poses and edges).
            "converged_poses": None if self._converged is None else self._converged.num_poses,
            "meta": {} if meta is None else meta,
        }
        arrays = {
            "vertex_ids": self._vertex_ids,
            "T": self._T,
            "T_initial": self._T_initial,
            "edges": self._edges,
            "measurements": self._measurements,
            "Z_inv": self._Z_inv,
            "information": self._information,
            "robust": self._robust,
            "mu": self._mu,
            "mu_init": self._mu_init,
            "r": self._r,
            "converged_trusted": np.zeros(0, dtype=bool) if self._converged is None else self._converged.trusted,
            "update_ms": np.array(self._update_ms),
            "update_iterations": np.array(self._update_iterations, dtype=np.int64),
        }
        try:
            write_checkpoint(Path(path), settings, arrays)
        except (TypeError, ValueError) as error:
            raise OptionError(f"meta must hold only JSON data (dicts, lists, strings, numbers): {error}") from None

    @classmethod
    def load(cls, path: str | Path) -> tuple[OnlineSolver, dict]:
        """Restore a solver written by `save`; returns it and the `meta` saved with it.

        Raises:
            OptionError: `path` is not a file path.
            EgncError: the file cannot be read, is not an egnc checkpoint of this version, or its
                entries do not fit together (`egnc.io.checkpoint.read_checkpoint`).
        """
        check_instance("path", path, (str, os.PathLike), "a file path")
        settings, arrays = read_checkpoint(Path(path))
        try:
            solver = cls(
                settings["dim"],
                settings["method"],
                linear_solver=settings["linear_solver"],
                options=SolverOptions(**settings["options"]),
                gnc_options=GncOptions(**settings["gnc_options"]),
                online_options=OnlineOptions(**settings["online_options"]),
            )
        except (EgncError, TypeError) as error:  # an unknown method or option, or options that are not a mapping
            raise EgncError(f"{path}: invalid checkpoint settings ({error})") from None
        solver._vertex_ids = arrays["vertex_ids"]
        solver._row = {vertex_id: row for row, vertex_id in enumerate(solver._vertex_ids.tolist())}
        solver._known_ids = set(solver._row)
        solver._T, solver._T_initial = arrays["T"], arrays["T_initial"]
        solver._edges, solver._measurements = arrays["edges"], arrays["measurements"]
        solver._Z_inv, solver._information = arrays["Z_inv"], arrays["information"]
        solver._robust, solver._mu, solver._mu_init = arrays["robust"], arrays["mu"], arrays["mu_init"]
        solver._loops = np.flatnonzero(solver._robust)
        solver._r = arrays["r"]
        solver._update_ms = arrays["update_ms"].tolist()
        solver._update_iterations = arrays["update_iterations"].tolist()
        solver._gauge, solver._has_prior = settings["gauge"], settings["has_prior"]
        solver._steps, solver._last_status = settings["steps"], settings["last_status"]
        if settings.get("converged_poses") is not None:
            trusted = arrays["converged_trusted"]
            problem = solver._prefix_problem(settings["converged_poses"], len(trusted))
            solver._converged = solver._factorize_map(trusted, problem)
        return solver, settings["meta"]


def _vertex_id(value: object) -> int:
    """One vertex id as an int; it must be an integer (bools refused; the range is `_ids`'s to check)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise GraphError(f"vertex ids must be integers, got {describe(value)}")
    return int(value)


def _pair(i: int, j: int) -> ArrayLike:
    """The ids of one edge as a one-row batch for `_ids`."""
    return [[_vertex_id(i), _vertex_id(j)]]


def _one(value: object) -> ArrayLike:
    """`value` as a one-row batch, unconverted: junk or ragged input fails in `_array`, which names it."""
    return cast(ArrayLike, [value])


def _ids(values: ArrayLike, width: int) -> np.ndarray:
    """Vertex ids as int64, `(K,)` for `width` 1 or `(K, 2)` for 2; non-negative."""
    try:
        array = np.asarray(values)
    except ValueError:  # ragged nesting
        raise GraphError(f"vertex ids must be integers, got {describe(values)}") from None
    if array.dtype.kind not in "iu":
        raise GraphError(f"vertex ids must be integers, got {array.dtype}")
    if array.size % width:
        raise GraphError(f"edge ids come in pairs, got {array.size} ids")
    array = array.astype(np.int64).reshape(-1) if width == 1 else array.astype(np.int64).reshape(-1, 2)
    if np.any(array < 0):
        raise GraphError("vertex ids must be non-negative")
    return array


def _array(values: ArrayLike, shape: tuple[int, ...], name: str) -> np.ndarray:
    """`values` as float64 of exactly `shape`, finite."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):  # not numbers, or ragged nesting
        raise GraphError(f"{name} must be numbers of shape {shape}") from None
    if array.shape != shape:
        raise GraphError(f"{name} has shape {array.shape}, expected {shape}")
    if not np.all(np.isfinite(array)):
        raise GraphError(f"{name} holds NaN or infinite values")
    return array
