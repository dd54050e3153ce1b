"""Recordings of a solve for the Rerun viewer (the `rerun` extra): what a solve did, on a timeline.

A plot shows where a solve ended; a recording shows its course. Rerun (`pip install rerun-sdk`) is
the viewer robotics projects log to: a recording holds entities (paths) whose values change along
timelines, written to an `.rrd` file or streamed to a running viewer, also inside a notebook.

- `log_result(result, recording, initial=graph)`: a batch solve on the `stage` timeline. Static:
  `initial/trajectory` (the initial guess, grey), `result/trajectory`, `result/loops/accepted`
  (coloured by IRLS weight, grey at 0 to green at 1), `result/loops/rejected` (red),
  `result/residuals` (every edge's whitened residual, a bar chart), `result/summary` (text). At
  stage `k` (1-based, one per `Result.stages`): `stages/cost`, `stages/mu` (min, mean, max),
  `stages/iterations`, `stages/log` (text); at stage 0 `stages/trajectory` is the initial guess.
- `StageRecorder`: `egnc.solve`'s `on_stage` callback that adds `stages/trajectory`, the poses at
  the end of each stage (`StageReport.poses`), on the same timeline.
- `OnlineRecorder`: `OnlineSolver`'s `on_update` hook; every update on the `update` timeline
  (`UpdateReport.step`): `online/map/<k>` (the trajectory in strips of `BLOCK` poses, each
  logged again when its poses moved: the last one as poses arrive, the few a loop update's
  region moved), `online/loops/<k>` (the loop closures in batches of `BLOCK` arrows, green when
  accepted and red when rejected by `OnlineSolver.inliers`, logged again when they moved or
  changed sides), `online/latency_ms`, `online/loop_counts` (accepted, rejected),
  `online/new_loops/mu` (each new loop's `mu` per stage, on the `stage` timeline too) and
  `online/log` (one line per update that brought loop closures).
- `recording(path, connect)`: a recording that writes `path` atomically (the file is complete or
  not there: it is written to a temporary and renamed when the block succeeds) and/or streams to
  the viewer at `connect`.
- `notebook_viewer(path)`: the viewer inside a notebook cell, showing a recorded `.rrd` file (the
  `rerun-notebook` package, which the `rerun` extra brings).

Positions are the poses' translations (`(N, 2)` or `(N, 3)`), so a 3D graph is drawn in 3D. Rerun
is imported inside the functions: `import egnc.rerun` works without it, and a function called
without it raises `EgncError` with the install command.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from egnc.api import Result
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io.atomic import atomic_path
from egnc.online import OnlineSolver, UpdateReport
from egnc.plot import ACCEPTED_COLOR, REJECTED_COLOR, RESULT_COLOR
from egnc.robust.gnc import StageCallback, StageReport

if TYPE_CHECKING:
    import rerun as rr

__all__ = [
    "DEFAULT_VIEWER_URL",
    "OnlineRecorder",
    "StageRecorder",
    "log_result",
    "notebook_viewer",
    "recording",
    "require_rerun",
]

INSTALL_HINT = "pip install 'egnc[rerun]'"
"""How to get the Rerun SDK; quoted in the error raised without it."""

DEFAULT_VIEWER_URL = "rerun+http://127.0.0.1:9876/proxy"
"""Where a viewer started with `rerun` listens (the SDK's own default)."""

APPLICATION_ID = "egnc"
"""The application a recording belongs to; the viewer groups recordings by it."""


def _rgb(hex_color: str) -> tuple[int, int, int]:
    """`(r, g, b)` bytes of `"#rrggbb"`."""
    return int(hex_color[1:3], 16), int(hex_color[3:5], 16), int(hex_color[5:7], 16)


# The palette of egnc.plot, so a colour means the same in a figure and in the viewer.
RESULT_RGB = _rgb(RESULT_COLOR)
INITIAL_RGB = (153, 153, 153)
ACCEPTED_RGB = _rgb(ACCEPTED_COLOR)
REJECTED_RGB = _rgb(REJECTED_COLOR)


def require_rerun() -> Any:
    """The `rerun` module, or `EgncError` naming the extra to install."""
    try:
        import rerun
    except ImportError:
        raise EgncError(f"recording for the Rerun viewer needs the Rerun SDK: {INSTALL_HINT}") from None
    return rerun


@contextlib.contextmanager
def recording(path: str | Path | None = None, connect: str | None = None) -> Iterator[rr.RecordingStream]:
    """A new recording that writes `path` and/or streams to the viewer at `connect`, for the block.

    Args:
        path: the `.rrd` file; written to a temporary beside it and renamed over it when the block
            succeeds (inside `egnc.io.atomic.all_or_nothing`, when that block does), removed if it fails.
        connect: the URL of a running viewer (`DEFAULT_VIEWER_URL` for one started with `rerun`);
            connecting does not block the block, only its end, which waits for the data to be sent.

    Raises:
        EgncError: the Rerun SDK is not installed, neither output is given, `path` cannot be
            written, or no viewer answered at `connect` when the block ended (`path` is then not written).
    """
    rr = require_rerun()
    if path is None and connect is None:
        raise EgncError("a recording needs a file to write or a viewer to connect to")
    stream = rr.RecordingStream(APPLICATION_ID)
    stream.set_log_time_enabled(False)  # the timelines are the solve's own: stages, updates
    with contextlib.ExitStack() as stack:
        sinks = [] if connect is None else [rr.GrpcSink(connect)]
        if path is not None:
            sinks.append(rr.FileSink(str(stack.enter_context(atomic_path(Path(path))))))
        stream.set_sinks(*sinks)
        try:
            yield stream
        finally:
            try:
                stream.flush()
            except RuntimeError as error:  # the SDK's only failure here: no viewer at `connect`
                raise EgncError(
                    f"{connect}: no Rerun viewer reachable there ({error}); start one with `rerun`"
                ) from None
            finally:
                stream.disconnect()  # closes the file before it is renamed


def notebook_viewer(path: str | Path, *, width: int | Literal["auto"] = "auto", height: int = 480) -> Any:
    """A Rerun viewer widget for a notebook cell that shows the recording in the `.rrd` file at `path`.

    The file's chunks are sent to a new recording the widget listens to, so the viewer shows
    exactly what the file holds (`recording(path)` wrote it; `egnc-solve --rerun` too). Display
    it by ending a cell with it, or with its `display()`.

    Args:
        path: the `.rrd` file.
        width: pixels, or `"auto"`: the cell's width.
        height: pixels.

    Raises:
        EgncError: the Rerun SDK or its notebook widget (`rerun-notebook`) is not installed.
    """
    rr = require_rerun()
    from rerun.chunk import RrdReader
    from rerun.notebook import HAS_NOTEBOOK, Viewer

    if not HAS_NOTEBOOK:
        raise EgncError(f"a viewer inside a notebook needs the rerun-notebook package: {INSTALL_HINT}")
    stream = rr.RecordingStream(APPLICATION_ID)
    viewer = Viewer(width=width, height=height, recording=stream)  # the widget is the stream's sink
    stream.send_chunks(RrdReader(Path(path)).stream())
    stream.flush()
    return viewer


def _positions(poses: np.ndarray) -> np.ndarray:
    """`(N, 2|3)` translations of `(N, n, n)` pose matrices or `(N, P)` stored poses (`x y ...`)."""
    if poses.ndim == 3:
        n = poses.shape[-1]
        return poses[:, : n - 1, n - 1]
    return poses[:, : 2 if poses.shape[1] == 3 else 3]


def _strips(rr: Any, strips: list[np.ndarray], colors: Any) -> Any:
    """`LineStrips2D` or `LineStrips3D` by the points' dimension."""
    archetype = rr.LineStrips3D if np.shape(strips[0])[-1] == 3 else rr.LineStrips2D
    return archetype(strips, colors=colors)


def _arrows(rr: Any, positions: np.ndarray, rows: np.ndarray, colors: Any) -> Any:
    """`Arrows2D` or `Arrows3D` from pose `i` to pose `j` of each edge of the `(K, 2)` pose `rows`.

    Arrows rather than two-point line strips: the SDK converts a batch of strips strip by strip,
    seven times slower for the loops of a whole map (2000 of them: 50 against 350 us).
    """
    origins = positions[rows[:, 0]]
    archetype = rr.Arrows3D if positions.shape[1] == 3 else rr.Arrows2D
    return archetype(origins=origins, vectors=positions[rows[:, 1]] - origins, colors=colors)


def weight_colors(weights: np.ndarray) -> np.ndarray:
    """`(K, 3)` uint8 colours of loops by IRLS weight: `INITIAL_RGB` grey at 0 to `ACCEPTED_RGB` at 1."""
    w = np.clip(np.nan_to_num(np.asarray(weights, dtype=float), nan=1.0), 0.0, 1.0)[:, None]
    return np.rint((1 - w) * np.array(INITIAL_RGB) + w * np.array(ACCEPTED_RGB)).astype(np.uint8)


def _stream(rr: Any, recording: rr.RecordingStream | None) -> rr.RecordingStream:
    """`recording`, else the global one (`rr.init`), else a new one (as for a notebook's viewer)."""
    if recording is not None:
        return recording
    return rr.get_global_data_recording() or rr.RecordingStream(APPLICATION_ID)


def log_result(
    result: Result, recording: rr.RecordingStream | None = None, *, initial: PoseGraph | None = None
) -> rr.RecordingStream:
    """Record a batch solve: its trajectory, loops, residuals and stages (module docstring).

    Args:
        result: the solve (`egnc.solve`).
        recording: where to log; None: the global recording (`rr.init`), else a new one.
        initial: the graph the solve started from (its poses are the initial guess); None leaves it out.

    Returns:
        The recording logged to (e.g. `log_result(result).notebook_show()` in a notebook).
    """
    rr = require_rerun()
    stream = _stream(rr, recording)
    if initial is not None:
        guess = _positions(initial.poses)
        stream.log("initial/trajectory", _strips(rr, [guess], INITIAL_RGB), static=True)
        stream.set_time("stage", sequence=0)
        stream.log("stages/trajectory", _strips(rr, [guess], INITIAL_RGB))
    _log_stages(rr, stream, result.stages)
    graph = result.graph
    positions = _positions(graph.poses)
    loops = ~result.known_inliers
    rejected = loops & ~result.inliers
    accepted = loops & result.inliers
    stream.log("result/trajectory", _strips(rr, [positions], RESULT_RGB), static=True)
    stream.log(
        "result/loops/accepted",
        _arrows(rr, positions, graph.edges[accepted], weight_colors(result.weights[accepted])),
        static=True,
    )
    stream.log(
        "result/loops/rejected",
        _arrows(rr, positions, graph.edges[rejected], REJECTED_RGB),
        static=True,
    )
    stream.log("result/residuals", rr.BarChart(result.residual_norms), static=True)
    summary = (
        f"{result.method}: {int(accepted.sum())} loop closures accepted, {int(rejected.sum())} rejected,"
        f" {len(result.stages)} stages, {result.time_s:.3f} s; {result.message}"
    )
    stream.log("result/summary", rr.TextLog(summary), static=True)
    return stream


def _log_stages(rr: Any, stream: rr.RecordingStream, stages: tuple[StageReport, ...]) -> None:
    """Each stage's cost, `mu` statistics, iterations and one line of text at its 1-based number."""
    stream.log("stages/mu", rr.SeriesLines(names=["mu min", "mu mean", "mu max"]), static=True)
    for k, stage in enumerate(stages, start=1):
        stream.set_time("stage", sequence=k)
        stream.log("stages/cost", rr.Scalars(stage.cost))
        stream.log("stages/iterations", rr.Scalars(stage.iterations))
        if not np.isnan(stage.mu_mean):
            stream.log("stages/mu", rr.Scalars([stage.mu_min, stage.mu_mean, stage.mu_max]))
        stream.log(
            "stages/log",
            rr.TextLog(
                f"stage {k} ({stage.kind}, {stage.start} start): {stage.iterations} iterations, cost"
                f" {stage.cost:.6g}, {stage.active_edges} edges, {stage.time_s:.3f} s"
            ),
        )
    stream.disable_timeline("stage")


class StageRecorder:
    """`egnc.solve`'s `on_stage` callback: each stage's poses as `stages/trajectory` at its number.

    Args:
        recording: where to log; None: the global recording, else a new one.
        then: another `on_stage` callback to call after recording (a progress display).

    The stages are numbered as `Result.stages`, from 1, so that `log_result` afterwards puts each
    stage's statistics beside its poses.
    """

    def __init__(self, recording: rr.RecordingStream | None = None, then: StageCallback | None = None):
        self._rr = require_rerun()
        self.recording = _stream(self._rr, recording)
        self._then = then
        self.stages = 0

    def __call__(self, report: StageReport) -> None:
        """Record the stage of `report` (its `poses`, when it carries them)."""
        self.stages += 1
        if report.poses is not None:
            self.recording.set_time("stage", sequence=self.stages)
            self.recording.log("stages/trajectory", _strips(self._rr, [_positions(report.poses)], RESULT_RGB))
            self.recording.disable_timeline("stage")
        if self._then is not None:
            self._then(report)


FLUSH_EVERY = 64
"""Updates an `OnlineRecorder` holds the rows of its scalars and text for before sending them as columns.

One `log` call per row and entity costs tens of microseconds, more on a loaded machine; sent as
columns, the four rows of each of manhattan_noisy's 3500 updates cost a few calls per 64 updates.
"""

BLOCK = 256
"""Poses per `online/map/<k>` strip, and loop closures per `online/loops/<k>` batch of arrows.

An update re-logs only the blocks whose values changed: the last map block as poses arrive, the
few blocks a loop update's region moved. Logging the whole map after each loop update instead
cost 1.3 ms per update on manhattan_noisy (3500 poses, 2100 loops), more than the update itself.
"""


class _Blocks:
    """Rows of an array in blocks of `BLOCK`, and which blocks differ from those last logged."""

    def __init__(self, overlap: int):
        self._overlap = overlap  # rows a block shares with the next (1: map strips join)
        self._logged: np.ndarray | None = None

    def changed(self, values: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """`(k, rows of block k)` of every block of the `(K, W)` `values` that differs (or is new)."""
        old = values[:0] if self._logged is None else self._logged
        kept = min(len(old), len(values))
        differs = np.ones(len(values), dtype=bool)
        differs[:kept] = np.any(values[:kept] != old[:kept], axis=1)
        rows = np.flatnonzero(differs)
        touched = np.zeros(-(-len(values) // BLOCK), dtype=bool)
        touched[rows // BLOCK] = True
        touched[rows[(rows % BLOCK < self._overlap) & (rows >= BLOCK)] // BLOCK - 1] = True  # the block before
        self._logged = values  # the caller's own array, not changed after
        return [(int(k), values[k * BLOCK : (k + 1) * BLOCK + self._overlap]) for k in np.flatnonzero(touched)]


@dataclass
class _Rows:
    """The per-update rows an `OnlineRecorder` holds until its next `flush`."""

    steps: list[int] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    counts: list[tuple[int, int]] = field(default_factory=list)
    mu_steps: list[int] = field(default_factory=list)
    mu_stages: list[int] = field(default_factory=list)
    mu: list[np.ndarray] = field(default_factory=list)
    text_steps: list[int] = field(default_factory=list)
    text: list[str] = field(default_factory=list)
    blocks: dict[str, list[tuple[int, np.ndarray]]] = field(default_factory=dict)  # entity -> (update, values)


class OnlineRecorder:
    """`OnlineSolver`'s `on_update` hook: every update on the `update` timeline (module docstring).

    Use: `OnlineSolver(dim, on_update=OnlineRecorder(recording))`, or `replay(..., on_update=...)`;
    call `flush()` after the last update. The map and the loops are logged at once, in blocks
    (`BLOCK`); the scalars and text of every update are held and sent every `flush_every`
    updates and by `flush()`.

    Args:
        recording: where to log; None: the global recording, else a new one.
        flush_every: updates between two sends of the held rows (`FLUSH_EVERY`; 1: at once, live).
    """

    def __init__(self, recording: rr.RecordingStream | None = None, flush_every: int = FLUSH_EVERY):
        self._rr = require_rerun()
        self.recording = _stream(self._rr, recording)
        self.flush_every = flush_every
        self._rows = _Rows()
        self._map = _Blocks(overlap=1)
        self._loops = _Blocks(overlap=0)
        self._styled: set[str] = set()  # map strips whose colour is logged
        self._row_of: dict[int, int] = {}  # vertex id -> pose row, of the poses seen so far
        self._edge_rows = np.zeros((0, 2), dtype=np.int64)  # pose rows of the edges seen so far
        self.recording.log("online/loop_counts", self._rr.SeriesLines(names=["accepted", "rejected"]), static=True)

    def __call__(self, solver: OnlineSolver, report: UpdateReport) -> None:
        """Record the update of `report`, which `solver` has just made."""
        rows = self._rows
        positions = solver.positions.astype(np.float32)  # what the viewer stores
        loops = solver.is_loop_closure
        inliers = solver.inliers
        for k, block in self._map.changed(positions):
            rows.blocks.setdefault(f"online/map/{k}", []).append((report.step, block))
        if report.stages or len(report.new_loops):  # a loop may have moved or changed sides
            self._hold_loops(report.step, positions, self._pose_rows(solver)[loops], inliers[loops])
        rows.steps.append(report.step)
        rows.latency_ms.append(1e3 * report.time_s)
        rows.counts.append((int((loops & inliers).sum()), int((loops & ~inliers).sum())))
        if len(report.new_loops):
            self._hold_new_loops(report, inliers)
        if len(rows.steps) >= self.flush_every:
            self.flush()

    def _hold_loops(self, step: int, positions: np.ndarray, rows: np.ndarray, accepted: np.ndarray) -> None:
        """The blocks of loop closures that changed at update `step`: rows `[x_i, x_j, accepted]` of
        the `(L, 2)` pose `rows` (arrows from `i` to `j`) and the `(L,)` decision `accepted`."""
        values = np.column_stack((positions[rows[:, 0]], positions[rows[:, 1]], accepted.astype(np.float32)))
        for k, block in self._loops.changed(values):
            self._rows.blocks.setdefault(f"online/loops/{k}", []).append((step, block))

    def _pose_rows(self, solver: OnlineSolver) -> np.ndarray:
        """`(E, 2)` pose rows of `solver`'s edges; only the edges added since the last call are looked up."""
        ids = solver.vertex_ids
        for row in range(len(self._row_of), len(ids)):
            self._row_of[int(ids[row])] = row
        new = solver.edge_ids[len(self._edge_rows) :]
        looked_up = np.array([self._row_of[int(i)] for i in new.ravel()], dtype=np.int64).reshape(-1, 2)
        self._edge_rows = np.concatenate((self._edge_rows, looked_up))
        return self._edge_rows

    def _hold_new_loops(self, report: UpdateReport, inliers: np.ndarray) -> None:
        """The new loops' `mu` per stage (timeline `stage`, from 0) and one line of text."""
        rows = self._rows
        history = report.mu_history[:, : len(report.new_loops)]  # the new loops' columns (priors follow)
        for s, mu in enumerate(history):
            rows.mu_steps.append(report.step)
            rows.mu_stages.append(s)
            rows.mu.append(mu)
        kept = inliers[report.new_loops]
        how = "decided at arrival" if report.decided_at_arrival else f"{len(report.stages)} stages"
        mu = "; ".join(" -> ".join(f"{value:.3g}" for value in column) for column in history.T)
        rows.text_steps.append(report.step)
        rows.text.append(
            f"update {report.step}: loop closures {report.new_loops.tolist()}, {how}, mu {mu or 'unchanged'};"
            f" {int(kept.sum())} accepted, {int((~kept).sum())} rejected, {1e3 * report.time_s:.1f} ms"
        )

    def flush(self) -> None:
        """Send the rows held since the last flush (`flush_every`)."""
        rr, stream, rows = self._rr, self.recording, self._rows
        if not rows.steps:
            return
        update = rr.TimeColumn("update", sequence=rows.steps)
        stream.send_columns("online/latency_ms", indexes=[update], columns=rr.Scalars.columns(scalars=rows.latency_ms))
        counts = rr.Scalars.columns(scalars=np.array(rows.counts, dtype=float))
        stream.send_columns("online/loop_counts", indexes=[update], columns=counts)
        if rows.mu:
            stream.send_columns(
                "online/new_loops/mu",
                indexes=[
                    rr.TimeColumn("update", sequence=rows.mu_steps),
                    rr.TimeColumn("stage", sequence=rows.mu_stages),
                ],
                columns=rr.Scalars.columns(scalars=np.concatenate(rows.mu)).partition([len(mu) for mu in rows.mu]),
            )
        if rows.text:
            stream.send_columns(
                "online/log",
                indexes=[rr.TimeColumn("update", sequence=rows.text_steps)],
                columns=rr.TextLog.columns(text=rows.text),
            )
        for entity, held in rows.blocks.items():
            steps = rr.TimeColumn("update", sequence=[step for step, _ in held])
            stream.send_columns(entity, indexes=[steps], columns=self._block_columns(entity, [b for _, b in held]))
        self._rows = _Rows()

    def _block_columns(self, entity: str, blocks: list[np.ndarray]) -> Any:
        """The columns of a map strip's or a loop batch's held `blocks`, one row each."""
        rr = self._rr
        if entity.startswith("online/map/"):
            archetype = rr.LineStrips3D if blocks[0].shape[1] == 3 else rr.LineStrips2D
            if entity not in self._styled:
                self.recording.log(entity, archetype.from_fields(colors=RESULT_RGB), static=True)
                self._styled.add(entity)
            return archetype.columns(strips=blocks).partition([1] * len(blocks))
        values = np.concatenate(blocks)
        d = (values.shape[1] - 1) // 2
        archetype = rr.Arrows3D if d == 3 else rr.Arrows2D
        colors = np.where(values[:, -1:] > 0, ACCEPTED_RGB, REJECTED_RGB).astype(np.uint8)
        columns = archetype.columns(origins=values[:, :d], vectors=values[:, d : 2 * d] - values[:, :d], colors=colors)
        return columns.partition([len(block) for block in blocks])
