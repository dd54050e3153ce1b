"""The GTSAM bridge on real graphs: costs, decisions and times, and two robots from GTSAM objects.

`python benchmarks/robust.py gtsam-bridge [--data-dir ../shared/datasets] [--files MIT,...] [--percent 0,30]
[--no-files] [--no-robots]`

- Every shared file (cubicle's information is not positive definite, so it is left out), as given
  and with `--percent` % false loops (riSAM's rule, seed 1, written to a g2o file), read by
  `gtsam.readG2o` and converted with `egnc.from_gtsam`: egnc's least-squares cost at the values
  against GTSAM's `graph.error(values)`, the default solve's rejected edges against those of the
  same file read by `egnc.read_g2o`, and the conversion time (both ways) against the solve time.
- manhattanOlson3500 cut in two robots (`egnc.datasets.two_robots`: robot `b` in its own frame,
  40 true inter-robot loops) with 0, 10 and 30 % random false inter-robot loops, and with a
  consistent false group of 20 and of 80 loops (smaller and larger than the true group), solved
  from GTSAM objects: rejected true and false loops, the group kept, where robot `b` was placed
  (median distance to the reference) and the warning about the groups.
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
from egnc.datasets.two_robots import GROUP_FALSE, RANDOM_FALSE, TRUE_LOOP, two_robots
from egnc.interop.gtsam import from_gtsam, gtsam_error, inlier_factor_mask, to_gtsam, to_gtsam_values

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
"""The two-robot cases: the false inter-robot loops added to the 40 true ones."""


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
    """Print the two-robot table (module docstring)."""
    graph = egnc.read_g2o(data_dir / "manhattanOlson3500.g2o")
    reference = egnc.solve(graph, "l2").graph.poses
    print(
        "| case | inter-robot loops (true + false) | true rejected | false rejected | group kept "
        "| start | b placed within (m, median) | warning about the groups | from_gtsam s | solve s |"
    )
    print("|---|---:|---:|---:|---|---|---:|---|---:|---:|")
    for label, options in ROBOT_CASES:
        robots = two_robots(graph, reference, true_loops=40, seed=1, **options)
        factors, values = to_gtsam(robots.graph)  # the robots as a GTSAM user holds them
        started = time.perf_counter()
        bridge = from_gtsam(factors, values)
        convert = time.perf_counter() - started
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = egnc.solve(bridge.graph)
        kept = inlier_factor_mask(result, bridge)
        kinds = robots.kinds
        rejected = {
            kind: int(np.count_nonzero(~kept & (kinds == kind))) for kind in (TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE)
        }
        counts = {kind: int(np.count_nonzero(kinds == kind)) for kind in (TRUE_LOOP, RANDOM_FALSE, GROUP_FALSE)}
        b_rows = np.arange(graph.num_poses) >= graph.num_poses // 2
        placed = np.median(np.linalg.norm(result.graph.poses[b_rows, :2] - reference[b_rows, :2], axis=1))
        group_warning = [_short(text) for text in result.warnings if "groups that disagree" in text]
        print(
            f"| {label} | {counts[TRUE_LOOP]} + {counts[RANDOM_FALSE] + counts[GROUP_FALSE]} "
            f"| {rejected[TRUE_LOOP]} of {counts[TRUE_LOOP]} "
            f"| {rejected[RANDOM_FALSE] + rejected[GROUP_FALSE]} of {counts[RANDOM_FALSE] + counts[GROUP_FALSE]} "
            f"| {_kept_group(rejected, counts)} | {result.start} | {placed:.2f} "
            f"| {group_warning[0] if group_warning else '-'} | {convert:.3f} | {result.time_s:.2f} |",
            flush=True,
        )


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
