"""Regenerate every table of REPRODUCTION.md: `python benchmarks/reproduce.py SECTION... [options]`.

Sections (each writes its runs as JSON lines, `runs.jsonl`, and its table as markdown into
`OUT/<section>/`; a section run again skips the runs already in its `runs.jsonl`):

- `table1`: false loop closures (the paper's Table 1) in the paper's setting, online: the cases of
  `benchmarks/online.py replay` (CSAIL, Intel, manhattanOlson3500, sphere2500 at 10/30/50 %,
  riSAM's generator rule, seed 0) replayed pose by pose with egnc's and riSAM's schedules
  (precision, recall, iterations, time), and the same corrupted graphs solved in batch by egnc and
  by GTSAM's GNC-TLS (`_lib/table1_runs.py`).
- `table2`: noisy Manhattan (the paper's Table 2): `--count` datasets per outlier regime made by
  `egnc.datasets.make_noisy_manhattan` (seeds 1..count) from manhattanOlson3500 with its
  least-squares optimum as ground truth, replayed online (egnc, risam) and solved in batch
  (egnc, risam, gnc-tls); every failure with the outliers it kept and their errors
  (`_lib/noisy_runs.py`).
- `table3`: the paper's case, `manhattan_noisy.irl`, and the gross-regime datasets where risam
  failed in `table2`, both schedules, online and in batch, with ATE and RPE against the
  outlier-free optimum and the ground truth (the irl's: its odometry rounded to the grid).
- `manhattan-noisy`: the shipped `manhattan_noisy.irl` case through `egnc-bench`, then egnc's and
  riSAM's trajectories against the case's grid ground truth (`ground_truth.md`).
- `figures`: `table1.png` (egnc's online time and iterations over riSAM's per log) and
  `table2.png` (successes per regime, mode and method, the paper's beside).

`--dry-run` prints the `egnc-bench` commands only. Datasets are read from `--data-dir` (default
`../shared/datasets` beside the checkout), never copied.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy
import numpy as np
import scipy
from _lib import noisy_runs, repro_report, table1_runs

from egnc import solve
from egnc.datasets.noisy_manhattan import NoisyGraph
from egnc.graph import PoseGraph
from egnc.io import read_irl
from egnc.metrics import ate, rpe
from egnc.nonlinear.initialize import initialize_poses

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA_DIR = REPO.parent / "shared" / "datasets"

BENCH_SECTIONS = {
    "manhattan-noisy": {
        "manhattan-noisy": [
            "--irl", "{data_dir}/manhattan_noisy.irl",
            "--methods", "egnc,risam,gnc-tls,gtsam-gnc-tls", "--time-limit", "300",
        ],
    },
}  # fmt: skip
"""`egnc-bench` runs of each section: output subfolder -> arguments (`--data-dir` and `--out` are added)."""

SECTIONS = ("table1", "table2", "table3", "manhattan-noisy", "figures")
TABLE1_DATASETS = "csail,intel,manhattanOlson3500,sphere2500"


def bench_commands(section: str, data_dir: Path, out: Path) -> list[list[str]]:
    """The `egnc-bench` command lines of a section, one per output subfolder."""
    commands = []
    for folder, template in BENCH_SECTIONS[section].items():
        arguments = [argument.replace("{data_dir}", str(data_dir)) for argument in template]
        if "--datasets" in arguments:
            arguments += ["--data-dir", str(data_dir)]
        commands.append(["egnc-bench", *arguments, "--out", str(out / folder)])
    return commands


def run_table1(out: Path, *, datasets: str, percents: str, modes: tuple[str, ...], time_limit_s: float) -> Path:
    """Table 1: `online.py replay`'s cases online (egnc, risam) and in batch (egnc, GTSAM's GNC-TLS)."""
    folder = out / "table1"
    runs = table1_runs.run_all(
        folder / "runs.jsonl", datasets=datasets, percents=percents, modes=modes, time_limit_s=time_limit_s
    )
    text = repro_report.table1_markdown(_rows(runs))
    _write(folder / "table1.md", f"{_machine()}\n\n{text}")
    return folder


def run_table2(
    data_dir: Path, out: Path, *, count: int, methods: str, min_r2: list[float | None], modes: tuple[str, ...]
) -> Path:
    """Table 2: `count` noisy-Manhattan datasets per regime, online and in batch, with every failure's edges."""
    folder = out / "table2"
    batch_methods = tuple(filter(None, methods.split(",")))
    runs = noisy_runs.run_all(
        data_dir, folder / "runs.jsonl", count=count, bounds=min_r2, modes=modes, batch_methods=batch_methods
    )
    rows = _rows(runs)
    parts = [_machine(), repro_report.table2_markdown(rows)]
    for regime in dict.fromkeys(row["regime"] for row in rows):
        parts += [f"Failures, {regime}:", repro_report.failures_markdown(rows, regime)]
        parts.append(f"Truncated costs, batch, {regime}: {repro_report.criterion_summary(rows, regime)}")
    _write(folder / "table2.md", "\n\n".join(parts) + "\n")
    return folder


def run_table3(data_dir: Path, out: Path) -> Path:
    """Table 3: the paper's case (`manhattan_noisy.irl`) and the gross-regime datasets where risam failed
    in Table 2, both schedules, online and in batch, with ATE and RPE."""
    folder = out / "table3"
    table2 = out / "table2" / "runs.jsonl"
    wanted = noisy_runs.risam_failures(_rows(table2)) if table2.exists() else []
    shipped = [("irl", 0, shipped_case(data_dir))] if (data_dir / "manhattan_noisy.irl").exists() else []
    cases = itertools.chain(shipped, noisy_runs.selected(data_dir, wanted))
    runs = noisy_runs.run_cases(folder / "runs.jsonl", cases, ("online", "batch"), ("egnc", "risam"))
    rows = _rows(runs) if runs.exists() else []
    text = repro_report.table3_markdown(rows) if rows else "No shipped case; risam failed on no dataset of Table 2.\n"
    _write(folder / "table3.md", f"{_machine()}\n\n{text}")
    return folder


def shipped_case(data_dir: Path) -> NoisyGraph:
    """`manhattan_noisy.irl` as a noisy-Manhattan dataset: labels, grid ground truth, outlier-free optimum."""
    log = read_irl(data_dir / "manhattan_noisy.irl")
    reference = solve(log.graph.subgraph_edges(~log.is_outlier), "l2").graph.poses
    return NoisyGraph(log.graph, log.is_outlier, grid_ground_truth(log.graph), reference)


def run_figures(out: Path) -> list[Path]:
    """The figures of Tables 1 and 2 from their runs, beside their tables."""
    made = []
    for name, draw in (("table1", repro_report.figure_table1), ("table2", repro_report.figure_table2)):
        runs = out / name / "runs.jsonl"
        if runs.exists():
            made.append(draw(_rows(runs), out / name / f"{name}.png"))
    return made


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    print(text)


def grid_ground_truth(graph: PoseGraph) -> np.ndarray:
    """`(N, 3)` ground truth of a Manhattan-world graph: its odometry rounded to grid motions and composed.

    Every odometry measurement of the Manhattan world is a unit move with a heading change of a
    multiple of 90 degrees plus noise (about 0.06 m and 0.015 rad in `manhattan_noisy.irl`), so
    rounding recovers the true motion; composing from the first pose gives the true trajectory.
    """
    odometry = graph.measurements[graph.is_odometry]
    motions = np.column_stack((np.round(odometry[:, :2]), np.round(odometry[:, 2] / (np.pi / 2)) * (np.pi / 2)))
    known = np.zeros(graph.num_poses, dtype=bool)
    known[0] = True
    return initialize_poses(2, graph.edges[graph.is_odometry], motions, poses=graph.poses, known=known)


def run_ground_truth_errors(data_dir: Path, out: Path, methods: tuple[str, ...] = ("egnc", "risam")) -> Path:
    """ATE and RPE of `manhattan_noisy.irl`'s solutions against its grid ground truth (the paper's yardstick).

    `egnc-bench` measures trajectories against the outlier-free optimum; the paper's 1.45 m ATE
    and 3.2 % RPE are errors against the ground truth, which the odometry noise alone moves the
    outlier-free optimum away from. Writes `OUT/manhattan-noisy/ground_truth.md`.
    """
    log = read_irl(data_dir / "manhattan_noisy.irl")
    truth = grid_ground_truth(log.graph)
    solutions = {
        "outlier-free optimum (l2 without the labelled outliers)": solve(
            log.graph.subgraph_edges(~log.is_outlier), "l2"
        )
    }
    solutions.update({method: solve(log.graph, method) for method in methods})
    lines = [
        "| trajectory | ATE vs ground truth (m) | RPE vs ground truth (%) |",
        "|---|---:|---:|",
        f"| initial guess (odometry) | {ate(log.graph.poses, truth, 2):.3f} "
        f"| {rpe(log.graph.poses, truth, 2).percent:.2f} |",
    ]
    for name, result in solutions.items():
        poses = result.graph.poses
        lines.append(f"| {name} | {ate(poses, truth, 2):.3f} | {rpe(poses, truth, 2).percent:.2f} |")
    text = (
        "`python benchmarks/reproduce.py manhattan-noisy` (ground-truth step)\n\n"
        f"{_machine()}. Ground truth: the odometry rounded to unit grid motions and composed.\n\n"
        + "\n".join(lines)
        + "\n"
    )
    folder = out / "manhattan-noisy"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "ground_truth.md").write_text(text)
    print(text)
    return folder


def _min_r2(text: str) -> list[float | None]:
    """`none,90` -> `[None, 90.0]`."""
    try:
        return [None if item.strip().lower() == "none" else float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers or none, got {text!r}") from None


def _machine() -> str:
    """Date, CPU model and core count, versions."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    stamp = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    return (
        f"{stamp}; {model}, {os.cpu_count()} cpus; Python {platform.python_version()}, "
        f"numpy {numpy.__version__}, scipy {scipy.__version__}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Regenerate the tables of REPRODUCTION.md.",
        epilog="sections: " + ", ".join(SECTIONS) + " (or all)",
    )
    parser.add_argument("sections", nargs="+", choices=(*SECTIONS, "all"), metavar="SECTION")
    parser.add_argument("--data-dir", type=Path, default=DEFAULT_DATA_DIR, help="benchmark datasets folder")
    parser.add_argument("--out", type=Path, default=Path("reproduction"), help="output folder (default reproduction)")
    parser.add_argument("--count", type=int, default=50, help="table2: noisy datasets per regime (default 50)")
    parser.add_argument(
        "--methods", default="egnc,risam,gnc-tls", help="table2: batch methods (default egnc,risam,gnc-tls)"
    )
    parser.add_argument(
        "--outlier-min-r2",
        type=_min_r2,
        default=[90.0, None],
        help="table2: outlier regimes, make_noisy_manhattan's outlier_min_r2 values, none = chi2 (default 90,none)",
    )
    parser.add_argument("--modes", default="online,batch", help="table1, table2: online, batch or both (default)")
    parser.add_argument("--datasets", default=TABLE1_DATASETS, help=f"table1: logs (default {TABLE1_DATASETS})")
    parser.add_argument("--percents", default="10,30,50", help="table1: false-loop percentages (default 10,30,50)")
    parser.add_argument("--time-limit", type=float, default=300.0, help="table1: seconds per batch run (default 300)")
    parser.add_argument("--dry-run", action="store_true", help="print the egnc-bench commands, run nothing")
    args = parser.parse_args(argv)
    sections = SECTIONS if "all" in args.sections else tuple(dict.fromkeys(args.sections))
    modes = tuple(mode for mode in ("online", "batch") if mode in args.modes.split(","))
    started_all = time.perf_counter()
    for section in sections:
        started = time.perf_counter()
        print(f"# {section}", flush=True)
        if section == "manhattan-noisy":
            for command in bench_commands(section, args.data_dir, args.out):
                print(f"# {section}: {shlex.join(command)}", flush=True)
                if args.dry_run:
                    continue
                status = subprocess.run(command, check=False).returncode
                if status != 0:
                    print(f"reproduce: {section} failed with exit code {status}", file=sys.stderr)
                    return status
            if not args.dry_run:
                run_ground_truth_errors(args.data_dir, args.out)
        elif args.dry_run:
            continue
        elif section == "table1":
            run_table1(args.out, datasets=args.datasets, percents=args.percents, modes=modes,
                       time_limit_s=args.time_limit)  # fmt: skip
        elif section == "table2":
            run_table2(args.data_dir, args.out, count=args.count, methods=args.methods, min_r2=args.outlier_min_r2,
                       modes=modes)  # fmt: skip
        elif section == "table3":
            run_table3(args.data_dir, args.out)
        else:
            for path in run_figures(args.out):
                print(f"# figure: {path}")
        if not args.dry_run:
            print(f"# {section}: {time.perf_counter() - started:.0f} s of wall time", flush=True)
    if not args.dry_run:
        print(f"# all sections: {time.perf_counter() - started_all:.0f} s of wall time", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
