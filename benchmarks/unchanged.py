"""Prove a change changed no result: fingerprint the default's decisions, then compare two runs.

`python benchmarks/unchanged.py scan OUT.jsonl [--data-dir ../shared/datasets] [--only NAME,...]`
solves every case with the default (`egnc.solve(graph)`, CHOLMOD where installed) and writes one
JSON line per case: the number and SHA-1 of the rejected edges, the start that won, the final cost
over all edges and the solve time. The cases:

- every shared file as given (cubicle with its information repaired to the nearest positive
  definite matrix);
- every shared file with 10, 30 and 50 % false loops (riSAM's rule, seed 1), and seeds 2 and 3 on
  `egnc-bench`'s grid (csail, intel, manhattanOlson3500, sphere2500, city10000);
- clean graphs whose guess is made worse (heading noise 0.1 and 0.3 rad per step, translation
  noise 10 times each step's sigma; seeds 1 and 2) on manhattanOlson3500, intel, sphere2500;
- online replays (`egnc.online.replay`, method egnc) of csail, intel and manhattanOlson3500 at 30 %
  (seed 1) and of manhattan_noisy.irl: the rejected set of the final decision and the total of
  the update times.

`python benchmarks/unchanged.py compare BEFORE.jsonl AFTER.jsonl` prints one markdown table: per
group of cases, how many have the same rejected edges and start, the largest relative change of
the final cost, and the median time ratio (after / before); it exits 1 if any
decision differs. Cases missing from AFTER (a scan with `--only`) are counted, not compared.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from _lib.paths import SHARED_DATASETS
from _lib.robust_drifted import drifted

import egnc

SHARED = (
    "MIT",
    "csail",
    "intel",
    "kitti_00",
    "manhattanOlson3500",
    "city10000",
    "sphere2500",
    "sphere_a",
    "parking-garage",
    "cubicle",
    "smallGrid3D",
    "tinyGrid3D",
)
BENCH_GRID = ("csail", "intel", "manhattanOlson3500", "sphere2500", "city10000")
DRIFTED = ("manhattanOlson3500", "intel", "sphere2500")
ONLINE = ("csail", "intel", "manhattanOlson3500")
NEEDS_REPAIR = {"cubicle": "nearest-pd"}


def load(data_dir: Path, name: str) -> egnc.PoseGraph:
    """A shared file, repaired where `NEEDS_REPAIR` says."""
    return egnc.read_g2o(data_dir / f"{name}.g2o", information=NEEDS_REPAIR.get(name, "strict"))


def corrupted(graph: egnc.PoseGraph, reference: np.ndarray, percent: float, seed: int) -> egnc.PoseGraph:
    """`graph` with false loops added as `egnc-bench` adds them (random variant, riSAM's rule)."""
    from egnc.datasets import add_false_loops

    return add_false_loops(graph, percent, seed=seed, reference_poses=reference, variant="random").graph


def reference(graph: egnc.PoseGraph) -> np.ndarray:
    """The clean least-squares optimum `egnc-bench` draws false loops against."""
    from egnc.bench.cases import least_squares_optimum

    return least_squares_optimum(graph, "auto").graph.poses


def digest(edges: np.ndarray) -> str:
    """SHA-1 of a sorted edge index set, 12 hex digits."""
    return hashlib.sha1(np.asarray(sorted(int(e) for e in edges), dtype=np.int64).tobytes()).hexdigest()[:12]


def batch_row(group: str, name: str, graph: egnc.PoseGraph) -> dict:
    """The default's decision on one graph."""
    start = time.perf_counter()
    result = egnc.solve(graph)
    wall = time.perf_counter() - start
    return {
        "group": group,
        "case": name,
        "rejected": len(result.rejected_edges),
        "sha1": digest(result.rejected_edges),
        "start": str(result.start),
        "cost": float(result.cost),
        "time_s": wall,
    }


def online_row(name: str, graph: egnc.PoseGraph, known_inliers: np.ndarray) -> dict:
    """An online replay's final decision and update total."""
    from egnc.online.replay import replay

    start = time.perf_counter()
    outcome = replay(graph, "egnc", known_inliers=known_inliers)
    wall = time.perf_counter() - start
    return {
        "group": "online",
        "case": name,
        "rejected": len(outcome.result.rejected_edges),
        "sha1": digest(outcome.result.rejected_edges),
        "start": "",
        "cost": float(outcome.result.cost),
        "time_s": float(outcome.total_s),
        "wall_s": wall,
    }


def rows(data_dir: Path, only: set[str] | None) -> Iterator[dict]:
    """Every case's row, in a fixed order."""
    wanted = [name for name in SHARED if only is None or name in only]
    references = {}
    for name in wanted:
        graph = load(data_dir, name)
        yield batch_row("clean", name, graph)
        references[name] = reference(graph)
        for percent in (10, 30, 50):
            for seed in (1, 2, 3) if name in BENCH_GRID else (1,):
                bad = corrupted(graph, references[name], percent, seed)
                yield batch_row("corrupted", f"{name} {percent}% s{seed}", bad)
    for name in (n for n in DRIFTED if n in wanted):
        graph = load(data_dir, name)
        for kind, level in (("heading", 0.1), ("heading", 0.3), ("scaled", 10.0)):
            for seed in (1, 2):
                yield batch_row("drifted", f"{name} {kind} {level:g} s{seed}", drifted(graph, kind, level, seed))
    for name in (n for n in ONLINE if n in wanted):
        graph = corrupted(load(data_dir, name), references[name], 30, 1)
        yield online_row(f"{name} 30% s1", graph, graph.is_odometry)
    if only is None or "manhattan_noisy" in only:
        from egnc.io import read_irl

        log = read_irl(data_dir / "manhattan_noisy.irl")
        yield online_row("manhattan_noisy.irl", log.graph, log.is_odometry)


def scan(args: argparse.Namespace) -> int:
    """Write one JSON line per case as it finishes."""
    only = set(args.only.split(",")) if args.only else None
    with open(args.out, "w") as out:
        for row in rows(args.data_dir, only):
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(f"{row['group']:9} {row['case']:40} rejected {row['rejected']:5} {row['time_s']:8.2f} s", flush=True)
    return 0


def compare(args: argparse.Namespace) -> int:
    """Print the before/after table; 1 if any decision differs."""
    before = {(r["group"], r["case"]): r for r in map(json.loads, Path(args.before).read_text().splitlines())}
    after = {(r["group"], r["case"]): r for r in map(json.loads, Path(args.after).read_text().splitlines())}
    print(
        "| cases | same rejected edges and start | differ | largest relative cost change"
        " | median time, after / before |"
    )
    print("|---|---:|---|---:|---:|")
    differ_any = False
    for group in dict.fromkeys(key[0] for key in before):
        keys = [key for key in before if key[0] == group and key in after]
        if not keys:
            continue
        same = [k for k in keys if (before[k]["sha1"], before[k]["start"]) == (after[k]["sha1"], after[k]["start"])]
        differ = [k[1] for k in keys if k not in same]
        differ_any |= bool(differ)
        change = max(abs(after[k]["cost"] - before[k]["cost"]) / max(abs(before[k]["cost"]), 1e-300) for k in keys)
        ratio = float(np.median([after[k]["time_s"] / max(before[k]["time_s"], 1e-9) for k in keys]))
        print(f"| {group} | {len(same)} of {len(keys)} | {', '.join(differ) or '-'} | {change:.1e} | {ratio:.2f}x |")
    missing = [key[1] for key in before if key not in after]
    if missing:
        print(f"\n{len(missing)} cases of {args.before} are not in {args.after}.")
    return 1 if differ_any else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    scan_parser = commands.add_parser("scan", help="fingerprint every case")
    scan_parser.add_argument("out", type=Path)
    scan_parser.add_argument("--data-dir", type=Path, default=SHARED_DATASETS)
    scan_parser.add_argument("--only", default="", help="comma-separated file stems (default: all)")
    compare_parser = commands.add_parser("compare", help="compare two scans")
    compare_parser.add_argument("before", type=Path)
    compare_parser.add_argument("after", type=Path)
    args = parser.parse_args(argv)
    return scan(args) if args.command == "scan" else compare(args)


if __name__ == "__main__":
    sys.exit(main())
