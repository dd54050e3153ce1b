"""egnc.rerun: recordings read back without a viewer (entities, timelines, colours), `egnc-solve --rerun`.

Every test here needs the `rerun` extra (rerun-sdk) and is in the long tier (its ids name rerun).
"""

from __future__ import annotations

import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.io import read_g2o
from egnc.online.replay import replay

DATASETS = Path(__file__).parents[1] / "datasets"
RED = 0xD62728FF  # egnc.plot.REJECTED_COLOR, opaque, as Rerun packs it (0xRRGGBBAA)


@pytest.fixture(scope="module")
def rerun_egnc():
    """`egnc.rerun`, after checking the Rerun SDK (with its chunk reader) is installed."""
    pytest.importorskip("rerun.chunk", reason="needs the rerun extra: pip install 'egnc[rerun]'")
    from egnc import rerun as rerun_egnc

    return rerun_egnc


def read_back(path: Path) -> dict[str, list]:
    """Entity path -> the record batches of its chunks in an `.rrd` file."""
    from rerun.chunk import RrdReader

    batches = defaultdict(list)
    for chunk in RrdReader(path).stream():
        batches[chunk.entity_path].append(chunk.to_record_batch())
    return batches


def column(batches: list, name: str) -> list:
    """The values of column `name` over `batches`, row by row (absent rows skipped)."""
    return [value for batch in batches if name in batch.schema.names for value in batch.column(name).to_pylist()]


def timeline(batches: list, name: str) -> list[int]:
    """The sorted values of timeline `name` in `batches`."""
    return sorted(column(batches, name))


def latest(batches: list, name: str, time: str = "update"):
    """The value of column `name` at the last time of timeline `time` in `batches`."""
    rows = [
        (when, value)
        for batch in batches
        if name in batch.schema.names and time in batch.schema.names
        for when, value in zip(batch.column(time).to_pylist(), batch.column(name).to_pylist())
    ]
    return max(rows, key=lambda row: row[0])[1]


def test_rerun_batch_recording_has_every_stage_and_red_rejected_loops(rerun_egnc, tmp_path):
    graph = read_g2o(DATASETS / "grid3d_outliers.g2o")
    path = tmp_path / "solve.rrd"
    with rerun_egnc.recording(path) as stream:
        recorder = rerun_egnc.StageRecorder(stream)
        result = egnc.solve(graph, on_stage=recorder)
        rerun_egnc.log_result(result, stream, initial=graph)
    assert all(stage.poses is None for stage in result.stages), "Result.stages holds no poses"
    assert recorder.stages == len(result.stages) > 0
    batches = read_back(path)
    for entity in ("initial/trajectory", "result/trajectory", "result/loops/accepted", "result/residuals"):
        assert f"/{entity}" in batches
    stages = len(result.stages)
    assert timeline(batches["/stages/trajectory"], "stage") == list(range(stages + 1))  # 0: the initial guess
    assert timeline(batches["/stages/cost"], "stage") == list(range(1, stages + 1))
    rejected = int((~result.known_inliers & ~result.inliers).sum())
    assert rejected > 0
    colors = column(batches["/result/loops/rejected"], "Arrows3D:colors")
    assert len(colors) == 1 and set(colors[0]) == {RED}  # one colour for all: stored once
    assert len(column(batches["/result/loops/rejected"], "Arrows3D:origins")[0]) == rejected
    (residuals,) = column(batches["/result/residuals"], "BarChart:values")
    assert len(residuals) == 1  # one tensor
    points = column(batches["/result/trajectory"], "LineStrips3D:strips")[0][0]
    np.testing.assert_allclose(points, result.graph.poses[:, :3], rtol=1e-6, atol=1e-5)


def test_rerun_online_recording_has_every_update(rerun_egnc, tmp_path):
    graph = read_g2o(DATASETS / "grid2d_outliers.g2o")
    path = tmp_path / "online.rrd"
    with rerun_egnc.recording(path) as stream:
        recorder = rerun_egnc.OnlineRecorder(stream)
        outcome = replay(graph, on_update=recorder)
        recorder.flush()
    batches = read_back(path)
    steps = list(range(1, outcome.steps + 1))
    assert timeline(batches["/online/latency_ms"], "update") == steps
    assert timeline(batches["/online/loop_counts"], "update") == steps
    accepted, rejected = latest(batches["/online/loop_counts"], "Scalars:scalars")
    loops, inliers = outcome.solver.is_loop_closure, outcome.solver.inliers
    assert (accepted, rejected) == (np.sum(loops & inliers), np.sum(loops & ~inliers))
    # every loop update is in the text log and has its new loops' mu per stage
    loop_updates = len(column(batches["/online/log"], "TextLog:text"))
    assert loop_updates > 0 and len(timeline(batches["/online/new_loops/mu"], "update")) >= loop_updates
    # the last map blocks, joined, are the solver's trajectory
    blocks = sorted((int(name.rsplit("/", 1)[1]), name) for name in batches if name.startswith("/online/map/"))
    last = [np.array(latest(batches[name], "LineStrips2D:strips")[0]) for _, name in blocks]
    joined = np.concatenate([block[:-1] for block in last[:-1]] + [last[-1]])
    np.testing.assert_allclose(joined, outcome.solver.positions, rtol=1e-6, atol=1e-4)
    rejected_colors = {
        color
        for name in batches
        if name.startswith("/online/loops/")
        for row in column(batches[name], "Arrows2D:colors")
        for color in row
    }
    assert RED in rejected_colors


def test_rerun_unused_hooks_change_nothing(rerun_egnc):
    graph = read_g2o(DATASETS / "grid2d_outliers.g2o")
    stream = rerun_egnc.require_rerun().RecordingStream("egnc-test")  # no sink: logs go nowhere
    plain = egnc.solve(graph)
    recorded = egnc.solve(graph, on_stage=rerun_egnc.StageRecorder(stream))
    np.testing.assert_array_equal(plain.graph.poses, recorded.graph.poses)
    np.testing.assert_array_equal(plain.inliers, recorded.inliers)


def test_rerun_cli_writes_the_recording_atomically(rerun_egnc, tmp_path):
    path = tmp_path / "run.rrd"
    command = [sys.executable, "-m", "egnc", str(DATASETS / "grid2d_outliers.g2o"), "-q", "--rerun", str(path)]
    subprocess.run(command, check=True, timeout=300)
    assert "/result/loops/rejected" in read_back(path)
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]  # no temporary left
    # an output that cannot be written: no recording either, and no temporary
    failing = tmp_path / "failing.rrd"
    bad = tmp_path / "missing" / "out.g2o"
    done = subprocess.run([*command[:-1], str(failing), "-o", str(bad)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "missing" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.rrd"]


def test_rerun_import_egnc_does_not_import_rerun():
    code = "import egnc, egnc.rerun, egnc.cli.solve, sys; print('rerun' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert done.stdout.strip() == "False"


def test_rerun_notebook_viewer_names_the_widget_it_needs(rerun_egnc, tmp_path, monkeypatch):
    import rerun.notebook

    path = tmp_path / "run.rrd"
    with rerun_egnc.recording(path) as stream:
        rerun_egnc.log_result(egnc.solve(read_g2o(DATASETS / "grid2d.g2o")), stream)
    monkeypatch.setattr(rerun.notebook, "HAS_NOTEBOOK", False)  # as without rerun-notebook installed
    with pytest.raises(egnc.EgncError, match="rerun-notebook package: pip install 'egnc\\[rerun\\]'"):
        rerun_egnc.notebook_viewer(path)
