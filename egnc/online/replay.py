"""Replay a whole pose graph through the online solver, step by step, with checkpoints.

A step is one new pose: the edges are grouped by their later vertex (the larger pose row, i.e.
vertex id, of the two they join), groups in increasing order, and within a group the known
inliers (odometry) come first, then the loop closures, each in file order. One step is one
`OnlineSolver.update()`, as riSAM processes a log one pose at a time. For an IRL log this is
its own time order; for a g2o file it is the order in which a robot numbering its poses would
have made the measurements.

The replay starts from the gauge pose (the prior's or the fixed one, else row 0). A step whose
edges do not reach its poses in this order from the poses known so far is taken in as far as
its edges allow: odometry reaching a known pose in any order, a pose reached first by a loop
closure placed along that loop (which is graduated as a loop all the same), and the edges of
which neither end is known yet wait for the step that reaches one of them (a prior on a later
pose: the edges before it wait until the replay has met their poses). A graph whose edges all
reach their poses in order replays exactly as described above; steps left with nothing to add
are no updates.

A graph's priors (pose and position priors, `egnc.graph.priors`) are replayed at the step their
pose arrives (the gauge pose's with the first step), after the step's edges, in file order:
candidates or known inliers as `known_inliers` says, as in `egnc.solve`. A graph with priors and
no fixed pose starts from its first pose unheld by a prior: the online solver holds it until the
priors pin the map, then moves the map onto them (`egnc.online.priors`), as the batch solve puts
such a graph in the priors' frame. A graph without priors replays as it always did.

The `Result` of a replay lists the edges and the priors in the graph's own (file) order, so its
indices, `rejected_edges` and `rejected_priors` included, are those of `egnc.solve` on the same graph.

Checkpoints: with `checkpoint`, the solver's whole state is written there (atomically) every
`checkpoint_every` steps and after the last one, together with a fingerprint of the graph. A
replay given an existing checkpoint of the same graph and settings resumes after its last step
(the solver's update count: one update per step); since every update is deterministic, the final
result equals an uninterrupted run's. The checkpoint's own graph must be the replay's after those
steps (`_check_prefix`), and its content its digest (`egnc.io.checkpoint`): an edited checkpoint
is refused, not resumed to another map.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from egnc.api import Result
from egnc.errors import EgncError, GraphError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_callable, check_instance, check_int
from egnc.graph.priors import KIND_NAMES
from egnc.io.atomic import check_writable
from egnc.nonlinear.least_squares import SolverOptions
from egnc.online import OnlineOptions, OnlineSolver, UpdateReport
from egnc.online.solver import UpdateCallback
from egnc.robust.gnc import GncOptions, KnownInliers, known_inlier_mask

__all__ = [
    "CHECKPOINT_EVERY",
    "ReplayOutcome",
    "ReplayStep",
    "add_gauge",
    "add_priors",
    "add_step",
    "latency_summary",
    "prior_steps",
    "replay",
    "replay_plan",
    "replay_steps",
]

CHECKPOINT_EVERY = 50
"""Steps between two checkpoint writes unless told otherwise."""

StepCallback = Callable[[int, int, UpdateReport], None]
"""Receives `(step, total_steps, report)` after every update (progress display)."""


@dataclass(frozen=True, eq=False)
class ReplayOutcome:
    """The end of a replay.

    Attributes:
        result: the final `Result` (batch decision on the final estimate), edges in file order.
        solver: the online solver, at the end of the replay.
        steps: updates over the whole replay (including those before a resume).
        resumed_from: steps already done in the checkpoint the replay resumed from (0 if none).
        update_ms: `(steps,)` wall time of every update, milliseconds.
        update_iterations: `(steps,)` accepted solver steps of every update.
        total_s: sum of the update times, seconds (reading, the final decision and writing excluded).
    """

    result: Result
    solver: OnlineSolver
    steps: int
    resumed_from: int
    update_ms: np.ndarray
    update_iterations: np.ndarray
    total_s: float


@dataclass(frozen=True, eq=False)
class ReplayStep:
    """One update of a replay.

    Attributes:
        edges: `(K,)` edge indices in insertion order: the known inliers (odometry), then the loop closures.
        loop_placed: `(M,)` pose rows added first, without a value: poses no odometry of the step
            reaches from a known pose, placed along a loop closure (`egnc.online.state`); mostly empty.
    """

    edges: np.ndarray
    loop_placed: np.ndarray


def replay_steps(graph: PoseGraph, known_inliers: np.ndarray) -> list[np.ndarray]:
    """The edges of each step, in insertion order (module docstring): a list of `(K_s,)` edge indices."""
    return [step.edges for step in replay_plan(graph, known_inliers)]


def replay_plan(graph: PoseGraph, known_inliers: np.ndarray) -> list[ReplayStep]:
    """The steps of a replay of `graph` with the `(E,)` bool `known_inliers` (module docstring).

    Raises:
        GraphError: edges no edge connects to the gauge pose (a disconnected graph).
    """
    later = graph.edges.max(axis=1)
    order = np.lexsort((np.arange(graph.num_edges), ~known_inliers, later))
    boundaries = np.flatnonzero(np.diff(later[order])) + 1
    reached = np.zeros(graph.num_poses, dtype=bool)
    reached[gauge_row(graph)] = True
    ends, waiting, plan = graph.edges.tolist(), np.zeros(0, dtype=np.int64), []
    for group in np.split(order, boundaries):
        if not len(waiting) and _reaches_in_order(group, ends, known_inliers, reached):
            plan.append(ReplayStep(group, np.zeros(0, dtype=np.int64)))
            continue
        step, waiting = _connect(np.sort(np.concatenate((waiting, group))), ends, known_inliers, reached)
        if len(step.edges):
            plan.append(step)
    if len(waiting):
        first = int(waiting[0])
        line = int(graph.edge_lines[first])
        where = f"line {line}" if line else f"edge {first}"
        i, j = graph.vertex_ids[graph.edges[first]].tolist()
        gauge = int(graph.vertex_ids[gauge_row(graph)])
        message = f"edge ({i}, {j}) has no path of edges to the gauge pose {gauge}: a replay cannot place it"
        raise GraphError(f"{where}: {message}")
    return plan


def _reaches_in_order(group: np.ndarray, ends: list, known: np.ndarray, reached: np.ndarray) -> bool:
    """Whether the step `group` (odometry first, in order) reaches its poses as the online solver's
    `add_*` calls require: each odometry edge from a known pose, loop closures between known ones.
    If so, marks its poses in `reached` `(N,)` bool."""
    new: set[int] = set()
    for edge in group.tolist():
        i, j = ends[edge]
        known_i, known_j = reached[i] or i in new, reached[j] or j in new
        if not (known_i or known_j) or (not known[edge] and not (known_i and known_j)):
            return False
        new.update((i, j))
    reached[list(new)] = True
    return True


def _connect(
    candidates: np.ndarray, ends: list, known: np.ndarray, reached: np.ndarray
) -> tuple[ReplayStep, np.ndarray]:
    """The step of the edges `candidates` (file order) that reach a known pose, as `MapState` places
    them: odometry in passes until none reaches a new pose, then the first loop closure with one
    known end places the other, and so on. Returns it and the edges still waiting; updates `reached`."""
    odometry = [edge for edge in candidates.tolist() if known[edge]]
    loops = [edge for edge in candidates.tolist() if not known[edge]]
    taken: list[int] = []
    loop_placed: list[int] = []
    while True:
        progress = True
        while progress:
            left = []
            for edge in odometry:
                i, j = ends[edge]
                if reached[i] or reached[j]:
                    taken.append(edge)
                    reached[i] = reached[j] = True
                else:
                    left.append(edge)
            progress, odometry = len(left) < len(odometry), left
        placing = next((edge for edge in loops if reached[ends[edge][0]] != reached[ends[edge][1]]), None)
        if placing is None:
            break
        i, j = ends[placing]
        loop_placed.append(j if reached[i] else i)
        reached[i] = reached[j] = True
    taken += [edge for edge in loops if reached[ends[edge][0]] and reached[ends[edge][1]]]
    chosen = set(taken)
    waiting = np.array([edge for edge in candidates.tolist() if edge not in chosen], dtype=np.int64)
    return ReplayStep(np.array(taken, dtype=np.int64), np.array(loop_placed, dtype=np.int64)), waiting


def prior_steps(graph: PoseGraph, steps: list[ReplayStep]) -> np.ndarray:
    """`(K,)` the step at which each prior of `graph` is replayed: the first whose edges reach its
    pose (0 for the gauge pose's)."""
    arrival = np.full(graph.num_poses, len(steps), dtype=np.int64)
    for number in range(len(steps) - 1, -1, -1):  # the earliest step wins
        arrival[graph.edges[steps[number].edges].ravel()] = number
    arrival[gauge_row(graph)] = 0
    return arrival[graph.priors.rows]


def add_priors(solver: OnlineSolver, graph: PoseGraph, priors: np.ndarray, known: np.ndarray) -> None:
    """Add the `priors` (increasing indices) of `graph` to `solver` in their order, known inliers
    where `known` `(K,)` says so."""
    dim, d = graph.dim, graph.tangent_dim
    for k in priors.tolist():
        kind = KIND_NAMES[graph.priors.kinds[k]]
        m = d if kind == "pose" else dim
        value = graph.priors.measurements[k] if kind == "pose" else graph.priors.measurements[k, :dim]
        information = graph.priors.information[k, :m, :m]
        vertex = graph.vertex_ids[graph.priors.rows[k]]
        solver.add_priors(kind, [vertex], [value], [information], bool(known[k]))


def gauge_row(graph: PoseGraph) -> int:
    """The row of `graph`'s gauge pose: the fixed one, else row 0."""
    return int(np.flatnonzero(graph.fixed)[0]) if graph.fixed.any() else 0


def add_gauge(solver: OnlineSolver, graph: PoseGraph) -> None:
    """Give `solver` the prior of `graph`'s gauge pose (the fixed one, else row 0), as `replay`
    does; for a graph with priors and no fixed pose, that pose unheld by a prior (module docstring)."""
    gauge = gauge_row(graph)
    if graph.num_priors and not graph.fixed.any():
        solver.add_pose(int(graph.vertex_ids[gauge]), graph.poses[gauge])
    else:
        solver.add_prior(int(graph.vertex_ids[gauge]), graph.poses[gauge])


def add_step(solver: OnlineSolver, graph: PoseGraph, step: ReplayStep, known_inliers: np.ndarray) -> None:
    """Add one `step` of `graph` to `solver` as `replay` does: its loop-placed poses, then its
    known inliers (`(E,)` bool) as odometry, then the others as loop closures, in its order."""
    if len(step.loop_placed):
        solver.add_poses(graph.vertex_ids[step.loop_placed])
    edges = step.edges
    odometry, loops = edges[known_inliers[edges]], edges[~known_inliers[edges]]
    for batch, add in ((odometry, solver.add_odometry_batch), (loops, solver.add_loops)):
        if len(batch):
            add(graph.vertex_ids[graph.edges[batch]], graph.measurements[batch], graph.information[batch])


def fingerprint(graph: PoseGraph, known_inliers: np.ndarray) -> str:
    """A SHA-256 of what a replay depends on: the edges, their measurements and information, the
    roles (`(E,)`, or `(E + K,)` edges then priors), and the priors where the graph has any."""
    digest = hashlib.sha256()
    arrays = [graph.vertex_ids, graph.edges, graph.measurements, graph.information, known_inliers, graph.fixed]
    if graph.num_priors:  # a graph without priors keeps the fingerprint it always had
        priors = graph.priors
        arrays += [priors.rows, priors.kinds, priors.measurements, priors.information]
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def replay(
    graph: PoseGraph,
    method: str = "egnc",
    *,
    known_inliers: KnownInliers | None = None,
    linear_solver: str = "auto",
    options: SolverOptions | None = None,
    gnc_options: GncOptions | None = None,
    online_options: OnlineOptions | None = None,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = CHECKPOINT_EVERY,
    stop_after: int | None = None,
    on_step: StepCallback | None = None,
    on_update: UpdateCallback | None = None,
) -> ReplayOutcome:
    """Replay `graph` step by step through an `OnlineSolver` and decide at the end.

    Args:
        graph: the pose graph; its gauge pose (the fixed one, else row 0) is the prior.
        method: `"egnc"` or `"risam"`.
        known_inliers: the factors held quadratic, as for `egnc.solve`: kinds (default
            `"odometry"`: the edges between consecutive ids are added as odometry, the others as
            loop closures, and the priors are candidates) or a bool mask, `(E,)` over the edges or
            `(E + K,)` over the edges then the priors.
        linear_solver, options, gnc_options, online_options: as for `OnlineSolver`.
        checkpoint: a file to write the state to, and to resume from when it exists.
        checkpoint_every: steps between two checkpoint writes (and one after the last step).
        stop_after: stop after this many steps in all (for tests of interrupted runs); the
            checkpoint is written, and the result is that of the steps done, its edges in
            insertion (replay) order.
        on_step: called after every update with `(step, total_steps, report)`.
        on_update: the solver's `OnlineSolver.on_update`, called with `(solver, report)` after
            every update (e.g. `egnc.rerun.OnlineRecorder`), also on a resumed solver.

    Raises:
        EgncError: the checkpoint belongs to another graph or other settings, cannot be read
            (`OnlineSolver.load`: damaged, or edited since it was written), holds a graph that is
            not this one's after its steps, or, where it does not exist yet, cannot be written
            there (checked before the first step).
        GraphError: edges no edge connects to the gauge pose (`replay_plan`).
    """
    check_instance("graph", graph, PoseGraph)
    known, priors_known = _roles(graph, known_inliers)
    _check_arguments(graph, checkpoint, checkpoint_every, stop_after, on_step)
    check_callable("on_update", on_update)
    steps = replay_plan(graph, known)
    arrivals = prior_steps(graph, steps)
    settings = _checkpoint_meta(graph, np.concatenate((known, priors_known)), method, online_options or OnlineOptions())
    path = None if checkpoint is None else Path(checkpoint)
    solver = _resumed(path, settings, graph, known, steps, arrivals)
    if solver is None:
        solver = OnlineSolver(
            graph.dim,
            method,
            linear_solver=linear_solver,
            options=options,
            gnc_options=gnc_options,
            online_options=online_options,
        )
        add_gauge(solver, graph)
    solver.on_update = on_update
    done = resumed_from = solver.steps  # one update per step
    last = len(steps) if stop_after is None else min(len(steps), stop_after)
    for step in range(done, last):
        add_step(solver, graph, steps[step], known)
        add_priors(solver, graph, np.flatnonzero(arrivals == step), priors_known)
        report = solver.update()
        done = step + 1
        if on_step is not None:
            on_step(done, len(steps), report)
        if path is not None and (done % checkpoint_every == 0 or done == last):
            solver.save(path, meta=settings)
    result = _in_file_order(solver.result(), steps, arrivals, graph) if done == len(steps) else solver.result()
    update_ms = solver.update_ms
    return ReplayOutcome(
        result=result,
        solver=solver,
        steps=solver.steps,
        resumed_from=resumed_from,
        update_ms=update_ms,
        update_iterations=solver.update_iterations,
        total_s=1e-3 * float(update_ms.sum()),
    )


def _roles(graph: PoseGraph, known_inliers: KnownInliers | None) -> tuple[np.ndarray, np.ndarray]:
    """`(E,)` the known-inlier edges and `(K,)` the known-inlier priors of `replay`'s `known_inliers`."""
    mask = known_inlier_mask(graph, "odometry" if known_inliers is None else known_inliers)
    priors = mask[graph.num_edges :] if len(mask) > graph.num_edges else np.ones(graph.num_priors, dtype=bool)
    return mask[: graph.num_edges], priors


def _check_arguments(
    graph: PoseGraph,
    checkpoint: str | Path | None,
    checkpoint_every: int,
    stop_after: int | None,
    on_step: StepCallback | None,
) -> None:
    """Refuse `replay`'s arguments of the wrong kind, and a graph with a pose no edge touches."""
    check_int("checkpoint_every", checkpoint_every, 1)
    if stop_after is not None:
        check_int("stop_after", stop_after, 0)
    if checkpoint is not None:
        check_instance("checkpoint", checkpoint, (str, os.PathLike), "a file path")
    check_callable("on_step", on_step)
    touched = np.zeros(graph.num_poses, dtype=bool)
    touched[graph.edges.ravel()] = True
    if not touched.all():
        raise GraphError(f"{int((~touched).sum())} poses no edge touches: a replay cannot place them")


def _checkpoint_meta(graph: PoseGraph, known: np.ndarray, method: str, online_options: OnlineOptions) -> dict:
    """What a checkpoint of `replay` must have been written with to be resumed (`known`: `(E,)` roles)."""
    return {
        "fingerprint": fingerprint(graph, known),
        "method": method,
        # A resumed run keeps its checkpoint's options; one asked to solve otherwise is refused.
        "region_hops": online_options.region_hops,
        "decide_at_arrival": online_options.decide_at_arrival,
        "boundary_share": online_options.boundary_share,
    }


def _resumed(
    path: Path | None,
    settings: dict,
    graph: PoseGraph,
    known: np.ndarray,
    steps: list[ReplayStep],
    arrivals: np.ndarray,
) -> OnlineSolver | None:
    """The solver of the checkpoint at `path` when it exists, refused unless it was written with
    `settings` (`replay`'s checkpoint meta) and holds the first steps of the replay of `graph`
    (`_check_prefix`); None otherwise, once `path` (if any) is known writable."""
    if path is None:
        return None
    if not path.exists():
        check_writable(path)  # before the first steps, not at the first save
        return None
    solver, meta = OnlineSolver.load(path)
    # Checkpoints written before an option existed solved as its default does now.
    defaults = {"decide_at_arrival": False, "boundary_share": OnlineOptions().boundary_share}
    saved = {key: meta.get(key, defaults.get(key)) for key in settings}
    if saved != settings:
        differs = (f"{key} {old!r} (this run: {settings[key]!r})" for key, old in saved.items() if old != settings[key])
        same_graph = saved["fingerprint"] == settings["fingerprint"]
        what = ", ".join(differs) if same_graph else "another graph or edge roles"
        raise EgncError(f"{path}: the checkpoint was written for {what}; resume with its settings or remove it")
    _check_prefix(path, solver, graph, known, steps)
    inserted = np.flatnonzero(arrivals < solver.steps)  # in file order; replayed in step order
    expected = graph.vertex_ids[graph.priors.rows[inserted[np.argsort(arrivals[inserted], kind="stable")]]]
    if not np.array_equal(solver.prior_ids, expected):
        raise EgncError(f"{path}: the checkpoint's priors are not this input's after {solver.steps} steps; remove it")
    return solver


def _check_prefix(
    path: Path, solver: OnlineSolver, graph: PoseGraph, known: np.ndarray, steps: list[ReplayStep]
) -> None:
    """Refuse a checkpoint's `solver` whose graph is not that of the replay's first `solver.steps`
    `steps` of `graph` (`known`: `(E,)` roles): its poses, edges, roles, measurements and
    information. Its fingerprint names the input; this catches a checkpoint edited since."""
    done = solver.steps
    inserted = np.concatenate([step.edges for step in steps[:done]] or [np.zeros(0, dtype=np.int64)])
    refuse = f"{path}: the checkpoint's graph is not this input's after {done} steps"
    if done > len(steps) or len(inserted) != solver.num_edges:
        raise EgncError(f"{refuse} ({solver.num_edges} edges, expected {len(inserted)}); remove it")
    ids = graph.vertex_ids[graph.edges[inserted]]
    gauge = graph.vertex_ids[gauge_row(graph)]
    if not np.array_equal(np.sort(solver.vertex_ids), np.union1d(ids.ravel(), [gauge])):
        raise EgncError(f"{refuse} (other poses); remove it")
    differs = (
        np.any(solver.edge_ids != ids, axis=1)
        | (solver.is_loop_closure == known[inserted])
        | np.any(solver.measurements != graph.measurements[inserted], axis=1)
        | np.any(solver.information != graph.information[inserted], axis=(1, 2))
    )
    if differs.any():
        first = int(inserted[np.argmax(differs)])
        line = int(graph.edge_lines[first])
        where = f" (line {line})" if line else ""
        i, j = graph.vertex_ids[graph.edges[first]].tolist()
        raise EgncError(f"{refuse}: its edge ({i}, {j}){where} differs (edited?); remove it")


def _in_file_order(result: Result, steps: list[ReplayStep], arrivals: np.ndarray, graph: PoseGraph) -> Result:
    """`result` of the whole replay of `graph` in `steps` (edges and priors in insertion order;
    `arrivals`: `(K,)` each prior's step) with edges and priors in file order."""
    inserted = np.concatenate([step.edges for step in steps]) if steps else np.zeros(0, dtype=np.int64)
    prior_order = np.argsort(arrivals, kind="stable")  # prior k was inserted as prior position[k]
    position = np.empty_like(inserted)
    position[inserted] = np.arange(len(inserted))  # file edge f was inserted as edge position[f]
    prior_position = np.empty_like(prior_order)
    prior_position[prior_order] = np.arange(len(prior_order))
    solved = result.graph
    if not np.array_equal(solved.vertex_ids, graph.vertex_ids):
        raise EgncError("the replay did not take in every pose of the graph")
    reordered = replace(
        graph,
        poses=solved.poses,
        fixed=solved.fixed,
    )
    per_edge = {
        name: getattr(result, name)[position]
        for name in ("residual_norms", "weights", "mu", "known_inliers", "inliers", "robust_residual_norms")
    }
    per_prior = {
        name: getattr(result, name)[prior_position]
        for name in ("prior_residual_norms", "prior_inliers", "prior_candidates")
        if getattr(result, name) is not None
    }
    return replace(result, graph=reordered, **per_edge, **per_prior)


def latency_summary(update_ms: np.ndarray) -> dict[str, float]:
    """`{"p50", "p99", "max"}` of per-update times in milliseconds (all 0 without updates)."""
    if len(update_ms) == 0:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0}
    p50, p99 = np.percentile(update_ms, [50, 99])
    return {"p50": float(p50), "p99": float(p99), "max": float(np.max(update_ms))}
