"""One call in a forked child process, killed at its time limit.

Every benchmark run, and every reference solve, happens in a child forked from the process that
asks for it (the graph is inherited, not copied through a pipe). The child sends back
`("ok", value)` or a one-line error and exits; a child that does not answer within its time limit
is killed and reported as "timeout". The parent never solves anything itself, so no thread pool of
a numerical library is ever live in it at a fork.

`os.fork` is used directly rather than `multiprocessing.Process`, because a Dask worker is a
daemonic process and `multiprocessing` refuses to start children from one. A Dask worker also
runs threads of its own, and a lock one of them holds at the fork stays held in the child (Python
3.12 and later warn about forking such a process); the child only runs its call, which takes none
of Dask's locks, and leaves with `os._exit`.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from egnc.errors import EgncError

__all__ = ["Call", "Child", "Outcome", "run_in_child"]


@dataclass(frozen=True)
class Call:
    """A function call to run in a child process.

    Attributes:
        target: a module-level function (picklable by reference, for Dask).
        args: its positional arguments.
        time_limit_s: seconds the child may take before it is killed.
    """

    target: Callable[..., Any]
    args: tuple
    time_limit_s: float


@dataclass(frozen=True)
class Outcome:
    """How a `Call` ended.

    Attributes:
        status: "ok", "timeout" or "error: <one line>".
        value: the target's return value when "ok", else None.
        wall_s: seconds from the fork to the answer (or to the kill).
    """

    status: str
    value: Any = None
    wall_s: float = math.nan


class Child:
    """A `Call` running in a forked child; `connection` becomes readable when it answers or dies."""

    def __init__(self, call: Call):
        receiver, sender = multiprocessing.Pipe(duplex=False)
        _flush_std_streams()  # or the child would write the parent's buffered output again
        self.started = time.perf_counter()
        self.deadline = self.started + call.time_limit_s
        pid = os.fork()
        if pid == 0:  # the child: answer, then leave without running the parent's cleanup
            receiver.close()
            try:
                _answer(sender, call)
            finally:
                _flush_std_streams()
                os._exit(0)
        sender.close()  # so a child that dies without answering shows up as EOF
        self.pid = pid
        self.connection: Connection = receiver

    def finish(self) -> Outcome:
        """The child's answer if it sent one, else "timeout"; the child is gone afterwards."""
        status, value, died = "timeout", None, False
        try:
            if self.connection.poll(0):
                status, value = self.connection.recv()
        except EOFError:
            died = True
        exit_code = self.kill()
        if died:
            status = f"error: child process died (exit code {exit_code})"
        return Outcome(status, value, time.perf_counter() - self.started)

    def kill(self) -> int:
        """Kill the child unless it has exited, reap it, close the pipe; returns its exit code."""
        finished, wait_status = os.waitpid(self.pid, os.WNOHANG)
        if finished == 0:
            os.kill(self.pid, signal.SIGKILL)
            _, wait_status = os.waitpid(self.pid, 0)
        self.connection.close()
        return os.waitstatus_to_exitcode(wait_status)


def run_in_child(target: Callable[..., Any], args: tuple, time_limit_s: float) -> Outcome:
    """Run `target(*args)` in a forked child and wait for it, at most `time_limit_s` seconds."""
    child = Child(Call(target, args, time_limit_s))
    try:
        child.connection.poll(time_limit_s)
    except BaseException:  # interrupted while waiting: no child is left behind
        child.kill()
        raise
    return child.finish()


def _answer(connection: Connection, call: Call) -> None:
    """Body of the child: send `("ok", value)` or a one-line error, never raise across the fork."""
    try:
        connection.send(("ok", call.target(*call.args)))
    except BaseException as error:  # reported to the parent, whatever it was
        message = " ".join(str(error).split())  # one line
        if not isinstance(error, EgncError):
            message = f"{type(error).__name__}: {message}" if message else type(error).__name__
        connection.send((f"error: {message}", None))
    finally:
        connection.close()


def _flush_std_streams() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, ValueError, OSError):  # closed or replaced streams
            pass
