"""egnc's online replay of a corrupted graph against GTSAM's ISAM2 replaying the clean one, as whole processes.

    nice -n 10 python benchmarks/online.py vs-isam2 [--datasets manhattanOlson3500,sphere2500,city10000]
        [--percent 30] [--seed 1] [--repeats 1] [--relinearize-skips 10] [--egnc-timeout 1200]
        [--isam2-timeout 600] [--region-hops N] [--boundary-share S] [--decide-at-arrival] [--json rows.jsonl]

For every dataset: `egnc-corrupt` writes the graph with `--percent` false loop closures (riSAM's
protocol, `--seed`) and its labels to a temporary folder; then, `--repeats` times and alternated
(A, B, A, B ...), two child processes run:
- A: `egnc-solve CORRUPTED --online --report R.json -o OUT.g2o` (the report's `online` object gives
  the update total and latency; OUT.g2o the final estimate);
- B: `python benchmarks/online.py isam2 CLEAN --relinearize-skip S` (`isam2_replay`) for each `S` of
  `--relinearize-skips` (non-robust ISAM2 on the clean graph, an estimate after every update).
Each child's wall time is taken around its start and `os.wait4`, its peak memory is the
`ru_maxrss` that `os.wait4` returns. A child still running at its timeout is killed; the row then
says how far egnc's replay got (its last progress line). After the timed runs, one untimed
`online.py isam2 --output` run per `S` gives ISAM2's final estimate.

Columns (medians over the repeats):
- `wall s`: the whole process (start, imports, reading, the replay; for egnc also its final batch
  decision and writing the outputs);
- `update total s`, `p50`, `p99`, `max ms`: the sum and the percentiles of the per-update times
  (egnc: `OnlineSolver.update()`; ISAM2: `update()` plus `calculateEstimate()`);
- `peak MiB`: the child's peak resident memory;
- `P`, `R`: precision and recall of egnc's final rejections against the labels (outliers
  positive); ISAM2 sees no false loops;
- `ATE m`: the final estimate against the clean graph's least-squares optimum
  (`egnc.solve(clean, "l2")`), metres, after rigid alignment;
- `egnc / ISAM2`: on each ISAM2 row, egnc's wall time and update total over that row's, median of
  the pair-by-pair ratios.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .paths import ENTRIES, SHARED_DATASETS
from .processes import ChildRun, run_child


def egnc_row(run: ChildRun, report_path: Path, estimate_path: Path, is_outlier, reference, dim) -> dict:
    """egnc's figures from its child run, report and final estimate."""
    from egnc.io import read_g2o
    from egnc.metrics import ate, precision_recall

    row: dict = {"engine": "egnc", "wall_s": run.wall_s, "peak_mib": run.peak_mib, "returncode": run.returncode}
    if run.timed_out or run.returncode != 0:
        progress = [line for line in run.stderr.splitlines() if line.startswith("step ")]
        row["failure"] = ("timeout" if run.timed_out else f"exit {run.returncode}") + (
            f", last progress: {progress[-1]}" if progress else ", no progress line"
        )
        return row
    report = json.loads(report_path.read_text())
    online = report["online"]
    rejected = np.zeros(len(is_outlier), dtype=bool)
    rejected[report["rejected_edges"]] = True
    precision, recall = precision_recall(rejected, is_outlier)
    return {
        **row,
        "total_s": online["total_s"],
        **online["update_ms"],
        "steps": online["steps"],
        "P": precision,
        "R": recall,
        "ate": ate(read_g2o(estimate_path).poses, reference, dim),
    }


def isam2_row(run: ChildRun, skip: int) -> dict:
    """ISAM2's figures from its child run (the JSON line `online.py isam2` prints)."""
    row: dict = {"engine": f"ISAM2 skip {skip}", "wall_s": run.wall_s, "peak_mib": run.peak_mib}
    if run.timed_out or run.returncode != 0:
        row["failure"] = "timeout" if run.timed_out else f"exit {run.returncode}: {run.stderr.strip()[-300:]}"
        return row
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    parts = {key: figures[key] for key in ("update_s", "estimate_s")}  # for --json: where ISAM2's time goes
    return {**row, "total_s": figures["total_s"], **figures["update_ms"], "steps": figures["updates"], **parts}


def median_row(rows: list[dict]) -> dict:
    """The first row with every timing replaced by its median over `rows` (failed runs left out)."""
    done = [row for row in rows if "failure" not in row]
    if not done:
        return rows[-1]
    merged = dict(done[-1])
    for key in ("wall_s", "peak_mib", "total_s", "p50", "p99", "max"):
        merged[key] = statistics.median(row[key] for row in done)
    merged["runs"] = len(done)
    return merged


def ratio(egnc_runs: list[dict], isam2_runs: list[dict], key: str) -> float | None:
    """Median over repeats of egnc's `key` over ISAM2's, pair by pair (pairs where both finished)."""
    pairs = [(a[key], b[key]) for a, b in zip(egnc_runs, isam2_runs) if "failure" not in a and "failure" not in b]
    return statistics.median(a / b for a, b in pairs) if pairs else None


def format_row(name: str, percent: float, row: dict, ratios: tuple[float | None, float | None] = (None, None)) -> str:
    """One markdown row of the table."""

    def number(key: str, digits: int) -> str:
        return f"{row[key]:.{digits}f}" if key in row else ""

    ratio_text = " / ".join("" if r is None else f"{r:.2f}x" for r in ratios) if any(ratios) else ""
    failure = f" ({row['failure']})" if "failure" in row else ""
    return (
        f"| {name} | {percent:g} | {row['engine']}{failure} | {row['wall_s']:.1f} | {number('total_s', 1)}"
        f" | {number('p50', 1)} | {number('p99', 1)} | {number('max', 1)} | {row['peak_mib']:.0f}"
        f" | {number('P', 4)} | {number('R', 4)} | {number('ate', 4)} | {ratio_text} |"
    )


HEADER = (
    "| dataset | % | engine | wall s | update total s | p50 ms | p99 ms | max ms | peak MiB | P | R | ATE m"
    " | egnc / ISAM2 wall / update total |"
)


def isam2_command(clean: Path, skip: int) -> list[str]:
    """The child that replays `clean` through ISAM2 with `relinearizeSkip` `skip` (`online.py isam2`)."""
    return [sys.executable, str(ENTRIES / "online.py"), "isam2", str(clean), "--relinearize-skip", str(skip)]


def bench_dataset(name: str, args: argparse.Namespace, folder: Path) -> list[str]:
    """Corrupt, run the alternated children, check ISAM2's estimate; the dataset's markdown rows."""
    from egnc.api import solve
    from egnc.datasets import read_labels
    from egnc.io import read_g2o
    from egnc.metrics import ate

    clean = SHARED_DATASETS / f"{name}.g2o"
    corrupted = folder / f"{name}_{args.percent:g}.g2o"
    tools = Path(sys.executable).parent
    egnc_solve = str(tools / "egnc-solve") if (tools / "egnc-solve").exists() else shutil.which("egnc-solve")
    egnc_corrupt = str(tools / "egnc-corrupt") if (tools / "egnc-corrupt").exists() else shutil.which("egnc-corrupt")
    if egnc_solve is None or egnc_corrupt is None:
        raise SystemExit("egnc-solve and egnc-corrupt must be installed (pip install -e .)")
    corrupt_options = ["--percent", f"{args.percent:g}", "--seed", str(args.seed), "-o", str(corrupted), "-q"]
    subprocess.run([egnc_corrupt, str(clean), *corrupt_options], check=True)
    is_outlier, _ = read_labels(corrupted.with_name(corrupted.stem + ".labels.json"))
    graph = read_g2o(clean)
    reference = solve(graph, "l2").graph.poses
    report, estimate = folder / "report.json", folder / "estimate.g2o"
    egnc_command = [egnc_solve, str(corrupted), "--online", "--report", str(report), "-o", str(estimate)]
    if args.region_hops is not None:
        egnc_command += ["--region-hops", str(args.region_hops)]
    if args.boundary_share is not None:
        egnc_command += ["--boundary-share", f"{args.boundary_share:g}"]
    if args.decide_at_arrival:
        egnc_command.append("--decide-at-arrival")
    skips = [int(s) for s in args.relinearize_skips.split(",")]
    egnc_runs: list[dict] = []
    isam2_runs: dict[int, list[dict]] = {skip: [] for skip in skips}
    for _ in range(args.repeats):
        if not any("failure" in row and row["failure"].startswith("timeout") for row in egnc_runs):
            run = run_child(egnc_command, args.egnc_timeout)
            egnc_runs.append(egnc_row(run, report, estimate, is_outlier, reference, graph.dim))
            print(f"  {name}: egnc {egnc_runs[-1]}", file=sys.stderr, flush=True)
        for skip in skips:
            isam2_runs[skip].append(isam2_row(run_child(isam2_command(clean, skip), args.isam2_timeout), skip))
            print(f"  {name}: isam2 {isam2_runs[skip][-1]}", file=sys.stderr, flush=True)
    rows = [format_row(name, args.percent, median_row(egnc_runs))]
    records = [*egnc_runs, *(row for skip in skips for row in isam2_runs[skip])]
    for skip in skips:
        row = median_row(isam2_runs[skip])
        if "failure" not in row:  # the final estimate, from one more (untimed) run
            run_child([*isam2_command(clean, skip), "--output", str(estimate)], args.isam2_timeout)
            row["ate"] = ate(read_g2o(estimate).poses, reference, graph.dim)
        ratios = (ratio(egnc_runs, isam2_runs[skip], "wall_s"), ratio(egnc_runs, isam2_runs[skip], "total_s"))
        rows.append(format_row(name, args.percent, row, ratios))
    if args.json is not None:
        with open(args.json, "a", encoding="utf-8") as out:
            for record in records:
                out.write(json.dumps({"dataset": name, "percent": args.percent, **record}) + "\n")
    return rows


def report(args: argparse.Namespace) -> int:
    """Run every dataset's children and print the markdown table (`args`: the options of `online.py vs-isam2`)."""
    with open("/proc/loadavg") as load:
        load_start = load.read().split()[:3]
    print(
        f"egnc {importlib.metadata.version('egnc')}, gtsam {importlib.metadata.version('gtsam')},"
        f" Python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} CPUs,"
        f" {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load average {' '.join(load_start)}",
        file=sys.stderr,
    )
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1), flush=True)
    with tempfile.TemporaryDirectory(prefix="egnc-vs-isam2-") as folder:
        for name in filter(None, args.datasets.split(",")):
            for row in bench_dataset(name, args, Path(folder)):
                print(row, flush=True)
    with open("/proc/loadavg") as load:
        print(f"load average at the end {' '.join(load.read().split()[:3])}", file=sys.stderr)
    return 0
