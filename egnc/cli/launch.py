"""The console-script entry points: a signal while NumPy and SciPy load exits quietly with 130 or 143.

The scripts pip generates run `from <module> import <function>` before any egnc code: were that
module `egnc.cli.solve`, its imports (a few tenths of a second) would run outside `main`'s
handlers and a Ctrl-C there would print a `KeyboardInterrupt` traceback, a SIGTERM end the run
without a word. So this module, run as a console script, first of all makes SIGINT and SIGTERM
exit with one line (`_quit`); it imports only the standard library and `egnc.cli.signals`
(`import egnc` loads nothing heavy), and each command inside `_run`'s handlers. What is left is
the interpreter's own start-up and `import egnc`, a few milliseconds before this module runs
(docs/cli.md, "Exit and termination codes").
"""

from __future__ import annotations

import signal
import sys
from types import FrameType

PROGRAMS = ("egnc-solve", "egnc-corrupt", "egnc-bench")


def _quit(signum: int, frame: FrameType | None) -> None:
    """Until `_run` takes over: one line and 128 + the signal number (`SystemExit` unwinds an import quietly)."""
    name = "interrupted (SIGINT)" if signum == signal.SIGINT else "terminated (SIGTERM)"
    print(f"{_program()}: {name}; no output written", file=sys.stderr)
    raise SystemExit(128 + signum)


def _program() -> str:
    """The console script's name, from `sys.argv[0]` (`egnc` when run otherwise)."""
    name = sys.argv[0].replace("\\", "/").rsplit("/", 1)[-1] if sys.argv else ""
    return name if name in PROGRAMS else "egnc"


if _program() in PROGRAMS:  # a console script, not an import into someone's process
    signal.signal(signal.SIGINT, _quit)
    signal.signal(signal.SIGTERM, _quit)

import importlib  # noqa: E402 - after the handlers: they cover every import but the interpreter's own

from egnc.cli.signals import INTERRUPT_EXIT_CODES, Terminated  # noqa: E402


def solve() -> int:
    """`egnc-solve` (`egnc.cli.solve.main`)."""
    return _run("egnc.cli.solve", "egnc-solve")


def corrupt() -> int:
    """`egnc-corrupt` (`egnc.cli.corrupt.main`)."""
    return _run("egnc.cli.corrupt", "egnc-corrupt")


def bench() -> int:
    """`egnc-bench` (`egnc.cli.bench.main`)."""
    return _run("egnc.cli.bench", "egnc-bench")


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated


def _run(module: str, program: str) -> int:
    """Import `module` and return its `main()`; a SIGINT or SIGTERM escaping it is one line and 130 / 143."""
    previous = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    try:
        # From here the signals raise, so that `main` unwinds (removing its temporaries) and says so itself.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, _raise_terminated)
        return importlib.import_module(module).main()
    except (KeyboardInterrupt, Terminated) as interruption:
        code, what = INTERRUPT_EXIT_CODES[type(interruption)]
        print(f"{program}: {what}; no output written", file=sys.stderr)
        return code
    finally:
        signal.signal(signal.SIGINT, previous[0])
        signal.signal(signal.SIGTERM, previous[1])
