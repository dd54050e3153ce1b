"""The console scripts exit quietly with 130 on a Ctrl-C while NumPy and SciPy load (issue 19).

A Ctrl-C is simulated at the exact moment NumPy is imported; a real one sent at a chosen delay
would make the test depend on the machine's load. (In the interpreter's own start-up, the first
few tens of milliseconds before any egnc code runs, Python still prints its own traceback.)
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

GRID2D = Path(__file__).parents[1] / "datasets" / "grid2d.g2o"

# A Ctrl-C delivered exactly while `egnc.cli.solve` (and with it NumPy and SciPy) is imported.
INTERRUPTED_IMPORT = textwrap.dedent(
    """
    import sys

    class CtrlC:
        def find_spec(self, name, path=None, target=None):
            if name == "numpy":
                raise KeyboardInterrupt
            return None

    sys.meta_path.insert(0, CtrlC())
    from egnc.cli.launch import solve
    sys.exit(solve())
    """
)


def test_import_egnc_loads_neither_numpy_nor_scipy():
    script = "import sys, egnc, egnc.cli.launch; print(sorted({'numpy', 'scipy'} & set(sys.modules)))"
    run = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.stdout.strip() == "[]", run.stderr


def test_ctrl_c_during_the_imports_is_one_line_and_130():
    run = subprocess.run(
        [sys.executable, "-c", INTERRUPTED_IMPORT, str(GRID2D)], capture_output=True, text=True, timeout=60
    )
    assert (run.returncode, run.stderr) == (130, "egnc-solve: interrupted (SIGINT); no output written\n")


# A real signal, sent by the process to itself at the moment a module is first imported, as
# `egnc-solve` (so `sys.argv[0]` names the console script).
SIGNAL_DURING_IMPORT = textwrap.dedent(
    """
    import os, signal, sys

    signum, module = getattr(signal, sys.argv[1]), sys.argv[2]

    class Signal:
        def find_spec(self, name, path=None, target=None):
            if name == module:
                os.kill(os.getpid(), signum)
            return None

    sys.meta_path.insert(0, Signal())
    sys.argv = ["/usr/local/bin/egnc-solve", *sys.argv[3:]]
    from egnc.cli.launch import solve
    sys.exit(solve())
    """
)


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("module", ["egnc.cli.signals", "numpy"])
def test_a_signal_while_the_console_script_starts_is_one_line(signum, module):
    """Issue 56: a SIGINT while `egnc.cli.launch` itself was imported printed a traceback, and a
    SIGTERM before `main` ran ended the run without a word."""
    run = subprocess.run(
        [sys.executable, "-c", SIGNAL_DURING_IMPORT, signum, module, str(GRID2D)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    word = "interrupted" if signum == "SIGINT" else "terminated"
    expected = (128 + getattr(signal, signum), f"egnc-solve: {word} ({signum}); no output written\n")
    assert (run.returncode, run.stderr) == expected


def test_importing_the_launcher_leaves_the_signal_handlers_alone():
    script = "import signal, egnc.cli.launch; print(signal.getsignal(signal.SIGTERM) == signal.SIG_DFL)"
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert run.stdout.strip() == "True", run.stderr
