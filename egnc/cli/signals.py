"""SIGINT and SIGTERM as exceptions, so an interrupted `egnc-solve` unwinds: temporaries removed, one line, exit code.

Python already raises `KeyboardInterrupt` on SIGINT; SIGTERM (sent by `kill`, `timeout`, job
schedulers) would end the process at once and leave temporaries behind, so it raises `Terminated`.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from types import FrameType


class Terminated(BaseException):
    """SIGTERM arrived (a `BaseException`, like `KeyboardInterrupt`, so no `except Exception` swallows it)."""


INTERRUPT_EXIT_CODES: dict[type[BaseException], tuple[int, str]] = {
    KeyboardInterrupt: (128 + signal.SIGINT, "interrupted (SIGINT)"),
    Terminated: (128 + signal.SIGTERM, "terminated (SIGTERM)"),
}
"""Exit code (128 + signal number, the shell convention: 130 and 143) and message per interruption."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises `Terminated` in the main thread."""

    def raise_terminated(signum: int, frame: FrameType | None) -> None:
        raise Terminated

    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
