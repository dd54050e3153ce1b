"""Exception hierarchy: every error egnc raises on purpose is an `EgncError`.

The CLI turns any `EgncError` into a one-line message and exit code 1, so each message must
stand alone on one line and name what the user has to fix (file and line where there is one).
"""

from __future__ import annotations

from pathlib import Path


class EgncError(Exception):
    """Base class of all errors raised deliberately by egnc."""


class G2oFormatError(EgncError):
    """A pose-graph file could not be read: names the file and, where known, the 1-based line."""

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        super().__init__(f"{where}{message}")


class GraphError(EgncError):
    """The pose graph is well formed but cannot be solved as given (e.g. disconnected)."""


class SolverError(EgncError):
    """The solver could not proceed (e.g. the linear system is singular)."""


class NumericalError(SolverError):
    """The problem cannot be represented in double precision, or the solve produced non-finite numbers."""


class OptionError(EgncError, ValueError):
    """An option field or a function argument has a value out of its range; the message names it."""


class OptionTypeError(OptionError, TypeError):
    """An option field or a function argument has the wrong type; the message names it."""


class EgncWarning(UserWarning):
    """Something the user should know about an input egnc accepted (repaired, skipped or held fixed).

    Raised with `warnings.warn`, so library code never prints; `egnc-solve` shows each one as a
    `warning: ...` line on stderr and lists them in its JSON report.
    """


class UnsupportedFactorError(EgncError):
    """A factor of another library's graph has no counterpart in egnc: names its index and type."""

    def __init__(self, index: int, type_name: str, reason: str):
        self.index = index
        self.type_name = type_name
        super().__init__(f"factor {index} ({type_name}): {reason}")
