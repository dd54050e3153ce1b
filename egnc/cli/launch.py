"""The console-script entry points: a Ctrl-C while NumPy and SciPy load exits quietly with 130.

The scripts pip generates run `from <module> import <function>` before any egnc code: were that
module `egnc.cli.solve`, its imports (a few tenths of a second) would run outside `main`'s
handlers and a Ctrl-C there would print a `KeyboardInterrupt` traceback. This module imports
only the standard library and `egnc.cli.signals` (`import egnc` loads nothing heavy), and
imports each command inside the handler.
"""

from __future__ import annotations

import importlib
import sys

from egnc.cli.signals import INTERRUPT_EXIT_CODES


def solve() -> int:
    """`egnc-solve` (`egnc.cli.solve.main`)."""
    return _run("egnc.cli.solve", "egnc-solve")


def corrupt() -> int:
    """`egnc-corrupt` (`egnc.cli.corrupt.main`)."""
    return _run("egnc.cli.corrupt", "egnc-corrupt")


def bench() -> int:
    """`egnc-bench` (`egnc.cli.bench.main`)."""
    return _run("egnc.cli.bench", "egnc-bench")


def _run(module: str, program: str) -> int:
    """Import `module` and return its `main()`, turning a Ctrl-C that escapes it into one line and 130."""
    try:
        return importlib.import_module(module).main()
    except KeyboardInterrupt:
        code, what = INTERRUPT_EXIT_CODES[KeyboardInterrupt]
        print(f"{program}: {what}; no output written", file=sys.stderr)
        return code
