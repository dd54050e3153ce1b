"""`egnc-corrupt`: add seeded false loop closures to a g2o file (riSAM's protocol), and GNSS-like
position priors with multipath outliers (`--gnss-every`).

The clean input is solved with plain least squares (`egnc.solve(..., "l2")`) for the
outlier-free reference; `egnc.datasets.add_false_loops` draws the false loops against it; the
corrupted graph and its labels sidecar (`egnc.datasets.write_labels`) are written atomically.
The same input, options and seed give byte-identical files.

Exit codes: 0 success; 1 an error about the input or the outputs (one line on stderr);
2 bad command-line usage (argparse).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from egnc import __version__
from egnc.api import solve
from egnc.datasets import (
    OUTLIER_RULES,
    VARIANTS,
    add_false_loops,
    add_multipath_outliers,
    add_position_priors,
    write_labels,
)
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io import read_g2o, write_g2o
from egnc.linalg.linear_solvers import LINEAR_SOLVERS

EXAMPLES = """examples:
  egnc-corrupt datasets/grid2d.g2o --percent 30 --seed 1 -o grid2d_30.g2o
  egnc-corrupt csail.g2o --percent 50 --seed 2 --variant group --group-size 5 -o csail_50_group.g2o
  egnc-corrupt intel.g2o --percent 10 --seed 3 --variant close --close-radius 5 -o intel_close.g2o
  egnc-corrupt manhattanOlson3500.g2o --percent 10 --seed 4 --gnss-every 10 --gnss-sigma 2 \
      --gnss-outliers 20 --gnss-bursts -o manhattan_gnss.g2o
"""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `egnc-corrupt`."""
    parser = argparse.ArgumentParser(
        prog="egnc-corrupt",
        description="Add seeded false loop closures to a g2o pose graph and write their labels beside it.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("input", type=Path, help="clean pose graph (.g2o); its loop closures count as true")
    parser.add_argument(
        "--percent", type=float, required=True, help="share of false loops among all loop closures, in [0, 100)"
    )
    parser.add_argument("--seed", type=int, required=True, help="seed of the random draws")
    parser.add_argument(
        "--variant",
        choices=VARIANTS,
        default="random",
        help="random pairs (default), groups of consecutive false loops, mixed, or close endpoints",
    )
    parser.add_argument(
        "--group-size", type=int, default=5, help="false loops per group for --variant group/mixed (default 5)"
    )
    parser.add_argument(
        "--close-radius",
        type=float,
        default=10.0,
        help="--variant close: maximum distance in metres between the endpoints (default 10)",
    )
    parser.add_argument(
        "--outlier-rule",
        choices=OUTLIER_RULES,
        default="squared",
        help="a candidate false loop counts when r^2 (default) or, as riSAM's generator, r exceeds chi2.ppf(0.95, d)",
    )
    gnss = parser.add_argument_group("GNSS-like position priors (egnc.datasets.add_position_priors)")
    gnss.add_argument("--gnss-every", type=int, metavar="K", help="add a position prior on every K-th pose")
    gnss.add_argument(
        "--gnss-sigma", type=float, default=2.0, metavar="S", help="noise per coordinate, metres (default 2)"
    )
    gnss.add_argument(
        "--gnss-outliers",
        type=float,
        default=0.0,
        metavar="P",
        help="share of the fixes moved by multipath jumps of 10-50 m, in [0, 100) (default 0), labelled",
    )
    gnss.add_argument(
        "--gnss-bursts", action="store_true", help="jumps in bursts of 5-20 consecutive fixes (a street canyon)"
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="corrupted pose graph to write (.g2o)")
    parser.add_argument(
        "--labels", type=Path, help="labels sidecar to write (default: the output with .labels.json for .g2o)"
    )
    parser.add_argument(
        "--linear-solver",
        choices=LINEAR_SOLVERS,
        default="scipy",
        help="backend of the reference solve (default scipy, so the files do not depend on optional extras)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    parser.add_argument("--version", action="version", version=f"egnc {__version__}")
    return parser


def default_labels_path(output: Path) -> Path:
    """`name.g2o` -> `name.labels.json`; any other name gets `.labels.json` appended."""
    stem = output.name[: -len(".g2o")] if output.suffix == ".g2o" else output.name
    return output.with_name(f"{stem}.labels.json")


def _with_gnss(
    args: argparse.Namespace, graph: PoseGraph, reference: np.ndarray
) -> tuple[PoseGraph, np.ndarray | None, dict[str, object]]:
    """`graph` with `--gnss-every` position priors around the `(N, P)` `reference` and their
    multipath outliers, the priors' labels and metadata; `graph` itself without `--gnss-every`."""
    if args.gnss_every is None:
        return graph, None, {}
    with_priors = add_position_priors(graph, reference, every=args.gnss_every, sigma=args.gnss_sigma, seed=args.seed)
    moved = add_multipath_outliers(
        with_priors, args.gnss_outliers, seed=args.seed, bursts=args.gnss_bursts, reference_poses=reference
    )
    meta: dict[str, object] = {
        "gnss_generator": "egnc.datasets.add_position_priors, add_multipath_outliers",
        "gnss_every": args.gnss_every,
        "gnss_sigma": args.gnss_sigma,
        "gnss_outliers": args.gnss_outliers,
        "gnss_bursts": args.gnss_bursts,
    }
    return moved.graph, moved.is_outlier, meta


def main(argv: list[str] | None = None) -> int:
    """Entry point of `egnc-corrupt`; returns the process exit code."""
    args = build_parser().parse_args(argv)
    labels_path = args.labels if args.labels is not None else default_labels_path(args.output)
    written: list[Path] = []
    try:
        if labels_path.resolve() == args.output.resolve():
            raise EgncError(f"{labels_path}: the labels file must differ from the output graph")
        graph = read_g2o(args.input)
        reference = solve(graph, "l2", linear_solver=args.linear_solver)
        corrupted = add_false_loops(
            graph,
            args.percent,
            seed=args.seed,
            reference_poses=reference.graph.poses,
            variant=args.variant,
            group_size=args.group_size,
            close_radius=args.close_radius,
            outlier_rule=args.outlier_rule,
        )
        corrupted_graph, prior_outliers, gnss_meta = _with_gnss(args, corrupted.graph, reference.graph.poses)
        write_g2o(corrupted_graph, args.output)
        written.append(args.output)
        meta = {
            "graph": args.output.name,
            "clean_graph": args.input.name,
            "generator": "egnc.datasets.add_false_loops",
            "percent": args.percent,
            "variant": args.variant,
            "seed": args.seed,
            "outlier_rule": args.outlier_rule,
        }
        if args.variant in ("group", "mixed"):
            meta["group_size"] = args.group_size
        if args.variant == "close":
            meta["close_radius"] = args.close_radius
        meta["reference"] = f"l2 optimum of {args.input.name} (egnc.solve, linear_solver={args.linear_solver!r})"
        write_labels(labels_path, corrupted.is_outlier, {**meta, **gnss_meta}, prior_outliers)
    except EgncError as error:
        # A failed run leaves nothing behind: no graph without its labels.
        for path in written:
            path.unlink(missing_ok=True)
        print(f"egnc-corrupt: error: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        num_false = int(corrupted.is_outlier.sum())
        num_loops = int(graph.is_loop_closure.sum())
        print(
            f"added {num_false} false loop closures ({args.variant}, seed {args.seed}) to the {num_loops} of "
            f"{args.input.name}: {num_false / (num_false + num_loops):.1%} of loop closures are false\n"
            + (
                ""
                if prior_outliers is None
                else f"added {len(prior_outliers)} position priors (every {args.gnss_every} poses, sigma"
                f" {args.gnss_sigma} m), {int(prior_outliers.sum())} of them moved by multipath jumps\n"
            )
            + f"wrote {args.output} and {labels_path}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
