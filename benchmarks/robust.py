"""The default robust decision on shared files: never worse than least squares, whatever the guess.

    python benchmarks/robust.py clean [--data-dir DIR] [--files MIT,csail,...] [--gtsam-chordal]
    python benchmarks/robust.py drifted [--data-dir DIR] [--files ...] [--drifted ...] [--heading 0.1,0.3]
        [--scaled 10] [--seeds 1,2] [--extra FILE.g2o,...] [--time-limit 300] [--no-gtsam]
    python benchmarks/robust.py gnc [--loss gm|tls] [--time-limit 600] [FILE ...]
    python benchmarks/robust.py gtsam-bridge [--data-dir DIR] [--files MIT,...] [--percent 0,30]
        [--no-files] [--no-robots]
    python benchmarks/robust.py gnss [--files manhattanOlson3500,...] [--loops 0,10,30] [--priors 0,10,20]
        [--every 10] [--sigma 2] [--seed 1] [--guess file|heading:0.3|scaled:10]
        [--gtsam-time-limit 900] [--no-gtsam]

- `clean` (`_lib/robust_clean.py`): files without false loops, the default `egnc.solve` against
  `l2`: loops rejected, ATE to the `l2` optimum, both costs, warnings and times.
- `drifted` (`_lib/robust_drifted.py`): the same files from their own guess and from guesses
  re-chained from odometry with seeded drift; egnc, egnc from its guess only, GTSAM's GNC-TLS and
  LM, each a child process under a time limit: loops rejected and cost over the optimum.
- `gnss` (`_lib/robust_gnss.py`): GNSS-like position priors with multipath jumps (single and in
  bursts) and false loops; egnc and GTSAM's GNC-TLS: precision and recall for loops and priors
  apart, ATE without alignment, time against the clean solve.
- `gnc` (`_lib/gtsam_gnc.py`): GTSAM's `GncLMOptimizer` on g2o files, each in a child killed at the
  limit: status, final error, loops with weight < 0.5.
- `gtsam-bridge` (`_lib/gtsam_bridge.py`): `egnc.from_gtsam` on every shared file (cost equal to
  GTSAM's, rejected sets equal to the g2o path's, conversion time against the solve) and
  graphs cut in robots, from GTSAM objects (M3500 in two and in three, sphere2500 in two; random
  and consistent false inter-robot loops).

The corrupted grid (false loop closures, precision and recall, riSAM and GTSAM side by side) is
`egnc-bench`; the time robustness costs is `robust_speed.py`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from _lib.cli import add_gnss_case_arguments, command_echo
from _lib.paths import SHARED_DATASETS

CLEAN_FILES = (
    "MIT,csail,intel,kitti_00,manhattanOlson3500,city10000,sphere2500,parking-garage,smallGrid3D,tinyGrid3D,sphere_a"
)
DRIFTED_FILES = (
    "MIT,csail,intel,kitti_00,manhattanOlson3500,city10000,sphere2500,sphere_a,parking-garage,cubicle,smallGrid3D,"
    "tinyGrid3D"
)


def parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per question (module docstring)."""
    top = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = top.add_subparsers(dest="command", required=True)

    clean = commands.add_parser("clean", help="clean files: the default against least squares")
    clean.add_argument("--data-dir", type=Path, default=SHARED_DATASETS)
    clean.add_argument("--files", default=CLEAN_FILES, help="comma-separated dataset names (default: all but cubicle)")
    clean.add_argument("--gtsam-chordal", action="store_true", help="add GTSAM's LM-from-chordal cost for 3D files")

    drifted = commands.add_parser("drifted", help="clean graphs from drifted guesses, egnc and GTSAM")
    drifted.add_argument("--data-dir", type=Path, default=SHARED_DATASETS)
    drifted.add_argument("--files", default=DRIFTED_FILES, help="shared files solved from their own guess")
    drifted.add_argument(
        "--drifted",
        default="manhattanOlson3500,intel,sphere2500,grid3d",
        help="files (or grid3d) re-chained with drift",
    )
    drifted.add_argument("--heading", default="0.1,0.3", help="heading noise levels, rad per step")
    drifted.add_argument("--scaled", default="10", help="translation noise levels, times each step's sigma")
    drifted.add_argument("--seeds", default="1,2")
    drifted.add_argument("--extra", default="", help="comma-separated g2o files from elsewhere")
    drifted.add_argument("--time-limit", type=float, default=300.0)
    drifted.add_argument("--no-gtsam", action="store_true")

    gnc = commands.add_parser("gnc", help="GTSAM's GncLMOptimizer on g2o files, under a time limit")
    gnc.add_argument("files", nargs="*", help="g2o files or dataset names (default: the reference datasets)")
    gnc.add_argument("--loss", choices=("gm", "tls"), default="tls", help="GNC-GM or GNC-TLS (default tls)")
    gnc.add_argument("--time-limit", type=float, default=600.0, help="seconds per file")

    bridge = commands.add_parser("gtsam-bridge", help="egnc.from_gtsam on shared files and graphs cut in robots")
    bridge.add_argument("--data-dir", type=Path, default=SHARED_DATASETS)
    bridge.add_argument("--files", default=CLEAN_FILES, help="comma-separated dataset names (default: all but cubicle)")
    bridge.add_argument("--percent", default="0,30", help="false loops added to each file, in %% (0: as given)")
    bridge.add_argument("--no-files", action="store_true", help="only the robots table")
    bridge.add_argument("--no-robots", action="store_true", help="only the shared-file table")

    gnss = commands.add_parser("gnss", help="GNSS fixes with multipath outliers and false loops, egnc and GTSAM")
    add_gnss_case_arguments(gnss)
    gnss.add_argument(
        "--guess", default="file", help="'file', or drifted KIND:LEVEL (heading:0.3 rad a step, scaled:10 sigmas)"
    )
    gnss.add_argument("--gtsam-time-limit", type=float, default=900.0, help="seconds per GTSAM solve (a child)")
    gnss.add_argument("--no-gtsam", action="store_true")
    return top


def main(argv: list[str] | None = None) -> int:
    """Parse the command line and run the chosen command."""
    given = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(given)
    if args.command == "clean":
        from _lib import robust_clean

        return robust_clean.run(args.data_dir, args.files, args.gtsam_chordal)
    if args.command == "gnss":
        from _lib import robust_gnss

        print(command_echo(given))
        return robust_gnss.run(args)
    if args.command == "drifted":
        from _lib import robust_drifted

        return robust_drifted.run(args)
    if args.command == "gtsam-bridge":
        from _lib import gtsam_bridge

        return gtsam_bridge.run(
            args.data_dir, args.files, args.percent, not args.no_files, not args.no_robots, command_echo(given)
        )
    from _lib import gtsam_gnc

    return gtsam_gnc.report_gnc(args.files, args.loss, args.time_limit, command_echo(given))


if __name__ == "__main__":
    sys.exit(main())
