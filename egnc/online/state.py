"""The graph an online solver holds: poses, edges, their roles and `mu`, grown as entries arrive.

Rows are in arrival order (a vertex id's row is fixed when the pose is taken in), edges in
insertion order. Each array grows by appending rows into room kept at its end (`MapState.grow`),
so an update that only extends the trajectory copies nothing of the map. A new pose is placed by
composing the odometry that reaches it from the current estimate, so that edge starts at zero
residual; a pose no new odometry reaches from a placed pose is placed, likewise, along the first
new loop closure that does (the loop is graduated as any other).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.errors import GraphError
from egnc.graph import POSE_SIZE, TANGENT_SIZE, PoseGraph
from egnc.graph.index_sets import sorted_unique
from egnc.nonlinear.factors import BetweenFactors, from_matrices, group_of, to_matrices
from egnc.nonlinear.least_squares import Problem
from egnc.online.intake import Pending
from egnc.online.options import Settings
from egnc.online.priors import MapPriors
from egnc.online.region import LocalProblem

__all__ = ["MapState", "Saved"]


@dataclass(frozen=True, eq=False)
class Saved:
    """The part of the estimate a solve may change, as it was before: a region's pose rows and
    factors (its solves write into them), or the whole map's arrays (its solves replace them).

    Attributes:
        rows: `(M,)` pose rows, or None for every row.
        T: `(M, n, n)` (or `(N, n, n)`) their poses.
        factors: `(K,)` factor indices (edges, then priors), or None for every factor.
        r: `(K,)` (or `(E + K,)`) their whitened residual norms.
    """

    rows: np.ndarray | None
    T: np.ndarray
    factors: np.ndarray | None
    r: np.ndarray


class MapState:
    """The online solver's graph and estimate.

    Attributes:
        settings: the solver's (`dim`; `linear_solver`, the backend of the problems built).
        row: vertex id -> pose row.
        vertex_ids: `(N,)` vertex id of each row.
        T: `(N, n, n)` current estimate; `T_initial` the poses as placed at arrival.
        gauge: the row held fixed (-1 before the first pose); `has_prior`: whether a prior set it;
            `gauge_free`: whether the measurement priors hold the map instead (`egnc.online.priors`).
        edges: `(E, 2)` pose rows of each edge; `measurements` `(E, P)`, `Z_inv` `(E, n, n)` the
            inverse measured transforms, `information` `(E, d, d)`.
        priors: the measurement priors (`egnc.online.priors.MapPriors`), `K` of them.
        robust: `(E + K,)` bool per factor (the edges, then the priors): the candidates, loop
            closures and priors not known inliers; `loops`: `(L,)` their factor indices, increasing.
        mu, mu_init: `(E + K,)` each candidate's current `mu` and the `mu` its next graduation starts from.
        r: `(E + K,)` whitened residual norms at the current estimate.
        problem: the whole map's problem, built when first needed after the graph changed.
        buffers: the arrays `grow` appends to, by attribute name, with room to spare.
    """

    def __init__(self, settings: Settings):
        dim = settings.dim
        n, d = dim + 1, TANGENT_SIZE[dim]
        self.settings, self.dim = settings, dim
        self.row: dict[int, int] = {}
        self.vertex_ids = np.zeros(0, dtype=np.int64)
        self.T = np.zeros((0, n, n))
        self.T_initial = np.zeros((0, n, n))
        self.gauge = -1
        self.has_prior = False
        self.gauge_free = False
        self.priors = MapPriors(dim)
        self.edges = np.zeros((0, 2), dtype=np.int64)
        self.measurements = np.zeros((0, POSE_SIZE[dim]))
        self.Z_inv = np.zeros((0, n, n))
        self.information = np.zeros((0, d, d))
        self.robust = np.zeros(0, dtype=bool)
        self.loops = np.zeros(0, dtype=np.int64)
        self.mu = np.zeros(0)
        self.mu_init = np.zeros(0)
        self.r = np.zeros(0)
        self.problem: Problem | None = None
        self._factors: BetweenFactors | None = None
        self.buffers: dict[str, np.ndarray] = {}

    def integrate(self, pending: Pending) -> bool:
        """Move the `pending` entries into the graph, place new poses and evaluate the new factors'
        residuals. Returns whether the map moved (onto a gauge prior or onto the fixes)."""
        if not pending:
            return False
        group, P = group_of(self.dim), POSE_SIZE[self.dim]
        for vertex_id in pending.pose_ids:
            self.row[vertex_id] = len(self.row)
        start = len(self.vertex_ids)
        self.grow("vertex_ids", np.array(pending.pose_ids, dtype=np.int64))
        if self.gauge < 0 and len(self.vertex_ids):
            self.gauge = 0
        Z = to_matrices(self.dim, np.array(pending.measurements).reshape(-1, P))
        rows = np.array([[self.row[i], self.row[j]] for i, j in pending.edge_ids], dtype=np.int64).reshape(-1, 2)
        robust = np.array(pending.robust, dtype=bool)
        new_T = self._placed(pending, start, rows, Z, robust)
        self.grow("T", new_T)
        self.grow("T_initial", new_T)
        self.grow("edges", rows)
        self.grow("measurements", np.array(pending.measurements).reshape(len(rows), P))
        self.grow("Z_inv", group.inverse(Z))
        d = TANGENT_SIZE[self.dim]
        self.grow("information", np.array(pending.information).reshape(len(rows), d, d))
        num_old_priors = len(self.priors)
        new_priors = np.array(pending.prior_known, dtype=bool)
        if len(new_priors):
            self.priors.append(
                np.array([self.row[vertex] for vertex in pending.prior_ids], dtype=np.int64),
                np.array(pending.prior_kinds, dtype=np.int8),
                np.array(pending.prior_measurements).reshape(len(new_priors), P),
                np.array(pending.prior_information).reshape(len(new_priors), d, d),
            )
        self._grow_factors("robust", robust, ~new_priors, num_old_priors)
        if num_old_priors or len(new_priors):  # the priors' indices follow the edges': they moved
            self.loops = np.flatnonzero(self.robust)
        else:
            self.grow("loops", len(self.robust) - len(robust) + np.flatnonzero(robust))
        for name in ("mu", "mu_init"):
            self._grow_factors(name, np.zeros(len(rows)), np.zeros(len(new_priors)), num_old_priors)
        if len(rows) or len(pending.pose_ids) or len(new_priors):
            self.problem = self._factors = None
        moved = self._move_gauge(pending, len(new_priors) > 0)
        new_edges = np.arange(len(self.edges) - len(rows), len(self.edges))
        added = self.factors().subset(new_edges)
        # A moved map moves every prior's residual; the edges' stay.
        kept_priors = 0 if moved else num_old_priors
        prior_r = self.priors.residual_norms(self.T, first=kept_priors)
        self._grow_factors("r", added.whitened_norms(added.residuals(self.T)), prior_r, kept_priors)
        return moved

    def _move_gauge(self, pending: Pending, new_priors: bool) -> bool:
        """Move the map onto `pending`'s gauge prior (`OnlineSolver.add_prior`), or onto the
        measurement priors while they do not pin it yet, freeing the held pose once they do
        (`egnc.online.priors`). Returns whether the map moved."""
        if pending.prior is not None:
            # The prior's pose becomes the gauge: move the map rigidly onto it (relative residuals unchanged).
            row = self.row[pending.prior[0]]
            target = to_matrices(self.dim, pending.prior[1])
            self.T = target @ group_of(self.dim).inverse(self.T[row]) @ self.T
            self.gauge, self.has_prior, self.gauge_free = row, True, False
            self.problem = None
            return True
        if not new_priors or self.has_prior or self.gauge_free:
            return False
        self.T = self.priors.onto_fixes(self.T)
        self.gauge_free = self.priors.pin_the_map()
        self.problem = None
        return True

    def _grow_factors(self, name: str, edge_rows: np.ndarray, prior_rows: np.ndarray, kept_priors: int) -> None:
        """Append to the per-factor array `name` (the `E` edges then the `K` priors) the new edges'
        `edge_rows` after the edges and `prior_rows` after the first `kept_priors` priors."""
        current = getattr(self, name)
        num_edges = len(self.edges) - len(edge_rows)  # before the new ones
        if len(current) == num_edges:  # no prior yet: grown in place, as the edges are
            self.grow(name, edge_rows)
            if len(prior_rows):
                self.grow(name, prior_rows)
            return
        old = (current[:num_edges], edge_rows, current[num_edges : num_edges + kept_priors], prior_rows)
        setattr(self, name, np.concatenate(old))

    def _placed(self, pending: Pending, start: int, rows: np.ndarray, Z: np.ndarray, robust: np.ndarray) -> np.ndarray:
        """`(K, n, n)` the new poses (rows from `start`): explicit values, the others composed
        along the new odometry (`rows` `(M, 2)`, transforms `Z`, `robust` `(M,)`) in arrival order,
        or, for a pose no odometry reaches from a placed one, along a new loop closure."""
        n = self.dim + 1
        new_T = np.zeros((len(pending.pose_ids), n, n))
        placed = np.zeros(len(pending.pose_ids), dtype=bool)  # of the new poses; the others are placed
        for k, value in enumerate(pending.pose_values):
            if value is not None:
                new_T[k] = to_matrices(self.dim, value)
                placed[k] = True
        if start == 0 and len(placed) and not placed[0]:  # the very first pose, placed by nothing: at the identity
            new_T[0] = np.eye(n)
            placed[0] = True
        edges = list(zip(rows.tolist(), Z, robust.tolist()))
        odometry, loops = [edge for edge in edges if not edge[2]], [edge for edge in edges if edge[2]]
        # One pass over the odometry in arrival order places every pose reached in order. A pose
        # left over (one reached first by a loop closure, or by odometry that arrived before the
        # edge placing its other end) is placed by further passes, and when no odometry places
        # one, by the first loop closure with one end placed (the loop stays a loop).
        self._place_along(odometry, start, new_T, placed)
        while not placed.all():
            if not (
                self._place_along(odometry, start, new_T, placed)
                or self._place_along(loops, start, new_T, placed, first_only=True)
            ):
                break
        if not placed.all():
            unplaced = self.vertex_ids[start:][~placed][:5].tolist()
            raise GraphError(f"poses {unplaced} have no value and no edge from a placed pose")
        return new_T

    def _place_along(
        self, edges: list, start: int, new_T: np.ndarray, placed: np.ndarray, first_only: bool = False
    ) -> bool:
        """Place the new poses (rows from `start`, `new_T`, `placed`) that `edges` (row pairs,
        transforms, loop flags, in arrival order) reach from a placed end, in one pass (only the
        first such edge with `first_only`). Returns whether one was placed."""
        group, progress = group_of(self.dim), False
        for (i, j), Z_ij, _ in edges:
            placed_i, placed_j = i < start or placed[i - start], j < start or placed[j - start]
            if placed_i == placed_j:
                continue
            if placed_i:
                new_T[j - start] = (self.T[i] if i < start else new_T[i - start]) @ Z_ij
                placed[j - start] = True
            else:
                new_T[i - start] = (self.T[j] if j < start else new_T[j - start]) @ group.inverse(Z_ij)
                placed[i - start] = True
            progress = True
            if first_only:
                break
        return progress

    def grow(self, name: str, rows: np.ndarray) -> None:
        """Append `rows` to the array attribute `name` in time that follows `rows`: the array is
        kept as the first rows of a buffer with an eighth of room to spare (a new buffer when
        full: about nine copies per row on average). An attribute a solve has replaced by another
        array is copied into a new buffer first."""
        current = getattr(self, name)
        size, grown = len(current), len(current) + len(rows)
        buffer = self.buffers.get(name)
        if (
            buffer is None
            or current.base is not buffer
            or current.ctypes.data != buffer.ctypes.data  # not a prefix of its buffer
            or grown > len(buffer)
        ):
            buffer = np.empty((grown + max(16, grown // 8), *current.shape[1:]), dtype=current.dtype)
            buffer[:size] = current
            self.buffers[name] = buffer
        buffer[size:grown] = rows
        setattr(self, name, buffer[:grown])

    @property
    def num_priors(self) -> int:
        """Measurement priors `K` in the map."""
        return len(self.priors)

    @property
    def held(self) -> int:
        """The pose row solves hold fixed, or -1 when the priors hold the map."""
        return -1 if self.gauge_free else self.gauge

    def dims(self, factors: np.ndarray) -> int | np.ndarray:
        """The chi-square dimension of the `factors` `(F,)` (factor indices): `d`, or per factor
        `(F,)` where the map holds priors (a position prior's is `dim`)."""
        if not self.num_priors:
            return self.settings.d
        dims = np.full(len(factors), self.settings.d)
        priors = factors >= len(self.edges)
        dims[priors] = self.priors.dims[factors[priors] - len(self.edges)]
        return dims

    def factor_rows(self, factors: np.ndarray) -> np.ndarray:
        """Sorted pose rows the `factors` (factor indices: edges, then priors) measure."""
        edges = factors[factors < len(self.edges)]
        prior_rows = self.priors.rows[factors[factors >= len(self.edges)] - len(self.edges)]
        return sorted_unique(np.concatenate((self.edges[edges].ravel(), prior_rows)))

    def factors(self) -> BetweenFactors:
        """The factors of every edge, built when first needed after the graph changed."""
        if self._factors is None:
            self._factors = BetweenFactors(self.dim, self.edges, self.Z_inv, self.information)
        return self._factors

    def current_problem(self) -> Problem:
        """The whole map's problem (`problem`), built if the graph changed since the last one."""
        if self.problem is None:
            # Its whole system is solved by CG with the trusted preconditioner; only a fallback factorizes it.
            # Every entry was checked when added: no PoseGraph to check them again.
            problem = Problem.from_factors(
                self.factors(),
                self.fixed(len(self.vertex_ids)),
                self.settings.linear_solver,
                fill_reducing=False,
                priors=self.priors.factors(),
            )
            # With priors, the loss sees every factor (edges then priors): candidates are weighed.
            self.problem = replace(problem, weighted_priors=True) if self.num_priors else problem
        return self.problem

    def prefix_problem(self, num_poses: int, num_edges: int) -> Problem:
        """The problem of the graph's first `num_poses` poses and `num_edges` edges, as
        `current_problem` built it when the graph had those."""
        edges = slice(num_edges)
        factors = BetweenFactors(self.dim, self.edges[edges], self.Z_inv[edges], self.information[edges])
        return Problem.from_factors(factors, self.fixed(num_poses), self.settings.linear_solver, fill_reducing=False)

    def fixed(self, num_poses: int) -> np.ndarray:
        """`(num_poses,)` bool: the gauge's row (the solver fixes row 0 itself when none is and the
        map holds no prior); none once the priors hold the map."""
        fixed = np.zeros(num_poses, dtype=bool)
        if not self.gauge_free:
            fixed[self.gauge] = self.gauge != 0 or self.num_priors > 0
        return fixed

    def graph(self) -> PoseGraph:
        """The current graph in insertion (row) order, poses at the current estimate. Its vertex
        ids are the rows: poses may arrive in any id order, and a `PoseGraph` keeps its ids sorted."""
        return PoseGraph(
            dim=self.dim,
            vertex_ids=np.arange(len(self.vertex_ids)),
            poses=from_matrices(self.dim, self.T),
            edges=self.edges,
            measurements=self.measurements,
            information=self.information,
            fixed=self.fixed(len(self.vertex_ids)),
            priors=self.priors.priors(),
        )

    def save(self, local: LocalProblem | None) -> Saved:
        """What the stages on `local` (None: the whole map) may change of the estimate (`Saved`)."""
        if local is None:  # whole-map solves replace the arrays, never write into them
            return Saved(None, self.T, None, self.r)
        return Saved(local.rows, self.T[local.rows], local.factors, self.r[local.factors])

    def restore(self, saved: Saved) -> None:
        """Put the estimate back as `saved` holds it."""
        if saved.rows is None or saved.factors is None:
            self.T, self.r = saved.T, saved.r
        else:
            self.T[saved.rows] = saved.T
            self.r[saved.factors] = saved.r
