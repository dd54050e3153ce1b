"""Least squares: how fast egnc reaches the optimum, against GTSAM's Levenberg-Marquardt and g2o.

    python benchmarks/least_squares.py [compare] [--files NAME ...] [--repeat N]
    python benchmarks/least_squares.py reference [FILE ...] [--repeat N] [--tol T]
    python benchmarks/least_squares.py scale [--poses 100000,...] [--dim 2] [--backends cholmod,rslab,scipy]
        [--no-gtsam] [--runs 1] [--timeout 600] [--init file|chordal]
    python benchmarks/least_squares.py backends [--cases sphere2500,...] [--backends cholmod,scipy,...]
        [--repeat 5] [--budget 60]
    python benchmarks/least_squares.py gtsam-solve IN.g2o OUT.g2o [--init file|chordal] [--json]

- `compare` (the default; `_lib/ls_compare.py`): egnc (CHOLMOD, SciPy) against GTSAM's LM and, with
  the `g2opy` wheel, g2o's Gauss-Newton, interleaved on the same files: solve and whole-command
  times, the ratios, the optima, and milliseconds per iteration by phase.
- `reference` (`_lib/gtsam_lm.py`): GTSAM's LM under the reference protocol, checked against the
  reference errors; exit code 1 on a mismatch.
- `scale` (`_lib/ls_scale.py`): generated grids of many poses, each solver a whole process:
  wall and solve time, peak memory, cost, egnc / GTSAM.
- `backends` (`_lib/ls_backends.py`): the sparse SPD solvers egnc has or could have, on egnc's own
  Gauss-Newton matrices, each row a single-threaded child process.
- `gtsam-solve` (`_lib/gtsam_process.py`): the GTSAM process `scale` times, readG2o to writeG2o.

Each command imports only its own module, so a child process loads what its job needs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from _lib.cli import command_echo, with_default_command

COMMANDS = ("compare", "reference", "scale", "backends", "gtsam-solve")


def parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per question (module docstring)."""
    top = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = top.add_subparsers(dest="command", required=True)

    compare = commands.add_parser("compare", help="egnc against GTSAM's LM and g2o's GN on shared files")
    compare.add_argument(
        "--files", nargs="+", default=["manhattanOlson3500", "city10000", "sphere2500"], help="g2o files or names"
    )
    compare.add_argument("--repeat", type=int, default=3, help="timed runs per solver and file (median reported)")

    reference = commands.add_parser("reference", help="GTSAM's LM under the reference protocol")
    reference.add_argument("files", nargs="*", help="g2o files or dataset names (default: the reference datasets)")
    reference.add_argument("--repeat", type=int, default=1, help="timed optimize() calls per file")
    reference.add_argument("--tol", type=float, default=1e-12, help="LM relativeErrorTol = absoluteErrorTol")

    scale = commands.add_parser("scale", help="generated grids at scale, each solver a whole process")
    scale.add_argument("--generate", nargs=3, help=argparse.SUPPRESS)  # POSES DIM PATH, in the child
    scale.add_argument("--poses", default="100000,250000,500000,1000000")
    scale.add_argument("--dim", type=int, choices=(2, 3), default=2)
    scale.add_argument("--backends", default="cholmod,rslab,scipy")
    scale.add_argument("--no-gtsam", action="store_true", help="time egnc only")
    scale.add_argument("--runs", type=int, default=1)
    scale.add_argument("--timeout", type=float, default=600.0, help="seconds after which a process is killed")
    scale.add_argument("--init", choices=("file", "chordal"), default="file", help="the initial guess of both")

    backends = commands.add_parser("backends", help="sparse SPD solvers on egnc's normal equations")
    backends.add_argument("--child", help=argparse.SUPPRESS)
    backends.add_argument(
        "--cases", default="sphere2500,sphere2500-50,manhattanOlson3500,city10000,grid2d-10k,grid2d-100k"
    )
    backends.add_argument(
        "--backends",
        default="cholmod,scipy,superlu-unpostordered,superlu-mmd,superlu-colamd,cholespy,qdldl,rslab,pardiso,pyamg",
    )
    backends.add_argument("--repeat", type=int, default=5, help="numeric factorizations timed per row (median)")
    backends.add_argument("--budget", type=float, default=60.0, help="stop repeating after this many seconds")

    gtsam_solve = commands.add_parser("gtsam-solve", help="one GTSAM LM process: readG2o, optimize, writeG2o")
    gtsam_solve.add_argument("source")
    gtsam_solve.add_argument("target")
    gtsam_solve.add_argument("--init", choices=("file", "chordal"), default="file")
    gtsam_solve.add_argument("--json", action="store_true")
    return top


def main(argv: list[str] | None = None) -> int:
    """Parse the command line and run the chosen command."""
    given = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(with_default_command(given, COMMANDS, "compare"))
    if args.command == "gtsam-solve":
        from _lib import gtsam_process

        return gtsam_process.solve_file(args.source, args.target, args.init, args.json)
    if args.command == "compare":
        from _lib import ls_compare

        return ls_compare.run(args.files, args.repeat, command_echo(given))
    if args.command == "reference":
        from _lib import gtsam_lm

        return gtsam_lm.report_lm(args.files, args.repeat, args.tol, command_echo(given))
    if args.command == "scale":
        from _lib import ls_scale

        if args.generate:
            poses, dim, path = args.generate
            print(ls_scale.generate(int(poses), int(dim), Path(path)))
            return 0
        ls_scale.run(args.poses, args.dim, args.backends, not args.no_gtsam, args.runs, args.timeout, args.init)
        return 0
    import json

    from _lib import ls_backends

    if args.child:
        print(json.dumps(ls_backends.run_case(*json.loads(args.child))))
        return 0
    ls_backends.run(args.cases, args.backends, args.repeat, args.budget)
    return 0


if __name__ == "__main__":
    sys.exit(main())
