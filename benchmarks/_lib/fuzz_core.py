"""What every fuzz target shares: the time limit that turns a hang into an outcome, and the tables.

Each target (`fuzz_files`, `fuzz_options`, `fuzz_api`, `fuzz_checkpoints`) runs seeded cases,
classifies each one and reports the classes with `counts_table` or `outcomes_table`; the entry
`benchmarks/fuzz.py` runs them.
"""

from __future__ import annotations

import collections
import contextlib
import signal
from collections.abc import Iterable, Iterator, Sequence

TIME_LIMIT_S = 60.0
"""A case taking longer is a hang: the cases are graphs of at most 30 poses."""


class Hang(BaseException):
    """A case ran past its time limit (a `BaseException`, so no `except Exception` in egnc swallows it)."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise `Hang` in the block once `seconds` of wall time have passed (SIGALRM; main thread only)."""

    def expire(signum: int, frame: object) -> None:
        raise Hang

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def outcomes_table(cases: Iterable[tuple[str, str]], classes: Sequence[str], counted: str, first: str) -> str:
    """Markdown from `(row, outcome)` pairs: per row (and `**all**`), the cases (`counted` heads
    their column) by outcome class (`classes`); `first` heads the row names."""
    rows: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for name, outcome in cases:
        for row in (name, "**all**"):
            rows[row][counted] += 1
            rows[row][outcome] += 1
    return counts_table(rows, [counted, *classes], first)


def counts_table(rows: dict[str, collections.Counter], columns: list[str], first: str = "kind") -> str:
    """Markdown table of per-row class counts (`first` heads the row names), rows sorted, `**all**` last."""
    lines = [f"| {first} | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for name in [*sorted(set(rows) - {"**all**"}), "**all**"]:
        lines.append(f"| {name} | " + " | ".join(str(rows[name][c]) for c in columns) + " |")
    return "\n".join(lines)
