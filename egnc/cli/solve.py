"""`egnc-solve`: optimize a g2o pose graph from the command line.

Exit codes: 0 success; 1 an error about the input or the solve (one line on stderr);
2 bad command-line usage (argparse).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from egnc import __version__
from egnc.api import METHODS, Result, StageReport, solve
from egnc.errors import EgncError
from egnc.io import read_g2o, write_g2o
from egnc.io.atomic import atomic_text_file
from egnc.least_squares import SolverOptions
from egnc.plot import plot_trajectory, require_matplotlib, save_figure

EXAMPLES = """examples:
  egnc-solve datasets/grid2d_outliers.g2o -o solved.g2o
  egnc-solve graph.g2o --method risam --report report.json
  egnc-solve graph.g2o --drop-outliers -o inliers_only.g2o
  egnc-solve graph.g2o --method l2 --linear-solver scipy
  egnc-solve graph.g2o --plot trajectory.png

exit codes: 0 success; 1 error in the input, the solve or an output (one line on stderr, no
partial output file); 2 bad command-line usage.
"""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `egnc-solve`."""
    parser = argparse.ArgumentParser(
        prog="egnc-solve",
        description="Optimize a 2D or 3D pose graph given as a g2o file.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("input", type=Path, help="input pose graph (.g2o)")
    parser.add_argument("-o", "--output", type=Path, help="write the optimized graph here (.g2o)")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="egnc",
        help="egnc (default), the riSAM or GNC-GM/TLS schedules, a fixed kernel, or l2 (plain least squares)",
    )
    parser.add_argument(
        "--known-inliers",
        choices=("odometry", "none"),
        default="odometry",
        help="edges never rejected: odometry (consecutive ids, default) or none",
    )
    parser.add_argument(
        "--drop-outliers", action="store_true", help="write the output graph without the rejected loop closures"
    )
    parser.add_argument(
        "--linear-solver",
        choices=("auto", "cholmod", "scipy"),
        default="auto",
        help="sparse backend: CHOLMOD (needs egnc[cholmod]) or SciPy's SuperLU; auto picks CHOLMOD if present",
    )
    parser.add_argument("--solver", choices=("lm", "gn"), default="lm", help="Levenberg-Marquardt or Gauss-Newton")
    parser.add_argument(
        "--max-iters", type=_non_negative_int, default=100, help="maximum solver iterations (default 100)"
    )
    parser.add_argument("--skip-unknown", action="store_true", help="ignore lines with unknown g2o tags")
    parser.add_argument("--report", type=Path, help="write a JSON report here")
    parser.add_argument(
        "--plot",
        type=Path,
        metavar="PNG",
        help="draw the initial guess, the result and the accepted/rejected loop closures here (needs egnc[plot])",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    parser.add_argument("--version", action="version", version=f"egnc {__version__}")
    return parser


def _non_negative_int(text: str) -> int:
    """Parse an integer >= 0; anything else is a usage error (exit 2), not a solver error."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return value


def report_dict(result: Result) -> dict:
    """The JSON report of a solve (documented in the README)."""
    graph = result.graph
    return {
        "method": result.method,
        "linear_solver": result.linear_solver,
        "time_s": result.time_s,
        "initial_cost": result.initial_cost,
        "final_cost": result.cost,
        "iterations": result.iterations,
        "status": result.status,
        "message": result.message,
        "converged": result.converged,
        "poses": graph.num_poses,
        "edges": graph.num_edges,
        "loop_closures": int(graph.is_loop_closure.sum()),
        "known_inliers": int(result.known_inliers.sum()),
        "rejected_edges": result.rejected_edges.tolist(),
        "stages": [
            {
                "mu_min": _finite_or_none(stage.mu_min),
                "mu_mean": _finite_or_none(stage.mu_mean),
                "mu_max": _finite_or_none(stage.mu_max),
                "iterations": stage.iterations,
                "cost": stage.cost,
                "time_s": stage.time_s,
                "status": stage.status,
                "active_edges": stage.active_edges,
            }
            for stage in result.stages
        ],
        "timings_s": result.timings,
    }


def _finite_or_none(value: float) -> float | None:
    """JSON has no NaN: statistics that do not apply become null."""
    return value if math.isfinite(value) else None


def summary(result: Result) -> str:
    """A short human-readable summary of a solve."""
    graph = result.graph
    accepted_cost = 0.5 * float(np.sum(result.residual_norms[result.inliers] ** 2))
    return "\n".join(
        [
            f"poses {graph.num_poses}, edges {graph.num_edges}, loop closures {int(graph.is_loop_closure.sum())}"
            f" ({graph.dim}D)",
            f"method {result.method}, linear solver {result.linear_solver}",
            f"least-squares cost {result.initial_cost:.10g} -> {result.cost:.10g} over all edges,"
            f" {accepted_cost:.10g} over the accepted ones",
            f"{len(result.stages)} stages, {result.iterations} iterations ({result.message})",
            f"rejected {len(result.rejected_edges)} of {int((~result.known_inliers).sum())} loop closures"
            f" (candidates: edges not known inliers)",
            f"time {result.time_s:.3f} s",
        ]
    )


def _print_stage_progress() -> Callable[[StageReport], None]:
    """A callback printing one progress line per finished stage on stderr."""
    count = 0

    def show(stage: StageReport) -> None:
        nonlocal count
        count += 1
        mu = "least squares" if math.isnan(stage.mu_mean) else f"mu {stage.mu_min:.3g}..{stage.mu_max:.3g}"
        print(
            f"stage {count}: {mu}, {stage.iterations} iterations, cost {stage.cost:.6g},"
            f" {stage.active_edges} edges, {stage.time_s:.2f} s",
            file=sys.stderr,
            flush=True,
        )

    return show


def main(argv: list[str] | None = None) -> int:
    """Entry point of `egnc-solve`; returns the process exit code."""
    args = build_parser().parse_args(argv)
    written: list[Path] = []
    try:
        if args.plot is not None:  # fail before a long solve, not after it
            require_matplotlib()
        graph = read_g2o(args.input, skip_unknown=args.skip_unknown)
        result = solve(
            graph,
            args.method,
            known_inliers=args.known_inliers,
            linear_solver=args.linear_solver,
            options=SolverOptions(method=args.solver, max_iterations=args.max_iters),
            on_stage=None if args.quiet else _print_stage_progress(),
        )
        if args.output is not None:
            write_g2o(result.graph, args.output, keep_edges=result.inliers if args.drop_outliers else None)
            written.append(args.output)
        if args.report is not None:
            with atomic_text_file(args.report) as out:
                out.write(json.dumps(report_dict(result), indent=2) + "\n")
            written.append(args.report)
        if args.plot is not None:
            save_figure(plot_trajectory(result, initial=graph), args.plot)
    except EgncError as error:
        # A failed run leaves no output behind, not even a graph written before the report failed.
        for path in written:
            path.unlink(missing_ok=True)
        print(f"egnc-solve: error: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(summary(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
