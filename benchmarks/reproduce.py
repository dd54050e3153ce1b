"""Regenerate every table of REPRODUCTION.md: `python benchmarks/reproduce.py SECTION... [options]`.

Sections (each writes `results.csv`, `results.md` and plots into `OUT/<section>[/<part>]/`):

- `table1`: false loop closures (paper's Table 1): CSAIL, Intel, Manhattan3500 at 10/30/50 % and
  Sphere2500 at 10 % with seeds 1-3, methods egnc, egnc[threshold=distance], risam, l2 (about 12
  minutes on 2 cores); Sphere2500 at 30/50 % with seed 1, egnc and risam only, 900 s per run
  (runs of 150 to 900 s: about half an hour).
- `gtsam`: egnc and the riSAM schedule next to GTSAM's GNC-GM and GNC-TLS on CSAIL, Intel and
  Manhattan3500 at 10/30 %, seed 1.
- `table2`: noisy Manhattan (paper's Table 2): `--count` datasets made by
  `egnc.datasets.make_noisy_manhattan` (seeds 1..count, default parameters) from
  manhattanOlson3500 with its least-squares optimum as ground truth; success = precision = recall
  = 1. The only section that is not an `egnc-bench` command, since `egnc-bench` corrupts with
  false loops; it uses the same library calls (`egnc.bench.run_case`: every run in a child
  process killed at the time limit, scored by egnc's chi-square rule), with the outlier-free
  optimum as the ATE reference. `--write-datasets` also writes each dataset as an IRL file.
- `manhattan-noisy`: the shipped `manhattan_noisy.irl` case (paper: EGNC P = R = 1, ATE 1.45 m,
  RPE 3.2 %; riSAM ATE 23.6 m), then egnc's and riSAM's trajectories against the case's grid
  ground truth (`ground_truth.md`), the paper's yardstick.

The `egnc-bench` sections print their exact command before running it; `--dry-run` prints the
commands only. Datasets are read from `--data-dir` (default `../shared/datasets` beside the
checkout), never copied.
"""

from __future__ import annotations

import argparse
import datetime
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

from egnc import solve
from egnc.bench import (
    BenchCase,
    describe_run,
    format_markdown,
    parse_methods,
    run_case,
    summarize,
    write_outputs,
)
from egnc.datasets import make_noisy_manhattan
from egnc.datasets.noisy_manhattan import DEFAULT_ODOMETRY_SIGMA, DEFAULT_OUTLIER_SIGMA
from egnc.graph import PoseGraph
from egnc.io import read_g2o, read_irl, write_irl
from egnc.metrics import ate, rpe
from egnc.nonlinear.initialize import initialize_poses

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA_DIR = REPO.parent / "shared" / "datasets"

BENCH_SECTIONS = {
    "table1": {
        "table1/main": [
            "--datasets", "csail,intel,manhattanOlson3500", "--percent", "10,30,50", "--seeds", "1,2,3",
            "--methods", "egnc,egnc[threshold=distance],risam,l2", "--time-limit", "300",
        ],
        "table1/sphere10": [
            "--datasets", "sphere2500", "--percent", "10", "--seeds", "1,2,3",
            "--methods", "egnc,egnc[threshold=distance],risam,l2", "--time-limit", "300",
        ],
        # Runs of 150 to 900 s each: one seed, two methods.
        "table1/sphere30-50": [
            "--datasets", "sphere2500", "--percent", "30,50", "--seeds", "1",
            "--methods", "egnc,risam", "--time-limit", "900",
        ],
    },
    "gtsam": {
        "gtsam": [
            "--datasets", "csail,intel,manhattanOlson3500", "--percent", "10,30", "--seeds", "1",
            "--methods", "egnc,risam,gtsam-gnc-gm,gtsam-gnc-tls", "--time-limit", "300",
        ],
    },
    "manhattan-noisy": {
        "manhattan-noisy": [
            "--irl", "{data_dir}/manhattan_noisy.irl",
            "--methods", "egnc,egnc[threshold=distance],risam,gnc-tls,gtsam-gnc-tls", "--time-limit", "300",
        ],
    },
}  # fmt: skip
"""`egnc-bench` runs of each section: output subfolder -> arguments (`--data-dir` and `--out` are added)."""

SECTIONS = ("table1", "gtsam", "table2", "manhattan-noisy")

TABLE2_METHODS = "egnc,egnc[warm_start=true],risam,gnc-tls"
"""table2's methods: the default batch protocol (stages restart from the initial guess) and warm starts."""


def bench_commands(section: str, data_dir: Path, out: Path) -> list[list[str]]:
    """The `egnc-bench` command lines of a section, one per output subfolder."""
    commands = []
    for folder, template in BENCH_SECTIONS[section].items():
        arguments = [argument.replace("{data_dir}", str(data_dir)) for argument in template]
        if "--datasets" in arguments:
            arguments += ["--data-dir", str(data_dir)]
        commands.append(["egnc-bench", *arguments, "--out", str(out / folder)])
    return commands


def run_table2(
    data_dir: Path,
    out: Path,
    *,
    count: int,
    methods: str,
    min_r2: list[float | None],
    time_limit_s: float,
    write_datasets: bool,
) -> Path:
    """Noisy-Manhattan success counts over `count` datasets per outlier regime; returns the results folder.

    A regime is an `outlier_min_r2` of `make_noisy_manhattan` (None: the chi-square threshold);
    the dataset column names it, e.g. `noisy_manhattan[r2>90]`.
    """
    folder = out / "table2"
    specs = parse_methods(methods)
    source = read_g2o(data_dir / "manhattanOlson3500.g2o")
    truth = solve(source, "l2", linear_solver="scipy").graph.poses
    records = []
    total = len(min_r2) * count * len(specs)
    for bound in min_r2:
        name = "noisy_manhattan" if bound is None else f"noisy_manhattan[r2>{bound:g}]"
        for seed in range(1, count + 1):
            noisy = make_noisy_manhattan(source, truth, seed=seed, outlier_min_r2=bound)
            if write_datasets:
                (folder / "datasets").mkdir(parents=True, exist_ok=True)
                notes = f"make_noisy_manhattan(manhattanOlson3500, seed={seed}, outlier_min_r2={bound})"
                log = noisy.to_irl(f"{name}_{seed}", date="2000-01-01", notes=notes)
                write_irl(log, folder / "datasets" / f"{name}_{seed}.irl")
            case = BenchCase(
                dataset=name,
                percent=30.0,
                seed=seed,
                graph=noisy.graph,
                is_outlier=noisy.is_outlier,
                known_inliers=noisy.graph.is_odometry,
                reference=noisy.reference,
            )
            for spec in specs:
                record = run_case(case, spec, time_limit_s=time_limit_s)
                records.append(record)
                print(f"[{len(records)}/{total}] {describe_run(record)}", file=sys.stderr, flush=True)
    header = (
        f"`python benchmarks/reproduce.py table2 {table2_options(count, methods, min_r2, time_limit_s)}`\n\n"
        f"{_machine()}. Datasets: `make_noisy_manhattan(manhattanOlson3500, its l2 optimum, seed=1..{count})`, "
        f"odometry sigma {DEFAULT_ODOMETRY_SIGMA}, outlier sigma {DEFAULT_OUTLIER_SIGMA}, 30 % of the "
        "2099 loop closures perturbed; `noisy_manhattan` keeps outliers above the chi-square threshold, "
        "`noisy_manhattan[r2>X]` only those whose squared whitened error exceeds X. ATE/RPE against each "
        "dataset's outlier-free optimum; success = precision = recall = 1."
    )
    write_outputs(records, folder, baseline_method="risam", header=header)
    print(format_markdown(summarize(records, "risam"), "risam"))
    return folder


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


def table2_options(count: int, methods: str, min_r2: list[float | None], time_limit_s: float) -> str:
    """The command-line options that reproduce a table2 run."""
    bounds = ",".join("none" if bound is None else f"{bound:g}" for bound in min_r2)
    return f"--count {count} --methods {shlex.quote(methods)} --outlier-min-r2 {bounds} --time-limit {time_limit_s:g}"


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
    parser.add_argument("--methods", default=TABLE2_METHODS, help=f"table2: methods (default {TABLE2_METHODS})")
    parser.add_argument(
        "--outlier-min-r2",
        type=_min_r2,
        default=[None, 90.0],
        help="table2: outlier regimes, make_noisy_manhattan's outlier_min_r2 values, none = chi2 (default none,90)",
    )
    parser.add_argument("--time-limit", type=float, default=120.0, help="table2: seconds per run (default 120)")
    parser.add_argument("--write-datasets", action="store_true", help="table2: also write the datasets as IRL")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args(argv)
    sections = SECTIONS if "all" in args.sections else tuple(dict.fromkeys(args.sections))
    for section in sections:
        started = time.perf_counter()
        if section == "table2":
            options = table2_options(args.count, args.methods, args.outlier_min_r2, args.time_limit)
            print(f"# table2: python benchmarks/reproduce.py table2 {options}", flush=True)
            if not args.dry_run:
                run_table2(
                    args.data_dir,
                    args.out,
                    count=args.count,
                    methods=args.methods,
                    min_r2=args.outlier_min_r2,
                    time_limit_s=args.time_limit,
                    write_datasets=args.write_datasets,
                )
        else:
            for command in bench_commands(section, args.data_dir, args.out):
                print(f"# {section}: {shlex.join(command)}", flush=True)
                if args.dry_run:
                    continue
                status = subprocess.run(command, check=False).returncode
                if status != 0:
                    print(f"reproduce: {section} failed with exit code {status}", file=sys.stderr)
                    return status
            if section == "manhattan-noisy" and not args.dry_run:
                run_ground_truth_errors(args.data_dir, args.out)
        if not args.dry_run:
            print(f"# {section}: {time.perf_counter() - started:.0f} s of wall time", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
