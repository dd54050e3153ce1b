"""The GTSAM bridge on real graphs: costs, decisions and times, and several robots from GTSAM objects.

`python benchmarks/robust.py gtsam-bridge [--data-dir ../shared/datasets] [--files MIT,...] [--percent 0,30]
[--no-files] [--no-robots]`

- Every shared file (cubicle's information is not positive definite, so it is left out), as given
  and with `--percent` % false loops (riSAM's rule, seed 1, written to a g2o file), read by
  `gtsam.readG2o` and converted with `egnc.from_gtsam`: egnc's least-squares cost at the values
  against GTSAM's `graph.error(values)`, the default solve's rejected edges against those of the
  same file read by `egnc.read_g2o`, and the conversion time (both ways) against the solve time.
- Graphs cut in robots (`egnc.datasets.two_robots.robots`: each robot but `a` in its own frame,
  joined only by inter-robot loops), solved from GTSAM objects (`ROBOT_MAPS`): manhattanOlson3500
  in two robots (40 true inter-robot loops) and in three (60), sphere2500 in two (40), each with
  random false inter-robot loops and with a consistent false group between `a` and `b` smaller
  and larger than the true loops between them: rejected true and false loops (per pair of robots
  with three), precision and recall of the false inter-robot loops, the group kept, where each
  robot but `a` was placed (median distance to the reference) and the warning about the groups.
"""

from __future__ import annotations

import re
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import egnc
from egnc.datasets import add_false_loops
from egnc.datasets.two_robots import GROUP_FALSE, RANDOM_FALSE, SYMBOL_A, TRUE_LOOP, Robots, robots
from egnc.interop.gtsam import from_gtsam, gtsam_error, inlier_factor_mask, to_gtsam, to_gtsam_values
from egnc.metrics import precision_recall

SHARED_FILES = (
    "MIT,csail,intel,kitti_00,manhattanOlson3500,city10000,sphere2500,parking-garage,smallGrid3D,tinyGrid3D,sphere_a"
)
THREE_D = {"sphere2500", "parking-garage", "smallGrid3D", "tinyGrid3D", "sphere_a", "cubicle"}

ROBOT_CASES = (
    ("0 % false", {}),
    ("10 % false", {"false_percent": 10.0}),
    ("30 % false", {"false_percent": 30.0}),
    ("group of 20 < 40 true", {"false_group": 20}),
    ("group of 80 > 40 true", {"false_group": 80}),
    ("30 % + group of 20", {"false_percent": 30.0, "false_group": 20}),
)
"""The two-robot cases of manhattanOlson3500: the false inter-robot loops added to the 40 true ones."""

THREE_ROBOT_CASES = (
    ("0 % false", {}),
    ("30 % false", {"false_percent": 30.0}),
    ("group of 20 < 38 true a-b", {"false_group": 20}),
    ("group of 40 > 38 true a-b", {"false_group": 40}),
    ("30 % + group of 20", {"false_percent": 30.0, "false_group": 20}),
)
"""The three-robot cases of manhattanOlson3500 (60 true inter-robot loops, 38 of them between `a` and `b`)."""

SPHERE_CASES = (
    ("0 % false", {}),
    ("30 % false", {"false_percent": 30.0}),
    ("group of 20 < 40 true", {"false_group": 20}),
    ("group of 60 > 40 true", {"false_group": 60}),
    ("30 % + group of 20", {"false_percent": 30.0, "false_group": 20}),
)
"""The two-robot cases of sphere2500 (40 true inter-robot loops)."""

ROBOT_MAPS = (
    ("manhattanOlson3500", 2, 40, ROBOT_CASES),
    ("manhattanOlson3500", 3, 60, THREE_ROBOT_CASES),
    ("sphere2500", 2, 40, SPHERE_CASES),
)
"""`(file, robots, true inter-robot loops, cases)`: each file cut in that many robots of equal length."""


def file_row(path: Path, percent: float) -> str:
    """One markdown row of the shared-file table: the file, or it with `percent` % false loops (seed 1)."""
    import gtsam

    label = path.stem
    if percent:
        graph = egnc.read_g2o(path)
        reference = egnc.solve(graph, "l2").graph.poses
        corrupted = add_false_loops(graph, percent, seed=1, reference_poses=reference).graph
        folder = Path(tempfile.mkdtemp(prefix="egnc-bridge-"))
        path = folder / path.name
        egnc.write_g2o(corrupted, path)
        label = f"{label} {percent:g} %"
    factors, values = gtsam.readG2o(str(path), path.stem in THREE_D)
    started = time.perf_counter()
    bridge = from_gtsam(factors, values)
    convert_in = time.perf_counter() - started
    gtsam_cost, egnc_cost = float(factors.error(values)), gtsam_error(bridge.graph)
    result = egnc.solve(bridge.graph)
    started = time.perf_counter()
    to_gtsam_values(result, bridge)
    mask = inlier_factor_mask(result, bridge)
    convert_out = time.perf_counter() - started
    from_file = egnc.solve(egnc.read_g2o(path))
    same = np.array_equal(from_file.rejected_edges, np.flatnonzero(~mask))
    return (
        f"| {label} | {factors.size()} | {gtsam_cost:.10g} | {abs(egnc_cost - gtsam_cost) / gtsam_cost:.1e} "
        f"| {len(from_file.rejected_edges)} | {int(np.count_nonzero(~mask))} | {'yes' if same else 'NO'} "
        f"| {convert_in:.3f} | {convert_out:.3f} | {result.time_s:.2f} |"
    )


def files_table(data_dir: Path, names: str, percents: str) -> None:
    """Print the shared-file table."""
    print(
        "| file | factors | GTSAM error | relative difference of egnc's cost | rejected, g2o path "
        "| rejected, GTSAM path | same set | from_gtsam s | back to GTSAM s | solve s |"
    )
    print("|---|---:|---:|---:|---:|---:|---|---:|---:|---:|")
    for percent in (float(text) for text in percents.split(",")):
        for name in names.split(","):
            path = data_dir / f"{name}.g2o"
            if path.is_file():
                print(file_row(path, percent), flush=True)


def robots_table(data_dir: Path) -> None:
    """Print the table of graphs cut in robots (module docstring)."""
    print(
        "| graph | case | inter-robot loops (true + false) | true rejected | false rejected | P / R | group kept "
        "| start | robots placed within (m, median) | warning about the groups | from_gtsam s | solve s |"
    )
    print("|---|---|---:|---|---:|---|---|---|---|---|---:|---:|")
    for name, count, true_loops, cases in ROBOT_MAPS:
        graph = egnc.read_g2o(data_dir / f"{name}.g2o")
        reference = egnc.solve(graph, "l2").graph.poses
        splits = tuple(graph.num_poses * k // count for k in range(1, count))
        wrong_motion = _turned_over(reference) if graph.dim == 3 else None
        for label, options in cases:
            cut = robots(graph, reference, splits=splits, true_loops=true_loops, wrong_motion=wrong_motion, **options)
            print(f"| {name}, {count} robots | {label} | {_robots_row(cut, reference)}", flush=True)


def _robots_row(cut: Robots, reference: np.ndarray) -> str:
    """The cells of one row of the robots table after its first two: `cut` solved from GTSAM objects."""
    factors, values = to_gtsam(cut.graph)  # the robots as a GTSAM user holds them
    started = time.perf_counter()
    bridge = from_gtsam(factors, values)
    convert = time.perf_counter() - started
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = egnc.solve(bridge.graph)
    kept = inlier_factor_mask(result, bridge)
    kinds = cut.kinds
    rejected = {kind: int(np.count_nonzero(~kept & (kinds == kind))) for kind in (TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE)}
    counts = {kind: int(np.count_nonzero(kinds == kind)) for kind in (TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE)}
    precision, recall = precision_recall(~kept, cut.is_false)
    dim = cut.graph.dim
    placed = [
        np.median(np.linalg.norm(result.graph.poses[cut.robot == k, :dim] - reference[cut.robot == k, :dim], axis=1))
        for k in range(1, cut.robot.max() + 1)
    ]
    group_warning = [_short(text) for text in result.warnings if "groups that disagree" in text]
    return (
        f"{counts[TRUE_LOOP]} + {counts[RANDOM_FALSE] + counts[GROUP_FALSE]} "
        f"| {rejected[TRUE_LOOP]} of {counts[TRUE_LOOP]}{_by_pair(cut, ~kept & (kinds == TRUE_LOOP))} "
        f"| {rejected[RANDOM_FALSE] + rejected[GROUP_FALSE]} of {counts[RANDOM_FALSE] + counts[GROUP_FALSE]} "
        f"| {precision:.2f} / {recall:.2f} | {_kept_group(rejected, counts)} | {result.start} "
        f"| {'; '.join(f'{chr(ord(SYMBOL_A) + k)} {d:.2f}' for k, d in enumerate(placed, start=1))} "
        f"| {group_warning[0] if group_warning else '-'} | {convert:.3f} | {result.time_s:.2f} |"
    )


def _by_pair(cut: Robots, rejected: np.ndarray) -> str:
    """` (a-b 3 of 39, ...)`: the rejected true loops per pair of robots, where there are more than two."""
    if cut.robot.max() < 2:
        return ""
    pairs = np.sort(cut.robot[cut.graph.edges], axis=1)
    true = cut.kinds == TRUE_LOOP
    cells = []
    for i, j in np.unique(pairs[true], axis=0):
        pair = true & (pairs == (i, j)).all(axis=1)
        names = f"{chr(ord(SYMBOL_A) + i)}-{chr(ord(SYMBOL_A) + j)}"
        cells.append(f"{names} {np.count_nonzero(rejected & pair)} of {np.count_nonzero(pair)}")
    return f" ({', '.join(cells)})"


def _turned_over(reference: np.ndarray) -> np.ndarray:
    """`(4, 4)` a turn by 180 degrees about the x axis through the centre of the 3D `reference`
    positions: on sphere2500 it lays `b`'s half of the sphere over `a`'s, where a false group can be."""
    centre = reference[:, :3].mean(axis=0)
    W = np.eye(4)
    W[:3, :3] = np.diag([1.0, -1.0, -1.0])
    W[:3, 3] = centre - W[:3, :3] @ centre
    return W


def _short(warning: str) -> str:
    """The gist of the groups warning: what was kept and the rejected group, or the mix."""
    rival = re.search(r"(a group of \d+ was kept|none was kept), a rejected group of (\d+)", warning)
    if rival:
        return f"yes: {rival.group(1)}, a rejected group of {rival.group(2)}"
    mixed = re.search(r"\(([^)]*)\): check them", warning)
    return f"yes, mixed: {mixed.group(1)}" if mixed else "yes"


def _kept_group(rejected: dict[int, int], counts: dict[int, int]) -> str:
    """Which inter-robot group the decision kept: the true loops, the false group, both, or neither."""
    true_kept = rejected[TRUE_LOOP] < counts[TRUE_LOOP]
    group_kept = rejected[GROUP_FALSE] < counts[GROUP_FALSE]
    if true_kept and group_kept:
        return "MIXED"
    if group_kept:
        return "false group"
    return "true loops" if true_kept else "none"


def run(data_dir: Path, files: str, percents: str, with_files: bool, with_robots: bool, command: str) -> int:
    """Print the tables; 0."""
    print(f"`{command}`\n")
    if with_files:
        files_table(data_dir, files, percents)
        print()
    if with_robots:
        robots_table(data_dir)
    return 0
