"""`egnc-solve`: optimize a g2o pose graph or an IRL log from the command line, in batch or online.

The input is read as riSAM's Incremental Robot Log (`egnc.io.irl`) when its name ends in `.irl`
or its fourth line is `nonlinear` (the IRL header), else as g2o. For an IRL log the known inliers
are its ODOMETRY entries, and edge indices count its ODOMETRY and LOOP entries in file order.
`--online` replays the input pose by pose through the online solver (`egnc.online.replay`) instead of
solving it in one batch.

Exit codes: 0 success; 1 an error about the input, the solve or an output (one line on stderr,
no output written); 2 bad command-line usage (argparse); 3 numerical failure (the solve produced
non-finite numbers, or the problem cannot be represented in double precision; one line, no
output); 130 / 143 interrupted by SIGINT / SIGTERM (one line, no output).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from egnc import __version__
from egnc.api import INITIALIZATIONS, METHODS, Result, solve
from egnc.cli.arguments import add_irl_covariance_order, int_at_least, positive_float, share
from egnc.cli.outputs import OutputPlan
from egnc.cli.progress import Progress, StepProgress
from egnc.cli.report import report_dict, summary
from egnc.cli.signals import INTERRUPT_EXIT_CODES, Terminated, sigterm_raises
from egnc.errors import EgncError, EgncWarning, NumericalError, OptionError
from egnc.graph import PoseGraph
from egnc.graph.health import UnrepresentableError
from egnc.io import read_g2o, read_irl
from egnc.io.edge_roles import read_known_inliers
from egnc.io.information import INFORMATION_MODES
from egnc.io.trajectory import TRAJECTORY_FORMATS
from egnc.linalg.linear_solvers import LINEAR_SOLVERS, resolve_name
from egnc.linalg.step_solver import LINEAR_METHODS
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, SolverOptions
from egnc.online import ONLINE_METHODS, OnlineOptions
from egnc.online.replay import CHECKPOINT_EVERY, ReplayOutcome, replay, replay_steps
from egnc.rerun import DEFAULT_VIEWER_URL, OnlineRecorder, StageRecorder, log_result, recording
from egnc.robust.gnc import KNOWN_INLIER_KINDS, known_inlier_mask

EXIT_NUMERICAL_FAILURE = 3
"""Exit code when the solve fails numerically (documented in docs/cli.md)."""

"""`Result.status` of a solve that produced non-finite numbers (`egnc.nonlinear.least_squares`)."""

CHOLMOD_HINT_MIN_POSES = {2: 30_000, 3: 3_000}
"""Graph sizes (poses, by dimension) from which a SciPy-only `egnc-solve` names the `rslab` and `cholmod` extras.

Measured with the default method, SciPy's SuperLU against CHOLMOD (2 shared cores, so absolute
times are high), before issue 18 postordered SuperLU's order (up to 7x faster factorizations on
large 2D graphs; BENCHMARKS.md, "Pip-only sparse Cholesky"): 3D grid worlds of 2000 / 3500 /
5000 poses 0.8 / 3.1 / 6.1 s against 0.2 / 0.4 / 0.9 s; sphere2500 1.1 against 0.5 s; SE-Sync's
torus3D (5000 poses) 92 against 8 s; cubicle (5750) 215 against 34 s. In 2D the fill-in is
smaller: city10000 2.9 against 0.9 s, a 30000-pose grid world 6.6 against 2.3 s; but a
100 000-pose one with 10 % false loops took 129 s on CHOLMOD and had not finished after 11
minutes on SuperLU (BENCHMARKS.md, "Large graphs").
"""

EXAMPLES = """examples:
  egnc-solve datasets/grid2d_outliers.g2o -o solved.g2o
  egnc-solve manhattan_noisy.irl --report report.json
  egnc-solve manhattan_noisy.irl --online --method risam --checkpoint run.ckpt
  egnc-solve graph.g2o --method risam --report report.json
  egnc-solve graph.g2o --drop-outliers -o inliers_only.g2o
  egnc-solve graph.g2o --method l2 --linear-solver scipy
  egnc-solve graph.g2o --plot trajectory.png
  egnc-solve graph.g2o --trajectory solved.tum --edges edges.csv
  egnc-solve manhattan_noisy.irl --online --rerun run.rrd
  egnc-solve cubicle.g2o --information nearest-pd --known-inliers odometry

exit codes: 0 success; 1 error in the input, the solve or an output (one line on stderr, no
output written); 2 bad command-line usage; 3 numerical failure (no output written);
130 / 143 interrupted by SIGINT / SIGTERM (no output written).
"""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `egnc-solve`."""
    parser = argparse.ArgumentParser(
        prog="egnc-solve",
        description="Optimize a 2D or 3D pose graph given as a g2o file or an IRL log, in batch or online.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_problem_arguments(parser)
    _add_solver_arguments(parser)
    _add_online_arguments(parser)
    _add_output_arguments(parser)
    return parser


def _add_problem_arguments(parser: argparse.ArgumentParser) -> None:
    """The input, the graph output, the method, the edges' roles and the initial guess."""
    parser.add_argument("input", type=Path, help="input pose graph (.g2o) or riSAM log (.irl)")
    parser.add_argument("-o", "--output", type=Path, help="write the optimized graph here (.g2o)")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="egnc",
        help="egnc (default), the riSAM or GNC-GM/TLS schedules, a fixed kernel, or l2 (plain least squares)",
    )
    parser.add_argument(
        "--known-inliers",
        default="odometry",
        metavar="{KINDS,none,FILE}",
        help="factors never rejected: kinds joined by commas among odometry (consecutive ids in either"
        " direction, default), loops and priors (e.g. odometry,priors; priors not named are candidates like"
        " loop closures), none, or a FILE of edge indices (whitespace separated, # comments) or an egnc"
        " labels JSON (every edge it does not list as an outlier)",
    )
    parser.add_argument(
        "--information",
        choices=INFORMATION_MODES,
        default="strict",
        help="information matrices that are not positive definite: strict (default) refuses the file,"
        " nearest-pd clips their eigenvalues, diagonal keeps their diagonal (one warning with the count)",
    )
    add_irl_covariance_order(parser)
    parser.add_argument(
        "--drop-outliers", action="store_true", help="write the output graph without the rejected loop closures"
    )
    parser.add_argument(
        "--init",
        choices=INITIALIZATIONS,
        default="file",
        help="initial guess: the file's poses (default), the odometry composed from the first pose, or the"
        " chordal relaxation (better from a drifted guess, but distorted by false loop closures)",
    )


def _add_solver_arguments(parser: argparse.ArgumentParser) -> None:
    """The linear backend and method, the nonlinear solver, its iteration limit, and unknown g2o lines."""
    parser.add_argument(
        "--linear-solver",
        choices=LINEAR_SOLVERS,
        default="auto",
        help="sparse backend: CHOLMOD (needs egnc[cholmod]) or SciPy's SuperLU; auto picks CHOLMOD if present",
    )
    parser.add_argument(
        "--linear-method",
        choices=LINEAR_METHODS,
        default="auto",
        help="auto: solve robust steps by conjugate gradients preconditioned by the edges the kernel kept"
        " (false loops then cost no fill-in); direct: factorize every edge at every step",
    )
    parser.add_argument("--solver", choices=("lm", "gn"), default="lm", help="Levenberg-Marquardt or Gauss-Newton")
    parser.add_argument(
        "--max-iters", type=int_at_least(0), default=100, help="maximum solver iterations (default 100)"
    )
    parser.add_argument(
        "--skip-unknown",
        action="store_true",
        help="skip lines with g2o tags egnc does not read (landmarks, parameters, ...); -o writes them back unchanged",
    )


def _add_online_arguments(parser: argparse.ArgumentParser) -> None:
    """`--online` and the options of its replay: checkpoints, regions, decisions at arrival."""
    parser.add_argument(
        "--online",
        action="store_true",
        help="replay the input pose by pose through the online solver (methods egnc and risam): each new pose"
        " with its odometry and loop closures is one update; the report gains an 'online' object",
    )
    parser.add_argument(
        "--checkpoint",
        type=Path,
        metavar="PATH",
        help="with --online: save the solver's state here every --checkpoint-every steps, and resume from it"
        " when it exists (same input and method)",
    )
    parser.add_argument(
        "--checkpoint-every",
        type=int_at_least(1),
        metavar="N",
        help=f"with --checkpoint: steps between two saves (default {CHECKPOINT_EVERY}; one more after the last step)",
    )
    parser.add_argument(
        "--region-hops",
        type=int_at_least(0),
        metavar="N",
        help="with --online: solve each loop update first on the poses within N trusted edges of its new"
        f" edges, falling back to the whole map when in doubt (default {OnlineOptions().region_hops};"
        " 0: always the whole map)",
    )
    parser.add_argument(
        "--boundary-share",
        type=share,
        metavar="S",
        help="with --online: a loop update finishes on the whole map when its region's boundary would still"
        " lower the cost by more than S times the update's tolerance (default"
        f" {OnlineOptions().boundary_share}; larger: lower latency, a running estimate further from the"
        " optimum; docs/online.md)",
    )
    parser.add_argument(
        "--decide-at-arrival",
        action="store_true",
        help="with --online and --method egnc: solve nothing for a loop update whose stages, predicted from the"
        " map factorized after the last solve, would end where it starts (docs/online.md)",
    )


def _add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """The report, the figure, the trajectory and edge files, `--quiet` and `--version`."""
    parser.add_argument("--report", type=Path, help="write a JSON report here")
    parser.add_argument(
        "--plot",
        type=Path,
        metavar="PNG",
        help="draw the initial guess, the result and the accepted/rejected loop closures here (needs egnc[plot])",
    )
    parser.add_argument(
        "--plot-size",
        type=positive_float,
        nargs=2,
        metavar=("WIDTH", "HEIGHT"),
        help="size of the --plot figure in inches (default 6.4 6.0 for a 2D graph, 7.0 5.6 for 3D)",
    )
    parser.add_argument(
        "--dpi", type=positive_float, default=100.0, help="resolution of the --plot image, dots per inch (default 100)"
    )
    parser.add_argument(
        "--rerun",
        type=Path,
        metavar="RRD",
        help="record the solve for the Rerun viewer here: the initial guess, each stage's poses, loop closures"
        " coloured by IRLS weight (rejected ones red), residuals; with --online every update on a timeline"
        " (needs egnc[rerun]; written last, after the other outputs)",
    )
    parser.add_argument(
        "--rerun-connect",
        nargs="?",
        const=DEFAULT_VIEWER_URL,
        metavar="URL",
        help=f"stream the same recording to a running Rerun viewer (default {DEFAULT_VIEWER_URL})",
    )
    parser.add_argument(
        "--trajectory", type=Path, metavar="FILE", help="write the optimized poses here, TUM (.tum) or KITTI (.kitti)"
    )
    parser.add_argument(
        "--trajectory-format",
        choices=TRAJECTORY_FORMATS,
        help="format of --trajectory when its suffix does not say (e.g. .txt)",
    )
    parser.add_argument(
        "--edges", type=Path, metavar="CSV", help="write one CSV row per edge: index,i,j,kind,r,weight,mu,inlier"
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success but warnings")
    parser.add_argument("--version", action="version", version=f"egnc {__version__}")


def main(argv: list[str] | None = None) -> int:
    """Entry point of `egnc-solve`; returns the process exit code (module docstring)."""
    # The objects made by the imports (NumPy's and SciPy's, several hundred thousand) live until
    # exit: frozen, the garbage collector stops rescanning them each time reading or solving
    # triggers a full collection (25 ms of a city10000 run). Unfrozen after, for in-process callers.
    gc.freeze()
    try:
        return _main(argv)
    finally:
        gc.unfreeze()


def _main(argv: list[str] | None) -> int:
    """`main` without the garbage-collector setting."""
    args = build_parser().parse_args(argv)
    plan = OutputPlan(
        graph=args.output,
        report=args.report,
        plot=args.plot,
        plot_size=None if args.plot_size is None else tuple(args.plot_size),
        dpi=args.dpi,
        trajectory=args.trajectory,
        trajectory_format=args.trajectory_format,
        edges=args.edges,
        drop_outliers=args.drop_outliers,
        rerun=args.rerun,
    )
    try:
        with sigterm_raises(), _recording(args) as stream:
            result, written, online = _run(args, plan, stream)
    except NumericalError as error:
        print(f"egnc-solve: numerical failure: {error}", file=sys.stderr)
        return EXIT_NUMERICAL_FAILURE
    except EgncError as error:
        print(f"egnc-solve: error: {error}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, Terminated) as interruption:
        code, what = INTERRUPT_EXIT_CODES[type(interruption)]
        start = "\n" if sys.stderr.isatty() else ""  # below a live progress line, not on it
        print(f"{start}egnc-solve: {what}; no output written", file=sys.stderr)
        return code
    if not args.quiet:
        print(summary(result, written))
        if online is not None:
            latency = online["update_ms"]
            print(
                f"online: {online['steps']} updates, {online['iterations']} iterations, {online['total_s']:.3f} s;"
                f" update ms p50 {latency['p50']:.1f}, p99 {latency['p99']:.1f}, max {latency['max']:.1f}"
            )
    return 0


def _recording(args: argparse.Namespace) -> contextlib.AbstractContextManager:
    """The Rerun recording of `--rerun` and `--rerun-connect` (`egnc.rerun.recording`), or none (None)."""
    if args.rerun is None and args.rerun_connect is None:
        return contextlib.nullcontext()
    return recording(args.rerun, args.rerun_connect)


def _run(args: argparse.Namespace, plan: OutputPlan, stream=None) -> tuple[Result, list[Path], dict | None]:
    """Check the outputs, read, solve, write: the work of `main` between its error handlers; `stream`
    is the Rerun recording to log the solve to (None: none)."""
    _check_options(args)
    plan.check(args.input)  # before a long read and solve, not after them
    if args.checkpoint is not None and any(_same_path(args.checkpoint, path) for _, path in plan.paths()):
        raise EgncError(f"{args.checkpoint}: --checkpoint names an output file; choose another path")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        graph, odometry = _read(args)
        known_inliers = odometry if args.known_inliers == "odometry" else _known_inliers(args.known_inliers, graph)
        read_notes = _warning_notes(caught) + _duplicate_note(graph, args.input)
        hint = None if args.quiet else cholmod_hint(graph, args.linear_solver, resolve_name("auto") != "scipy")
        if hint is not None:
            print(f"hint: {hint}", file=sys.stderr, flush=True)  # before the solve: it explains a long one
        read_count = len(caught)
        resumed = args.checkpoint if args.checkpoint is not None and args.checkpoint.exists() else None
        try:
            result, outcome = _solve(args, graph, known_inliers, stream)
        except EgncError as error:
            # a replay numbers the edges in the order it adds them (`replay_steps`), a batch solve in file order
            edges_known = _mask(known_inliers, graph)[: graph.num_edges]
            order = np.concatenate(replay_steps(graph, edges_known)) if args.online else None
            raise located(error, args.input, graph, [args.checkpoint], order, resumed) from None
    _require_finite(result, args.input)
    report = report_dict(result, read_notes + _warning_notes(caught[read_count:]), outcome)
    written, output_notes = plan.write(result, graph, report)
    # Only a run that succeeds shows its warnings: a failure is one line (docs/cli.md).
    _print_warnings(report["warnings"] + output_notes)
    return result, written, report.get("online")


def _solve(
    args: argparse.Namespace, graph: PoseGraph, known_inliers: str | np.ndarray, stream=None
) -> tuple[Result, ReplayOutcome | None]:
    """Solve `graph` in one batch, or replay it with `--online`: the result, and the replay's outcome;
    recorded to the Rerun recording `stream` unless None."""
    options = SolverOptions(method=args.solver, max_iterations=args.max_iters, linear_method=args.linear_method)
    if not args.online:
        progress = None if args.quiet else Progress(sys.stderr)
        on_stage = None if progress is None else progress.on_stage
        result = solve(
            graph,
            args.method,
            known_inliers=known_inliers,
            init=args.init,
            linear_solver=args.linear_solver,
            options=options,
            on_stage=on_stage if stream is None else StageRecorder(stream, then=on_stage),
            on_iteration=None if progress is None else progress.on_iteration,
        )
        if stream is not None:
            log_result(result, stream, initial=graph)
        return result, None
    online_options = OnlineOptions(decide_at_arrival=args.decide_at_arrival)
    if args.region_hops is not None:
        online_options = replace(online_options, region_hops=args.region_hops or None)
    if args.boundary_share is not None:
        online_options = replace(online_options, boundary_share=args.boundary_share)
    recorder = None if stream is None else OnlineRecorder(stream)
    outcome = replay(
        graph,
        args.method,
        known_inliers=_mask(known_inliers, graph),
        linear_solver=args.linear_solver,
        options=options,
        checkpoint=args.checkpoint,
        checkpoint_every=args.checkpoint_every or CHECKPOINT_EVERY,
        online_options=online_options,
        on_step=None if args.quiet else StepProgress(sys.stderr).on_step,
        on_update=recorder,
    )
    if recorder is not None:
        recorder.flush()
        log_result(outcome.result, recorder.recording, initial=graph)
    return outcome.result, outcome


def located(
    error: EgncError,
    input_path: Path,
    graph: PoseGraph,
    own_paths: list[Path | None],
    edge_order: np.ndarray | None = None,
    resumed: Path | None = None,
) -> EgncError:
    """`error` of a solve of the graph read from `input_path`, its message led by `<file>[:<line>]: `.

    An error about one edge (`UnrepresentableError`) names that edge's line; an `OptionError` (about
    the command line) and one whose message already starts with the input or one of `own_paths` (a
    checkpoint's) are returned unchanged.

    Args:
        error: what the solve or replay raised.
        input_path: the input file.
        graph: the graph read from it (`edge_lines`).
        own_paths: other files an error may name itself (None entries ignored).
        edge_order: `(E,)` the file index of each edge as the solve numbers them (None: file order).
        resumed: the checkpoint a replay resumed from, if any: its state may be at fault, so the
            message names it too.
    """
    message = str(error)
    if isinstance(error, OptionError):  # about the command line, not the input
        return error
    if any(path is not None and message.startswith(f"{path}:") for path in (input_path, *own_paths)):
        return error
    edge = error.edge if isinstance(error, UnrepresentableError) else None
    if edge is not None and edge_order is not None:
        edge = int(edge_order[edge]) if 0 <= edge < len(edge_order) else None
    line = int(graph.edge_lines[edge]) if edge is not None and 0 <= edge < graph.num_edges else 0
    where = f"{input_path}:{line}" if line > 0 else f"{input_path}"
    if resumed is not None:
        message = f"{message} (resumed from the checkpoint {resumed})"
    # `main` tells only numerical failures (exit 3) from the other errors (exit 1)
    return (
        NumericalError(f"{where}: {message}") if isinstance(error, NumericalError) else EgncError(f"{where}: {message}")
    )


def _check_options(args: argparse.Namespace) -> None:
    """Refuse option combinations that cannot apply, before anything is read."""
    if args.online and args.method not in ONLINE_METHODS:
        raise EgncError(f"--online replays with the methods {' and '.join(ONLINE_METHODS)}, not {args.method}")
    if args.online and args.init != "file":
        raise EgncError("--online places every new pose by composing its odometry: --init does not apply")
    if not args.online and args.checkpoint is not None:
        raise EgncError("--checkpoint saves the state of an --online replay: add --online")
    if args.checkpoint is None and args.checkpoint_every is not None:
        raise EgncError("--checkpoint-every sets how often --checkpoint saves: add --checkpoint")
    if not args.online and args.region_hops is not None:
        raise EgncError("--region-hops sets how an --online update solves: add --online")
    if not args.online and args.boundary_share is not None:
        raise EgncError("--boundary-share sets how an --online update solves: add --online")
    if args.decide_at_arrival and (not args.online or args.method != "egnc"):
        raise EgncError("--decide-at-arrival sets how an --online update with --method egnc solves")
    if is_irl(args.input) and (args.skip_unknown or args.information != "strict"):
        raise EgncError("--skip-unknown and --information apply to g2o files, not to IRL logs")
    if args.irl_covariance_order is not None and not is_irl(args.input):
        raise EgncError("--irl-covariance-order applies to IRL logs, not to g2o files")


def _read(args: argparse.Namespace) -> tuple[PoseGraph, np.ndarray]:
    """The input graph and its odometry: an IRL log's ODOMETRY entries, a g2o file's consecutive-id edges."""
    if is_irl(args.input):
        log = read_irl(args.input, args.irl_covariance_order)
        return log.graph, log.is_odometry
    graph = read_g2o(args.input, skip_unknown=args.skip_unknown, information=args.information)
    return graph, graph.is_odometry


def is_irl(path: Path) -> bool:
    """Whether `path` holds an IRL log: named `.irl`, or its fourth line is `nonlinear` (the IRL header)."""
    if path.suffix.lower() == ".irl":
        return True
    try:
        with open(path, encoding="utf-8", errors="replace") as text:
            head = [text.readline(200) for _ in range(4)]
    except OSError:
        return False  # the g2o reader reports it
    return head[3].strip() == "nonlinear" and head[2].strip() in ("2", "3")


def _mask(known_inliers: str | np.ndarray, graph: PoseGraph) -> np.ndarray:
    """`(E,)` bool known-inlier edges, or `(E + K,)` edges then priors, from the `--known-inliers` choice."""
    return known_inlier_mask(graph, known_inliers)


def _same_path(a: Path, b: Path) -> bool:
    return a.resolve() == b.resolve()


def _warning_notes(caught: list[warnings.WarningMessage]) -> list[str]:
    """One line per `EgncWarning`; other warnings (NumPy's overflow notices, ...) summed up in one line."""
    notes = [str(warning.message) for warning in caught if issubclass(warning.category, EgncWarning)]
    others = [warning for warning in caught if not issubclass(warning.category, EgncWarning)]
    if others:
        first = f"{others[0].category.__name__}: {others[0].message}"
        notes.append(f"{len(others)} warnings from the libraries egnc uses; the first: {first}")
    return notes


def _duplicate_note(graph: PoseGraph, input_path: Path) -> list[str]:
    """The warning about duplicate edges, if the graph has any (`PoseGraph.is_duplicate`)."""
    duplicates = int(graph.is_duplicate.sum())
    if not duplicates:
        return []
    return [
        f"{input_path}: {duplicates} duplicate edges (the same two vertices as an earlier edge, in either "
        "direction); all are kept and solved"
    ]


def cholmod_hint(graph: PoseGraph, linear_solver: str, cholesky_installed: bool) -> str | None:
    """The line suggesting a sparse Cholesky extra, for a large graph left to SciPy by `auto`; else None.

    Args:
        graph: the graph about to be solved.
        linear_solver: `--linear-solver`; asking for `scipy` by name gets no hint.
        cholesky_installed: whether `auto` finds a faster backend (scikit-sparse or rslab).
    """
    if linear_solver != "auto" or cholesky_installed or graph.num_poses < CHOLMOD_HINT_MIN_POSES[graph.dim]:
        return None
    return (
        f"neither rslab nor scikit-sparse is installed, so this {graph.num_poses}-pose {graph.dim}D graph is"
        " solved with SciPy's SuperLU; a sparse Cholesky is several times faster at this size:"
        ' pip install "egnc[rslab]", or CHOLMOD: apt-get install libsuitesparse-dev, then'
        ' pip install "egnc[cholmod]"'
    )


def _known_inliers(choice: str, graph: PoseGraph) -> str | np.ndarray:
    """`--known-inliers`: kinds joined by commas (`odometry,priors`), `none`, or a file read by `egnc.io.edge_roles`."""
    kinds = {name.strip() for name in choice.split(",")}
    if kinds <= {*KNOWN_INLIER_KINDS, "none"}:
        return choice
    return read_known_inliers(choice, graph.num_edges)


def _require_finite(result: Result, input_path: Path) -> None:
    """Raise `NumericalError` for a solve the library marked as a numerical failure or that is not finite."""
    if result.status == NUMERICAL_FAILURE:
        raise NumericalError(f"{input_path}: {result.message}")
    if not (np.isfinite(result.graph.poses).all() and np.isfinite(result.residual_norms).all()):
        raise NumericalError(f"{input_path}: the solution holds non-finite numbers ({result.message})")


def _print_warnings(notes: list[str]) -> None:
    """Each warning as one `warning: ...` line on stderr."""
    for note in notes:
        print(f"warning: {note}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    sys.exit(main())
