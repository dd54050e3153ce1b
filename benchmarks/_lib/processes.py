"""A benchmark's child process, timed whole: wall time, peak memory, and a kill at a time limit.

Running a job as its own process makes its peak resident memory its own (`ru_maxrss` from
`os.wait4`) and lets a job that runs too long be killed (with its process group) instead of
hanging the benchmark.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class ChildRun:
    """One finished (or killed) child process."""

    returncode: int
    timed_out: bool  # killed at the time limit
    wall_s: float  # from start to exit, seconds
    peak_mib: float  # peak resident memory (`ru_maxrss`), MiB
    stdout: str
    stderr: str

    @property
    def ok(self) -> bool:
        """Whether the child ran to the end and exited with 0."""
        return not self.timed_out and self.returncode == 0


def run_child(command: list[str], timeout_s: float | None = None, env: Mapping[str, str] | None = None) -> ChildRun:
    """Run `command` in its own session; kill its group at `timeout_s` seconds; time it and read its rusage."""
    with tempfile.TemporaryFile("w+") as stdout, tempfile.TemporaryFile("w+") as stderr:
        started = time.perf_counter()
        process = subprocess.Popen(command, stdout=stdout, stderr=stderr, start_new_session=True, env=env)
        killed = threading.Event()

        def kill() -> None:
            killed.set()
            os.killpg(process.pid, signal.SIGKILL)

        timer = threading.Timer(timeout_s, kill) if timeout_s is not None else None
        if timer is not None:
            timer.start()
        _, status, usage = os.wait4(process.pid, 0)
        wall_s = time.perf_counter() - started
        if timer is not None:
            timer.cancel()
        process.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        stdout.seek(0)
        stderr.seek(0)
        return ChildRun(
            returncode=process.returncode,
            timed_out=killed.is_set(),
            wall_s=wall_s,
            peak_mib=usage.ru_maxrss / 1024.0,  # kilobytes on Linux
            stdout=stdout.read(),
            stderr=stderr.read(),
        )
