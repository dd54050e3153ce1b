"""Fuzz `OnlineSolver.load` with damaged and inconsistent checkpoint files.

Each case takes a checkpoint that a short online replay wrote (the first poses of
datasets/grid2d_outliers.g2o or datasets/grid3d_outliers.g2o, loop closures included) and changes
it by one operator (`OPERATORS`): its bytes (cut short, bytes overwritten, emptied, replaced by a
g2o file) or one entry, the archive written again (an array dropped, cut by a row, given another
type or shape, a NaN, a non-rigid pose, an information matrix that is not positive definite or an
edge index out of range; a setting dropped or given a junk value; settings that are not JSON).

Loading must end in an `EgncError` with a one-line message naming the file, or give a solver that
takes one more pose and odometry edge, updates and returns a result with finite poses (or an
`EgncError`), all within `fuzz_core.TIME_LIMIT_S`. Anything else is a bug: another exception from
loading or after it ("crash"; NumPy's `IndexError`, `KeyError`, `zipfile.BadZipFile` ...), a
hang, a multi-line message, a message without the file's name, or non-finite poses.

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

from egnc.errors import EgncError
from egnc.io import read_g2o
from egnc.online import OnlineSolver
from egnc.online.replay import replay

from .fuzz_core import TIME_LIMIT_S, Hang, outcomes_table, time_limit
from .paths import SHIPPED_DATASETS

CLASSES = ("clean error", "resumed", "message without the file", "multi-line message", "non-finite result",
           "crash", "hang")  # fmt: skip
BAD = CLASSES[2:]
POSES = 25
"""Poses of the replay whose checkpoint each case changes."""
JUNK_SETTINGS: tuple[object, ...] = (None, -1, 0, 2.5, True, "x", [], {}, [1, 2], 10**30, {"a": 1})


@dataclass
class CheckpointCase:
    """One damaged checkpoint: the operator that made it, the graph's dimension and what happened."""

    operator: str
    dim: int
    outcome: str


def base_checkpoints(folder: Path) -> dict[int, bytes]:
    """The bytes of a checkpoint of each dimension (2 and 3), written by a replay of `POSES` poses."""
    checkpoints = {}
    for dim, name in ((2, "grid2d_outliers.g2o"), (3, "grid3d_outliers.g2o")):
        path = folder / f"base{dim}.npz"
        replay(read_g2o(SHIPPED_DATASETS / name).first_poses(POSES), "egnc", checkpoint=path)
        checkpoints[dim] = path.read_bytes()
    return checkpoints


def _entries(blob: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    with np.load(io.BytesIO(blob), allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files if name != "settings"}
        return json.loads(str(data["settings"])), arrays


def _archive(settings: object, arrays: dict[str, np.ndarray], raw_settings: str | None = None) -> bytes:
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
    return _archive(settings, arrays)


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
    return _archive(settings, arrays)


def _changed_setting(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    key = rng.choice(sorted(settings))
    settings[key] = rng.choice(JUNK_SETTINGS)
    return _archive(settings, arrays)


def _dropped(settings: dict, arrays: dict[str, np.ndarray], rng: random.Random) -> bytes:
    if rng.random() < 0.5:
        del settings[rng.choice(sorted(settings))]
    else:
        del arrays[rng.choice(sorted(arrays))]
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
}


def run_case(path: Path) -> str:
    """Load the checkpoint at `path`, and resume one update from it; classify what happened."""
    try:
        with time_limit(TIME_LIMIT_S):
            try:
                solver, _ = OnlineSolver.load(path)
            except EgncError as error:
                message = str(error)
                if "\n" in message:
                    return "multi-line message"
                return "clean error" if str(path) in message else "message without the file"
            return _resumed(solver)
    except Hang:
        return "hang"
    except Exception:  # noqa: BLE001 - the class of failure is the finding
        return "crash"


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
    results = []
    for case in range(cases):
        operator, dim = rng.choice(sorted(OPERATORS)), rng.choice((2, 3))
        path = folder / f"case{case}.npz"
        path.write_bytes(OPERATORS[operator](bases[dim], rng))
        results.append(CheckpointCase(operator, dim, run_case(path)))
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
