"""Progress of a solve on stderr: a live line on a terminal, one line per stage otherwise.

An online replay reports per update instead (`StepProgress`).

`egnc.solve` reports through two callbacks: `on_iteration(iterations, cost)` after every accepted
solver step and `on_stage(StageReport)` when a stage ends. On a terminal the iteration line is
rewritten in place (carriage return), at most `REFRESH_S` apart, and each finished stage leaves
one line; in a log (not a terminal) only the stage lines are written. Every line carries the
time since the solve started, so a long stage is visibly alive.
"""

from __future__ import annotations

import math
import time
from typing import TextIO

from egnc.online import UpdateReport
from egnc.robust.gnc import StageReport

REFRESH_S = 0.1
"""Shortest interval between two rewrites of the live line, seconds."""


class _ProgressLine:
    """What both progress writers keep: the stream, whether it is a terminal, the clock and its start.

    Args:
        stream: where to write (stderr); a terminal gets the live line.
        clock: seconds, monotonic (replaceable in tests).
    """

    def __init__(self, stream: TextIO, clock=time.monotonic):
        self._stream = stream
        self._clock = clock
        self._live = stream.isatty()
        self._started = clock()
        self._last_refresh = -math.inf


class Progress(_ProgressLine):
    """The `on_stage` and `on_iteration` callbacks of one solve, writing to `stream` (`_ProgressLine`)."""

    def __init__(self, stream: TextIO, clock=time.monotonic):
        super().__init__(stream, clock)
        self._stage = 1
        self._line_open = False

    def on_iteration(self, iterations: int, cost: float) -> None:
        """Rewrite the live line (terminal only, throttled)."""
        now = self._clock()
        if not self._live or now - self._last_refresh < REFRESH_S:
            return
        self._last_refresh = now
        self._stream.write(
            f"\rstage {self._stage}: iteration {iterations}, cost {cost:.6g}, {now - self._started:.1f} s\x1b[K"
        )
        self._stream.flush()
        self._line_open = True

    def on_stage(self, stage: StageReport) -> None:
        """Write the finished stage's line (over the live line on a terminal)."""
        if stage.kind == "probe":
            mu = "chordal start, least squares probe"
        elif math.isnan(stage.mu_mean):
            mu = "least squares" + (f" ({stage.start} start)" if stage.start != "guess" else "")
        else:
            mu = f"mu {stage.mu_min:.3g}..{stage.mu_max:.3g}"
        limit = " (iteration limit)" if stage.status == 0 and stage.kind != "probe" else ""
        prefix = "\r" if self._line_open else ""
        self._stream.write(
            f"{prefix}stage {self._stage}: {mu}, {stage.iterations} iterations{limit}, cost {stage.cost:.6g},"
            f" {stage.active_edges} edges, {stage.time_s:.2f} s (elapsed {self._clock() - self._started:.1f} s)"
            + ("\x1b[K\n" if self._live else "\n")
        )
        self._stream.flush()
        self._stage += 1
        self._line_open = False
        self._last_refresh = -math.inf


class StepProgress(_ProgressLine):
    """The `on_step` callback of an online replay (`egnc.online.replay`), writing to `stream`.

    On a terminal one live line, rewritten at most `REFRESH_S` apart; in a log one line per tenth
    of the steps. Each line: steps done of all, poses and loop closures so far, loops rejected
    right now, the slowest update so far, and the elapsed time.

    Args: as `_ProgressLine`.
    """

    def __init__(self, stream: TextIO, clock=time.monotonic):
        super().__init__(stream, clock)
        self._slowest_ms = 0.0
        self._loops = 0

    def on_step(self, step: int, total: int, report: UpdateReport) -> None:
        """Report one finished update."""
        self._slowest_ms = max(self._slowest_ms, 1e3 * report.time_s)
        self._loops += len(report.new_loops)
        now = self._clock()
        last = step == total
        if self._live:
            if not last and now - self._last_refresh < REFRESH_S:
                return
        elif not (last or step % max(1, total // 10) == 0):
            return
        self._last_refresh = now
        line = (
            f"step {step}/{total}: {self._loops} loop closures, {report.iterations} iterations in the last update,"
            f" slowest update {self._slowest_ms:.1f} ms (elapsed {now - self._started:.1f} s)"
        )
        if self._live:
            self._stream.write(f"\r{line}\x1b[K" + ("\n" if last else ""))
        else:
            self._stream.write(line + "\n")
        self._stream.flush()
