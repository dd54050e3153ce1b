"""`egnc-bench`: run the benchmark grid (`egnc.bench`) and write its CSV, markdown table and plots.

Exit codes: 0 the grid ran (individual timeouts and errors are reported in the results, not
here); 1 nothing ran (no case, or no method can run here), or an error about the inputs, the
outputs or the Dask scheduler (one line on stderr); 2 bad command-line usage.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import sys
import textwrap
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from egnc import __version__
from egnc.bench import (
    SUCCESS_DEFINITION,
    format_markdown,
    parse_methods,
    run_grid,
    run_irl,
    summarize,
    write_outputs,
)
from egnc.cli.arguments import add_irl_covariance_order, int_at_least, positive_float
from egnc.datasets import OUTLIER_RULES, VARIANTS
from egnc.errors import EgncError
from egnc.linalg.linear_solvers import LINEAR_SOLVERS

EXAMPLES = f"""examples:
  egnc-bench --datasets csail,intel --percent 10 --seeds 1 --methods egnc,risam,gnc-tls,l2
  egnc-bench --datasets csail,intel,manhattanOlson3500,sphere2500 --percent 10,30,50 --seeds 1,2,3
  egnc-bench --datasets csail,intel --percent 10,30 --seeds 1,2,3 --methods egnc --workers 2
  egnc-bench --datasets csail,intel --percent 10,30 --seeds 1,2,3 --dask-scheduler tcp://127.0.0.1:8786
  egnc-bench --datasets datasets/grid2d.g2o --methods "egnc,egnc[threshold=distance],risam[c=2]"
  egnc-bench --irl ../shared/datasets/manhattan_noisy.irl --methods egnc,risam,gtsam-gnc-tls
  egnc-bench --irl sphere2500_30_random_0.irl --irl-covariance-order g2o --methods egnc,risam

Method specs: any egnc method (egnc, risam, gnc-gm, gnc-tls, huber, cauchy, gm, l2), optionally
with GncOptions overrides in brackets (egnc[threshold=distance], risam[c=2,refine=false]), and the
GTSAM baselines gtsam-gnc-gm, gtsam-gnc-tls, gtsam-lm when gtsam is installed (egnc[bench]).

Every run is a child process killed at --time-limit, with --workers N of them at once here, or
as tasks on a Dask cluster (--dask-scheduler, egnc[dask]; each worker forks the run's child and
enforces the limit). The table is the same whatever runs them: rows in grid order, and the same
numbers except the times. Progress lines come as the runs finish.

{textwrap.fill(SUCCESS_DEFINITION, 100)}
"""

DEFAULT_PERCENTS = "10,30,50"
DEFAULT_SEEDS = "1,2,3"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `egnc-bench`."""
    parser = argparse.ArgumentParser(
        prog="egnc-bench",
        description="Benchmark robust pose-graph methods on corrupted datasets (or an IRL log with labels).",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--datasets", type=_names, help="comma-separated g2o paths or names in --data-dir (csail,intel,...)"
    )
    source.add_argument("--irl", type=Path, help="an IRL log: solve it as is, scored against its own labels")
    parser.add_argument(
        "--data-dir",
        type=Path,
        default=Path("../shared/datasets"),
        help="where dataset names are looked up (default ../shared/datasets)",
    )
    add_irl_covariance_order(parser)
    parser.add_argument(
        "--percent", type=_floats, help=f"outlier percentages among loop closures (default {DEFAULT_PERCENTS})"
    )
    parser.add_argument("--seeds", type=_ints, help=f"corruption seeds (default {DEFAULT_SEEDS})")
    parser.add_argument(
        "--methods", default="egnc,risam,gnc-gm,gnc-tls,l2", help="comma-separated method specs (see below)"
    )
    parser.add_argument("--variant", choices=VARIANTS, default="random", help="false-loop variant (default random)")
    parser.add_argument(
        "--outlier-rule",
        choices=OUTLIER_RULES,
        default="squared",
        help="a candidate false loop counts when r^2 (default) or, as riSAM's generator, r exceeds chi2.ppf(0.95, d)",
    )
    parser.add_argument(
        "--time-limit", type=positive_float, default=300.0, help="seconds per run before it is killed (default 300)"
    )
    parser.add_argument(
        "--baseline-method", default="risam", help="method the time ratios are relative to (default risam)"
    )
    parser.add_argument(
        "--linear-solver",
        choices=LINEAR_SOLVERS,
        default="auto",
        help="egnc's sparse backend for every solve (default auto)",
    )
    parser.add_argument(
        "--workers",
        type=int_at_least(1),
        help="runs at once on this machine, each in its own child process (default 1)",
    )
    parser.add_argument(
        "--dask-scheduler",
        metavar="ADDRESS",
        help="run on this Dask cluster instead (e.g. tcp://127.0.0.1:8786); needs egnc[dask]",
    )
    parser.add_argument("--out", type=Path, default=Path("bench-results"), help="output folder (default bench-results)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines and no table on stdout")
    parser.add_argument("--version", action="version", version=f"egnc {__version__}")
    return parser


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError("expected at least one dataset")
    return names


def _floats(text: str) -> list[float]:
    try:
        return [float(value) for value in _names(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _ints(text: str) -> list[int]:
    try:
        return [int(value) for value in _names(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def _package_version(name: str) -> str | None:
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def describe_environment(argv: list[str], args: argparse.Namespace) -> str:
    """Markdown lines above the table: the command, the date, versions and the machine."""
    packages = ", ".join(
        f"{name} {found}" for name in ("numpy", "scipy", "scikit-sparse", "gtsam") if (found := _package_version(name))
    )
    where = f"on the Dask cluster at {args.dask_scheduler}" if args.dask_scheduler else f"{args.workers or 1} at a time"
    stamp = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    return (
        f"`egnc-bench {shlex.join(argv)}`\n\n"
        f"{stamp}; egnc {__version__}, {packages}; Python {platform.python_version()}, "
        f"{platform.machine()}, {os.cpu_count()} cpus; time limit {args.time_limit:g} s per run, "
        f"linear solver {args.linear_solver}"
        + ("" if args.irl else f", false-loop variant {args.variant}")
        + f", runs {where}"
        + ". Means over the seeds that finished; time = solver time (egnc: Result.time_s, GTSAM: optimize())."
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of `egnc-bench`; returns the process exit code."""
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.irl is not None and (args.percent is not None or args.seeds is not None):
        parser.error("--percent and --seeds apply to --datasets, not to --irl (an IRL log carries its own labels)")
    if args.irl is None and args.irl_covariance_order is not None:
        parser.error("--irl-covariance-order applies to --irl logs, not to --datasets")
    if args.workers is not None and args.dask_scheduler is not None:
        parser.error("--workers and --dask-scheduler exclude each other (the cluster has its own workers)")
    pool = {"workers": args.workers or 1, "dask_scheduler": args.dask_scheduler}

    def progress(line: str) -> None:
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    started = time.perf_counter()
    try:
        methods = parse_methods(args.methods)
        if args.irl is not None:
            records = run_irl(
                args.irl,
                methods,
                time_limit_s=args.time_limit,
                linear_solver=args.linear_solver,
                progress=progress,
                covariance_order=args.irl_covariance_order,
                **pool,
            )
        else:
            records = run_grid(
                args.datasets,
                args.percent or _floats(DEFAULT_PERCENTS),
                args.seeds or _ints(DEFAULT_SEEDS),
                methods,
                data_dir=args.data_dir,
                variant=args.variant,
                outlier_rule=args.outlier_rule,
                time_limit_s=args.time_limit,
                linear_solver=args.linear_solver,
                progress=progress,
                **pool,
            )
        written = write_outputs(
            records, args.out, baseline_method=args.baseline_method, header=describe_environment(argv, args)
        )
    except EgncError as error:
        print(f"egnc-bench: error: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(format_markdown(summarize(records, args.baseline_method), args.baseline_method))
        elapsed = time.perf_counter() - started
        print(
            f"\n{len(records)} runs in {elapsed:.1f} s; wrote {', '.join(str(path) for path in written.values())}",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
