"""Command-line plumbing the entry scripts share: a default command, and the command echoed above a table."""

from __future__ import annotations

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
