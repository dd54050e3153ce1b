"""Fuzz `OnlineSolver.load` with damaged and inconsistent checkpoint files.

Each case takes a checkpoint that a short online replay wrote (the first poses of
datasets/grid2d_outliers.g2o or datasets/grid3d_outliers.g2o, loop closures included) and changes
it by one operator (`OPERATORS`): its bytes (cut short, bytes overwritten, emptied, replaced by a
g2o file) or one entry, the archive written again (an array dropped, cut by a row, given another
type or shape, a NaN, a non-rigid pose, an information matrix that is not positive definite or an
edge index out of range; a setting dropped or given a junk value; settings that are not JSON).
Most of these keep the checkpoint's digest, which no longer matches; half of the entry operators
make it again, so that the checks behind it are reached. Since issue 56, "edited and saved
again" loads the checkpoint with NumPy, changes one measurement, information matrix, `robust`
flag, pose or `mu` by a plausible amount and saves it with `np.savez` (as version 1 without a
digest in a third of the cases): that checkpoint must not resume.

Loading must end in an `EgncError` with a one-line message naming the file, or give a solver that
takes one more pose and odometry edge, updates and returns a result with finite poses (or an
`EgncError`), all within `fuzz_core.TIME_LIMIT_S`. An edited checkpoint is also resumed as
`egnc-solve --online --checkpoint` does (`replay` of the graph it was written for): that must end
in such an `EgncError` ("refused edit"), or in the uninterrupted run's result for an edit that
the graph check cannot see in a version 1 file (a pose or `mu`; "resumed"). Anything else is a
bug: another exception from loading or after it ("crash"; NumPy's `IndexError`, `KeyError`,
`zipfile.BadZipFile` ...), a hang, a multi-line message, a message without the file's name,
non-finite poses, or an edit resumed to another graph ("edit resumed").

Run from `benchmarks/fuzz.py --target checkpoints`; `tests/test_fuzz.py` runs fewer cases.
"""

from __future__ import annotations

import io
import json
import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.api import Result
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io import read_g2o
from egnc.io.checkpoint import content_digest
from egnc.nonlinear.factors import group_of, to_matrices
from egnc.online import OnlineSolver
from egnc.online.replay import replay

from .fuzz_core import TIME_LIMIT_S, Hang, outcomes_table, time_limit
from .paths import SHIPPED_DATASETS

CLASSES = ("clean error", "resumed", "refused edit", "message without the file", "multi-line message",
           "non-finite result", "edit resumed", "crash", "hang")  # fmt: skip
BAD = CLASSES[3:]
POSES = 25
"""Poses of the replay whose checkpoint each case changes."""
EDIT_POSES, EDIT_STEPS = 60, 40
"""The edited checkpoints' replay: its poses, and the steps after which it is interrupted (loop
closures included, so that an edit changes the map)."""
JUNK_SETTINGS: tuple[object, ...] = (None, -1, 0, 2.5, True, "x", [], {}, [1, 2], 10**30, {"a": 1})


@dataclass
class CheckpointCase:
    """One damaged checkpoint: the operator that made it, the graph's dimension and what happened."""

    operator: str
    dim: int
    outcome: str


def base_checkpoints(folder: Path, poses: int = POSES, stop_after: int | None = None) -> dict[int, bytes]:
    """The bytes of a checkpoint of each dimension (2 and 3), written by a replay of `poses` poses
    (stopped after `stop_after` steps)."""
    checkpoints = {}
    for dim, graph in base_graphs(poses).items():
        path = folder / f"base{dim}.npz"
        replay(graph, "egnc", checkpoint=path, stop_after=stop_after)
        checkpoints[dim] = path.read_bytes()
        path.unlink()
    return checkpoints


def base_graphs(poses: int) -> dict[int, PoseGraph]:
    """The graphs of the base checkpoints (2D and 3D): the first `poses` poses of a shipped file."""
    names = {2: "grid2d_outliers.g2o", 3: "grid3d_outliers.g2o"}
    return {dim: read_g2o(SHIPPED_DATASETS / name).first_poses(poses) for dim, name in names.items()}


def _entries(blob: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    with np.load(io.BytesIO(blob), allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files if name != "settings"}
        return json.loads(str(data["settings"])), arrays


def _archive(
    settings: object, arrays: dict[str, np.ndarray], raw_settings: str | None = None, rng: random.Random | None = None
) -> bytes:
    """The archive of `settings` and `arrays`; with `rng`, half the time with their digest made again."""
    if rng is not None and isinstance(settings, dict) and "digest" in settings and rng.random() < 0.5:
        settings["digest"] = content_digest(settings, arrays)
    out = io.BytesIO()
    text = json.dumps(settings) if raw_settings is None else raw_settings
    np.savez(out, settings=np.array(text), **arrays)  # type: ignore[arg-type]
    return out.getvalue()


def _changed_array(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    """One array changed: cut by a row, retyped, reshaped, or given a NaN."""
    name = rng.choice(sorted(arrays))
    array = arrays[name]
    change = rng.randrange(4)
    if change == 0 and array.ndim and len(array):
        arrays[name] = array[:-1]
    elif change == 1:
        arrays[name] = array.astype(rng.choice((np.float64, np.int64, np.bool_, np.str_)))
    elif change == 2:
        arrays[name] = array.reshape(-1) if array.ndim > 1 else array.reshape(-1, 1)
    elif array.dtype.kind == "f" and array.size:
        array = array.copy()
        array.flat[rng.randrange(array.size)] = np.nan
        arrays[name] = array
    else:
        arrays[name] = np.array(rng.choice((0, "x", 1.5)))
    return _archive(settings, arrays, rng=rng)


def _broken_values(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    """Arrays of the right shape and type whose values are wrong."""
    arrays = {name: array.copy() for name, array in arrays.items()}
    change = rng.randrange(4)
    if change == 0:  # a pose that is not rigid
        name = rng.choice(("T", "T_initial", "Z_inv"))
        arrays[name][rng.randrange(len(arrays[name]))][0, 0] *= rng.choice((2.0, -1.0, 0.0))
    elif change == 1:  # an information matrix that is not positive definite
        arrays["information"][rng.randrange(len(arrays["information"]))] *= rng.choice((-1.0, 0.0))
    elif change == 2:  # an edge to a pose that is not there
        arrays["edges"][rng.randrange(len(arrays["edges"])), rng.randrange(2)] = rng.choice((-1, 10**9))
    else:  # a repeated vertex id, or mu outside [0, 1]
        if rng.random() < 0.5:
            arrays["vertex_ids"][-1] = arrays["vertex_ids"][0]
        else:
            arrays[rng.choice(("mu", "mu_init"))][0] = rng.choice((-0.5, 1.5))
    return _archive(settings, arrays, rng=rng)


def _changed_setting(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    key = rng.choice(sorted(settings))
    settings[key] = rng.choice(JUNK_SETTINGS)
    return _archive(settings, arrays, rng=rng)


def _dropped(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    if rng.random() < 0.5:
        del settings[rng.choice(sorted(settings))]
    else:
        del arrays[rng.choice(sorted(arrays))]
    return _archive(settings, arrays, rng=rng)


EDITABLE = ("measurements", "information", "robust", "T", "mu")
"""The arrays "edited and saved again" changes (the graph's, then the estimate's)."""


def _edited(blob: bytes, rng: random.Random) -> bytes:
    """One value of the checkpoint changed by a plausible amount, saved again with `np.savez` as
    a user editing it would: digest kept (stale), or dropped with the version set to 1."""
    settings, arrays = _entries(blob)
    undigested = rng.random() < 1 / 3
    name = rng.choice(EDITABLE[:3] if undigested else EDITABLE)  # version 1: what the graph check sees
    array = arrays[name].copy()
    k = rng.randrange(len(array))
    if name == "robust":
        array[k] = not array[k]
    elif name == "information":
        array[k] *= rng.choice((0.5, 2.0))
    elif name == "T":
        array[k, 0, -1] += rng.choice((-0.5, 0.5))
    elif name == "mu":
        array[k] = 1.0 - array[k]
    else:  # and the inverse transform the solver works with, so the edit is not inert
        array[k, rng.randrange(2)] += rng.choice((-0.5, 0.5))
        dim = settings["dim"]
        arrays["Z_inv"] = arrays["Z_inv"].copy()
        arrays["Z_inv"][k] = group_of(dim).inverse(to_matrices(dim, array[k]))
    arrays[name] = array
    if undigested:
        del settings["digest"]
        settings["version"] = 1
    return _archive(settings, arrays)


def _with_bytes(blob: bytes, rng: random.Random) -> bytes:
    data = bytearray(blob)
    for _ in range(rng.randint(1, 8)):
        data[rng.randrange(len(data))] = rng.randrange(256)
    return bytes(data)


OPERATORS: dict[str, Callable[[bytes, random.Random], bytes]] = {
    "cut short": lambda blob, rng: blob[: rng.randrange(len(blob))],
    "bytes overwritten": _with_bytes,
    "empty": lambda blob, rng: b"",
    "a g2o file": lambda blob, rng: (SHIPPED_DATASETS / "grid2d.g2o").read_bytes()[:2000],
    "an array changed": lambda blob, rng: _changed_array(*_entries(blob), rng),
    "wrong values": lambda blob, rng: _broken_values(*_entries(blob), rng),
    "a setting changed": lambda blob, rng: _changed_setting(*_entries(blob), rng),
    "an entry dropped": lambda blob, rng: _dropped(*_entries(blob), rng),
    "settings not JSON": lambda blob, rng: _archive(None, _entries(blob)[1], raw_settings="{'version': 1"),
    "settings not an object": lambda blob, rng: _archive(rng.choice(([1], "x", 3)), _entries(blob)[1]),
    "edited and saved again": _edited,
}


def run_case(path: Path, edit_of: tuple[PoseGraph, Result] | None = None) -> str:
    """Load the checkpoint at `path`, and resume one update from it; classify what happened. With
    `edit_of` (an edited checkpoint's graph and the uninterrupted replay's result), resume the
    replay from it instead, as `egnc-solve --online --checkpoint` does."""
    try:
        with time_limit(TIME_LIMIT_S):
            try:
                if edit_of is not None:
                    return _resumed_replay(path, *edit_of)
                solver, _ = OnlineSolver.load(path)
            except EgncError as error:
                message = str(error)
                if "\n" in message:
                    return "multi-line message"
                if str(path) not in message:
                    return "message without the file"
                return "clean error" if edit_of is None else "refused edit"
            return _resumed(solver)
    except Hang:
        return "hang"
    except Exception:  # noqa: BLE001 - the class of failure is the finding
        return "crash"


def _resumed_replay(path: Path, graph: PoseGraph, whole: Result) -> str:
    """Resume the replay of `graph` from the edited checkpoint `path`: "resumed" where it ends as
    the uninterrupted run (`whole`) does, "edit resumed" where the edit changed the result."""
    result = replay(graph, "egnc", checkpoint=path).result
    same = np.array_equal(result.graph.poses, whole.graph.poses) and np.array_equal(result.inliers, whole.inliers)
    return "resumed" if same else "edit resumed"


def _resumed(solver: OnlineSolver) -> str:
    """One more pose and odometry edge, an update and a result from a loaded `solver`."""
    ids = solver.vertex_ids
    if not len(ids):
        return "resumed"
    last, new = int(ids[-1]), int(ids.max()) + 1
    identity = [0.0, 0.0, 0.0] if solver.dim == 2 else [0.0] * 6 + [1.0]
    try:
        solver.add_pose(new)
        solver.add_odometry(last, new, identity, np.eye(3 if solver.dim == 2 else 6))
        solver.update()
        poses = solver.result(decide=False).graph.poses
    except EgncError:
        return "resumed"
    return "resumed" if np.all(np.isfinite(poses)) else "non-finite result"


def fuzz_checkpoints(cases: int, seed: int, folder: Path) -> list[CheckpointCase]:
    """Run `cases` damaged checkpoints, operators and dimensions drawn from one seed."""
    rng = random.Random(seed)
    bases = base_checkpoints(folder)
    edit_bases = base_checkpoints(folder, EDIT_POSES, EDIT_STEPS)
    graphs = base_graphs(EDIT_POSES)
    wholes = {dim: replay(graph, "egnc").result for dim, graph in graphs.items()}
    results = []
    for case in range(cases):
        operator, dim = rng.choice(sorted(OPERATORS)), rng.choice((2, 3))
        path = folder / f"case{case}.npz"
        edited = operator == "edited and saved again"
        path.write_bytes(OPERATORS[operator]((edit_bases if edited else bases)[dim], rng))
        edit_of = (graphs[dim], wholes[dim]) if edited else None
        results.append(CheckpointCase(operator, dim, run_case(path, edit_of)))
        path.unlink()
    return results


def table(results: list[CheckpointCase]) -> str:
    """Markdown: per operator, the cases by outcome class."""
    return outcomes_table(((case.operator, case.outcome) for case in results), CLASSES, "cases", "operator")


def run_target(cases: int, seed: int) -> tuple[str, int]:
    """The checkpoint target for `fuzz.py`: its table and the number of cases that are bugs."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        results = fuzz_checkpoints(cases, seed, Path(folder))
    return table(results), sum(case.outcome in BAD for case in results)
