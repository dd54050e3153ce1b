"""Command-line plumbing the entry scripts share: a default command, and the command echoed above a table."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path


def with_default_command(argv: Sequence[str], commands: Iterable[str], default: str) -> list[str]:
    """`argv` with `default` put first unless `argv` starts with a command's name or asks for help.

    So `python benchmarks/least_squares.py --files csail` means `least_squares.py compare --files csail`.
    """
    argv = list(argv)
    if argv and (argv[0] in set(commands) or argv[0] in ("-h", "--help")):
        return argv
    return [default, *argv]


def command_echo(argv: Sequence[str] | None = None) -> str:
    """The command that is running, as `python benchmarks/NAME.py ARGS` (the line above a printed table)."""
    arguments = sys.argv[1:] if argv is None else argv
    return " ".join(["python", f"benchmarks/{Path(sys.argv[0]).name}", *arguments])


def add_gnss_case_arguments(parser: argparse.ArgumentParser) -> None:
    """The GNSS case grid's options, shared by `robust.py gnss` and `online.py gnss`: files,
    false-loop and multipath shares (percent), a fix every K poses, its noise (metres), the seed."""
    parser.add_argument("--files", default="manhattanOlson3500,sphere2500,city10000")
    parser.add_argument("--loops", default="0,10,30", help="false-loop shares, percent")
    parser.add_argument("--priors", default="0,10,20", help="multipath shares of the fixes, percent")
    parser.add_argument("--every", type=int, default=10, help="a fix every K poses")
    parser.add_argument("--sigma", type=float, default=2.0, help="fix noise per coordinate, metres")
    parser.add_argument("--seed", type=int, default=1)
