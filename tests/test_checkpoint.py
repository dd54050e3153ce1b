"""A damaged or inconsistent checkpoint is refused with one line naming the file (egnc.io.checkpoint)."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.errors import EgncError
from egnc.io.checkpoint import content_digest
from egnc.online import OnlineSolver
from egnc.online.replay import replay

DATA = Path(__file__).parents[1] / "datasets"


@pytest.fixture(scope="module", params=["grid2d_outliers.g2o", "grid3d_outliers.g2o"])
def checkpoint(request, tmp_path_factory) -> bytes:
    """The bytes of a checkpoint of a replay of 40 poses with loop closures (2D, 3D)."""
    path = tmp_path_factory.mktemp("checkpoint") / "state.npz"
    replay(egnc.read_g2o(DATA / request.param).first_poses(40), "egnc", checkpoint=path)
    return path.read_bytes()


def _entries(blob: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    with np.load(io.BytesIO(blob)) as data:
        arrays = {name: data[name] for name in data.files if name != "settings"}
        return json.loads(str(data["settings"])), arrays


def _write(path: Path, settings: object, arrays: dict[str, np.ndarray]) -> Path:
    """A checkpoint of `settings` and `arrays` with their digest made again: its checks beyond the digest."""
    if isinstance(settings, dict) and "digest" in settings:
        settings["digest"] = content_digest(settings, arrays)
    np.savez(path, settings=np.array(json.dumps(settings)), **arrays)  # type: ignore[arg-type]
    return path


def test_the_written_checkpoint_loads(checkpoint, tmp_path):
    path = tmp_path / "state.npz"
    path.write_bytes(checkpoint)
    solver, meta = OnlineSolver.load(path)
    assert solver.num_poses == 40 and "fingerprint" in meta


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda blob: b"", r"not an egnc checkpoint \(an empty file\)"),
        (lambda blob: (DATA / "grid2d.g2o").read_bytes(), r"not an egnc checkpoint \(not a NumPy .npz archive\)"),
        (lambda blob: blob[: len(blob) // 2], "damaged checkpoint"),
        (lambda blob: blob[:200] + bytes(255 - b for b in blob[200:260]) + blob[260:], "damaged checkpoint"),
    ],
    ids=["empty", "a g2o file", "cut in half", "bytes overwritten"],
)
def test_a_damaged_file_is_one_error_naming_it(checkpoint, tmp_path, damage, message):
    path = tmp_path / "state.npz"
    path.write_bytes(damage(checkpoint))
    with pytest.raises(EgncError, match=message) as error:
        OnlineSolver.load(path)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)


def _not_rigid(arrays):
    arrays["T"][3, 0, 0] = 2.0


def _indefinite(arrays):
    arrays["information"][1] *= -1.0


def _edge_out_of_range(arrays):
    arrays["edges"][2, 1] = len(arrays["vertex_ids"])


def _repeated_id(arrays):
    arrays["vertex_ids"][5] = arrays["vertex_ids"][4]


def _nan_pose(arrays):
    arrays["T_initial"][0, 0, 2] = np.nan


def _mu_above_one(arrays):
    arrays["mu"][-1] = 1.5


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda arrays: arrays.pop("Z_inv"), r"inconsistent checkpoint \(no Z_inv\)"),
        (lambda arrays: arrays.update(r=arrays["r"][:-1]), r"r is float64 \(\d+,\), expected float \(\d+,\)"),
        (lambda arrays: arrays.update(robust=arrays["robust"].astype(float)), "robust is float64"),
        (lambda arrays: arrays.update(edges=np.array(3)), "edges is a single number"),
        (_nan_pose, "T_initial holds a non-finite number"),
        (_not_rigid, "T holds a matrix that is not a rigid transform"),
        (_indefinite, "information holds a matrix that is not symmetric positive definite"),
        (_edge_out_of_range, "edges name poses outside 0..39"),
        (_repeated_id, "vertex_ids repeats an id"),
        (_mu_above_one, r"mu is outside \[0, 1\]"),
        (lambda arrays: arrays.update(update_ms=arrays["update_ms"][:-1]), "update_iterations is int64"),
    ],
    ids=["missing", "short", "retyped", "scalar", "nan", "not rigid", "indefinite", "edge range", "repeated id",
         "mu", "steps"],  # fmt: skip
)
def test_arrays_that_do_not_fit_together_are_refused(checkpoint, tmp_path, change, message):
    settings, arrays = _entries(checkpoint)
    change(arrays)
    path = _write(tmp_path / "state.npz", settings, arrays)
    with pytest.raises(EgncError, match=message) as error:
        OnlineSolver.load(path)
    assert str(error.value).startswith(str(path))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda settings: settings.update(version=0), "checkpoint version 0, expected 2"),
        (lambda settings: settings.pop("gauge"), r"incomplete checkpoint \(settings without gauge\)"),
        (lambda settings: settings.update(dim=4), "dim is 4, expected 2 or 3"),
        (lambda settings: settings.update(steps=settings["steps"] + 1), r"steps is \d+, expected \d+"),
        (lambda settings: settings.update(gauge=-1), "gauge is -1"),
        (lambda settings: settings.update(meta=[1]), "meta is list"),
        (lambda settings: settings.update(method="gnc"), r"invalid checkpoint settings \(.*method"),
        (lambda settings: settings["options"].update(speed=2), r"invalid checkpoint settings \(.*speed"),
        (lambda settings: settings.update(converged_poses=0), "converged_poses is 0"),
    ],
)
def test_settings_that_do_not_fit_are_refused(checkpoint, tmp_path, change, message):
    settings, arrays = _entries(checkpoint)
    change(settings)
    path = _write(tmp_path / "state.npz", settings, arrays)
    with pytest.raises(EgncError, match=message):
        OnlineSolver.load(path)


def test_settings_that_are_not_a_json_object_are_refused(checkpoint, tmp_path):
    _, arrays = _entries(checkpoint)
    path = tmp_path / "state.npz"
    np.savez(path, settings=np.array("{'version': 1"), **arrays)  # type: ignore[arg-type]
    with pytest.raises(EgncError, match="its settings are not JSON"):
        OnlineSolver.load(path)
    _write(path, [1, 2], arrays)
    with pytest.raises(EgncError, match="not a JSON object"):
        OnlineSolver.load(path)


def test_the_cli_refuses_an_empty_checkpoint_in_one_line_and_writes_nothing(tmp_path):
    graph = tmp_path / "small.g2o"
    egnc.write_g2o(egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(30), graph)
    state, out = tmp_path / "state.npz", tmp_path / "out.g2o"
    state.write_bytes(b"")
    run = subprocess.run(
        [sys.executable, "-m", "egnc", str(graph), "--online", "--checkpoint", str(state), "-o", str(out), "-q"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 1
    assert run.stderr.strip().splitlines()[-1] == f"egnc-solve: error: {state}: not an egnc checkpoint (an empty file)"
    assert "Traceback" not in run.stderr and not out.exists()


def test_a_checkpoint_that_cannot_be_written_fails_before_the_first_step(tmp_path):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(30)
    steps = []
    with pytest.raises(EgncError, match=r"missing/state.npz: cannot write file: directory .*missing does not exist"):
        replay(graph, "egnc", checkpoint=tmp_path / "missing" / "state.npz", on_step=lambda *step: steps.append(step))
    assert steps == []


def _edited(path: Path, name: str, version: int = 2) -> None:
    """Load the checkpoint `path` with NumPy, change its array `name` (the first loop closure's
    measurement, or its `robust` flag), and save it again; as version 1 (no digest) on request."""
    with np.load(path) as data:
        arrays = {key: data[key].copy() for key in data.files}
    settings = json.loads(str(arrays["settings"]))
    loop = int(np.flatnonzero(arrays["robust"])[0])
    if name == "robust":
        arrays["robust"][loop] = False
    else:
        arrays["measurements"][loop, 0] += 0.5
    if version == 1:
        settings.pop("digest", None)
        settings["version"] = 1
    arrays["settings"] = np.array(json.dumps(settings))
    np.savez(path, **arrays)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["measurements", "robust"])
def test_a_checkpoint_edited_and_saved_again_is_refused(tmp_path, name):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(60)
    path = tmp_path / "state.npz"
    replay(graph, "egnc", checkpoint=path, stop_after=40)
    _edited(path, name)
    with pytest.raises(EgncError, match=r"state.npz: the checkpoint's content does not match its digest") as error:
        replay(graph, "egnc", checkpoint=path)
    assert str(error.value).startswith(str(path)) and "remove it" in str(error.value)
    # Written before the digest (version 1): refused where its graph is not the input's.
    replay(graph, "egnc", checkpoint=(again := tmp_path / "v1.npz"), stop_after=40)
    _edited(again, name, version=1)
    with pytest.raises(EgncError, match=r"v1.npz: the checkpoint's graph is not this input's after 40 steps: its edge"):
        replay(graph, "egnc", checkpoint=again)


def test_a_checkpoint_written_before_the_digest_resumes_where_its_graph_is_the_inputs(tmp_path):
    graph = egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(60)
    path = tmp_path / "state.npz"
    replay(graph, "egnc", checkpoint=path, stop_after=40)
    settings, arrays = _entries(path.read_bytes())
    del settings["digest"]
    settings["version"] = 1
    _write(path, settings, arrays)
    resumed = replay(graph, "egnc", checkpoint=path)
    whole = replay(graph, "egnc")
    assert resumed.resumed_from == 40
    np.testing.assert_array_equal(resumed.result.graph.poses, whole.result.graph.poses)
    np.testing.assert_array_equal(resumed.result.inliers, whole.result.inliers)


def test_the_cli_refuses_an_edited_checkpoint_naming_it(tmp_path):
    graph = tmp_path / "small.g2o"
    egnc.write_g2o(egnc.read_g2o(DATA / "grid2d_outliers.g2o").first_poses(60), graph)
    state, out = tmp_path / "state.npz", tmp_path / "out.g2o"
    replay(egnc.read_g2o(graph), "egnc", checkpoint=state, stop_after=40)
    _edited(state, "robust")
    run = subprocess.run(
        [sys.executable, "-m", "egnc", str(graph), "--online", "--checkpoint", str(state), "-o", str(out), "-q"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 1 and not out.exists()
    assert run.stderr.strip().startswith(f"egnc-solve: error: {state}: the checkpoint's content does not match")
