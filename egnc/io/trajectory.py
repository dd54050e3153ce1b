"""Write a graph's poses as a trajectory for evaluation tools (evo, the TUM and KITTI scripts).

- TUM: one line per pose, `timestamp x y z qx qy qz qw`; the vertex id is the timestamp, so two
  trajectories of the same graph associate pose by pose (`evo_ape tum REF OUT`).
- KITTI: one line per pose, the 12 numbers of the 3 x 4 matrix `[R | t]`, row-major, in vertex-id
  order (no timestamp: tools pair lines by position).

2D poses become 3D ones in the plane: `z = 0` and the rotation `theta` about the z axis.
The format comes from the suffix (`.tum`, `.kitti`) or is given; `.txt` is used by both formats,
so it, like any other suffix, needs the format named.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

import numpy as np

from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io.atomic import atomic_text_file
from egnc.io.numbers import format_floats
from egnc.lie import se3

TrajectoryFormat = Literal["tum", "kitti"]
TRAJECTORY_FORMATS: tuple[TrajectoryFormat, ...] = ("tum", "kitti")
_SUFFIXES: dict[str, TrajectoryFormat] = {".tum": "tum", ".kitti": "kitti"}


def trajectory_format(path: str | os.PathLike, file_format: TrajectoryFormat | None = None) -> TrajectoryFormat:
    """The format to write `path` in: `file_format` if given, else the one its suffix names.

    Raises:
        EgncError: no format given and the suffix names none (e.g. `.txt`, used by both).
    """
    if file_format is not None:
        return file_format
    suffix = Path(path).suffix.lower()
    if suffix not in _SUFFIXES:
        raise EgncError(
            f"{path}: cannot tell the trajectory format from the suffix {suffix or '(none)'!r}; "
            "name the file .tum or .kitti, or pass --trajectory-format tum|kitti"
        )
    return _SUFFIXES[suffix]


def xyz_quaternions(graph: PoseGraph) -> np.ndarray:
    """`(N, 7)` poses as `x y z qx qy qz qw` with unit quaternions, `qw >= 0` (2D: in the plane z = 0)."""
    if graph.dim == 3:
        q = graph.poses[:, 3:]
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        return np.concatenate((graph.poses[:, :3], np.where(q[:, 3:] < 0, -q, q)), axis=1)
    x, y, theta = graph.poses.T
    half = 0.5 * np.asarray(theta)
    zeros = np.zeros_like(x)
    q = np.stack((zeros, zeros, np.sin(half), np.cos(half)), axis=1)
    return np.concatenate((np.stack((x, y, zeros), axis=1), np.where(q[:, 3:] < 0, -q, q)), axis=1)


def write_trajectory(graph: PoseGraph, path: str | os.PathLike, file_format: TrajectoryFormat | None = None) -> None:
    """Write the poses of `graph` in TUM or KITTI format, atomically, in vertex-id order.

    Args:
        graph: the graph whose poses to write (e.g. `Result.graph`).
        path: the output file.
        file_format: `"tum"` or `"kitti"`; None takes it from the suffix (`trajectory_format`).
    """
    file_format = trajectory_format(path, file_format)
    poses = xyz_quaternions(graph)
    if file_format == "tum":
        lines = (f"{i} {format_floats(row)}" for i, row in zip(graph.vertex_ids.tolist(), poses))
    else:
        rows = se3.from_xyz_quat(poses)[:, :3, :].reshape(-1, 12)
        lines = (format_floats(row) for row in rows)
    with atomic_text_file(Path(path)) as out:
        out.write("".join(f"{line}\n" for line in lines))
