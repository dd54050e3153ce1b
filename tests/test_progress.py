"""`egnc-solve`'s progress on stderr: a throttled live line on a terminal, stage lines in a log."""

from __future__ import annotations

import io
import math

from egnc.cli.progress import REFRESH_S, Progress
from egnc.robust.gnc import StageReport


class FakeStream(io.StringIO):
    def __init__(self, tty: bool):
        super().__init__()
        self._tty = tty

    def isatty(self) -> bool:
        return self._tty


def stage(status: int = 1) -> StageReport:
    return StageReport(0.0, 0.5, 1.0, iterations=7, cost=12.5, time_s=0.3, status=status, active_edges=40)


def test_terminal_gets_a_throttled_live_line_then_the_stage_line():
    now = [0.0]
    stream = FakeStream(tty=True)
    progress = Progress(stream, clock=lambda: now[0])
    for k in range(1, 6):  # five steps within one refresh interval: one rewrite
        now[0] += REFRESH_S / 10
        progress.on_iteration(k, 100.0 / k)
    assert stream.getvalue().count("\r") == 1 and "iteration 1," in stream.getvalue()
    now[0] += REFRESH_S
    progress.on_iteration(6, 1.0)
    assert "iteration 6, cost 1," in stream.getvalue()
    progress.on_stage(stage(status=0))
    last = stream.getvalue().split("\r")[-1]
    assert last.startswith("stage 1: mu 0..1, 7 iterations (iteration limit), cost 12.5, 40 edges")
    assert last.endswith("\n") and "elapsed" in last


def test_a_log_gets_one_line_per_stage_and_no_carriage_returns():
    stream = FakeStream(tty=False)
    progress = Progress(stream)
    for k in range(100):
        progress.on_iteration(k, 1.0)
    progress.on_stage(stage())
    progress.on_stage(StageReport(math.nan, math.nan, math.nan, 3, 1.0, 0.1, 1, 40))
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and "\r" not in stream.getvalue()
    assert lines[1].startswith("stage 2: least squares, 3 iterations, cost 1")
