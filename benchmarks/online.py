"""The online solver: accuracy and latency of pose-by-pose replays, against riSAM's schedule and GTSAM's ISAM2.

    python benchmarks/online.py [replay] [--datasets csail,intel] [--percents 10,30,50] [--seed 0]
        [--methods egnc,risam] [--irl manhattan_noisy] [--stage-iterations N] [--regraduate reference|new]
        [--region-hops N] [--boundary-share S] [--strong-at-arrival] [--decide-at-arrival]
        [--rel-cost-tol TOL] [--linear-solver auto] [--repeats N] [--json rows.jsonl]
    python benchmarks/online.py isam2 FILE.g2o [--relinearize-threshold 0.1] [--relinearize-skip 10]
        [--reference] [--output ESTIMATE.g2o]
    python benchmarks/online.py gnss [--files manhattanOlson3500,sphere2500,city10000] [--loops 0,10,30]
        [--priors 0,10,20] [--every 10] [--sigma 2] [--seed 1] [--baseline] [--json rows.jsonl]
    nice -n 10 python benchmarks/online.py vs-isam2 [--datasets manhattanOlson3500,sphere2500,city10000]
        [--percent 30] [--seed 1] [--repeats 1] [--relinearize-skips 10] [--egnc-timeout 1200]
        [--isam2-timeout 600] [--region-hops N] [--boundary-share S] [--decide-at-arrival] [--json rows.jsonl]

- `replay` (the default; `_lib/online_replay.py`): corrupted graphs replayed through
  `egnc.online.replay` with egnc's and riSAM's schedules in one process: precision, recall and ATE
  of the final and running decisions, iterations, total time and update latency.
- `gnss` (`_lib/online_gnss.py`): `benchmarks/robust.py gnss`'s cases (GNSS fixes with multipath
  jumps, false loops) replayed online: P and R of the loops and of the priors, ATE without
  alignment, update time and latency, and the batch solve's time.
- `isam2` (`_lib/isam2_replay.py`): GTSAM's ISAM2 (non-robust) replaying one g2o file in the same
  steps; one JSON line of times, latency, cost and peak memory.
- `vs-isam2` (`_lib/online_vs_isam2.py`): `egnc-solve --online` on the corrupted graph against
  `online.py isam2` on the clean one, each a whole child process, alternated.

Each command imports only its own module, so an `isam2` child loads what its replay needs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from _lib.cli import add_gnss_case_arguments, with_default_command

COMMANDS = ("replay", "gnss", "isam2", "vs-isam2")


def parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per question (module docstring)."""
    top = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = top.add_subparsers(dest="command", required=True)

    replay = commands.add_parser("replay", help="egnc and risam replaying corrupted graphs, in this process")
    replay.add_argument("--datasets", default="csail,intel,manhattanOlson3500,sphere2500")
    replay.add_argument("--percents", default="10,30,50")
    replay.add_argument("--seed", type=int, default=0)
    replay.add_argument("--methods", default="egnc,risam")
    replay.add_argument("--irl", default="manhattan_noisy", help="IRL logs (names in the datasets folder); '' for none")
    replay.add_argument("--stage-iterations", type=int, default=1, help="0: every stage converges")
    replay.add_argument(
        "--region-hops", type=int, help="OnlineOptions.region_hops (default: its default); 0: the whole map"
    )
    replay.add_argument("--boundary-share", type=float, help="OnlineOptions.boundary_share (default: its default)")
    replay.add_argument("--regraduate", default="reference", choices=("reference", "new"))
    replay.add_argument("--strong-at-arrival", action="store_true", help="OnlineOptions(strong_at_arrival=True)")
    replay.add_argument("--decide-at-arrival", action="store_true", help="OnlineOptions(decide_at_arrival=True)")
    replay.add_argument(
        "--rel-cost-tol", type=float, help="OnlineOptions.rel_cost_tol (default: its default): where an update stops"
    )
    replay.add_argument("--linear-solver", default="auto")
    replay.add_argument("--repeats", type=int, default=1, help="replays of each method per case, alternating")
    replay.add_argument("--json", type=Path, help="append one JSON line per row here")

    gnss = commands.add_parser("gnss", help="GNSS fixes with multipath outliers and false loops, replayed online")
    add_gnss_case_arguments(gnss)
    gnss.add_argument("--baseline", action="store_true", help="also replay each graph without its fixes (time ratio)")
    gnss.add_argument("--json", type=Path, help="append one JSON line per row here")

    isam2 = commands.add_parser("isam2", help="GTSAM's ISAM2 replaying one g2o file; one JSON line")
    isam2.add_argument("file", help="a 2D or 3D g2o file with VERTEX lines")
    isam2.add_argument("--relinearize-threshold", type=float, default=0.1, help="ISAM2Params (GTSAM default 0.1)")
    isam2.add_argument("--relinearize-skip", type=int, default=10, help="ISAM2Params (GTSAM default 10)")
    isam2.add_argument("--reference", action="store_true", help="add lm_cost, lm_s and ate_vs_lm_m (untimed)")
    isam2.add_argument("--output", help="write the final estimate here (g2o)")

    versus = commands.add_parser("vs-isam2", help="egnc-solve --online against ISAM2, as whole processes")
    versus.add_argument("--datasets", default="manhattanOlson3500,sphere2500,city10000")
    versus.add_argument("--percent", type=float, default=30.0)
    versus.add_argument("--seed", type=int, default=1)
    versus.add_argument("--repeats", type=int, default=1, help="A, B pairs per dataset")
    versus.add_argument("--relinearize-skips", default="10", help="ISAM2 variants, e.g. 10,1 (GTSAM's default is 10)")
    versus.add_argument("--region-hops", type=int, help="egnc-solve --region-hops (default: egnc-solve's own)")
    versus.add_argument("--boundary-share", type=float, help="egnc-solve --boundary-share (default: its own)")
    versus.add_argument("--decide-at-arrival", action="store_true", help="egnc-solve --decide-at-arrival")
    versus.add_argument("--egnc-timeout", type=float, default=1200.0, help="seconds before egnc's child is killed")
    versus.add_argument("--isam2-timeout", type=float, default=600.0, help="seconds before ISAM2's child is killed")
    versus.add_argument("--json", type=Path, help="append one JSON line per child run here")
    return top


def main(argv: list[str] | None = None) -> int:
    """Parse the command line and run the chosen command."""
    top = parser()
    args = top.parse_args(with_default_command(sys.argv[1:] if argv is None else argv, COMMANDS, "replay"))
    if args.command == "isam2":
        from _lib import isam2_replay

        threshold, skip = args.relinearize_threshold, args.relinearize_skip
        return isam2_replay.report(args.file, threshold, skip, args.reference, args.output)
    if args.command == "gnss":
        from _lib import online_gnss

        return online_gnss.report(args)
    if args.command == "vs-isam2":
        from _lib import online_vs_isam2

        return online_vs_isam2.report(args)
    if args.repeats < 1:
        top.error("--repeats must be at least 1")
    from _lib import online_replay

    return online_replay.report(args)


if __name__ == "__main__":
    sys.exit(main())
