"""Atomic file output: a file egnc writes is either complete or not there at all.

Each file is written to a temporary `.NAME.<pid>.<hex>.tmp` beside it, flushed to disk and renamed
over `NAME`. Inside `all_or_nothing()`, the renames wait until every file of the block is written,
so a failure anywhere leaves all previous files untouched. A run killed before its rename
(SIGKILL, power loss) leaves its temporary behind; the next write to the same place removes the
temporaries of processes that no longer exist.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
import secrets
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO, TextIO

from egnc.errors import EgncError

_pending: contextvars.ContextVar[list[tuple[Path, Path]] | None] = contextvars.ContextVar("_pending", default=None)
"""`(temporary, path)` renames deferred by the innermost `all_or_nothing` block, or None outside one."""


def atomic_text_file(path: Path) -> contextlib.AbstractContextManager[TextIO]:
    """Yield a temporary UTF-8 text file beside `path` that replaces `path` only if the block succeeds.

    Raises:
        EgncError: the file cannot be created or written (names `path` and the reason).
    """
    return _atomic_file(path, "w", encoding="utf-8", newline="\n")


def atomic_binary_file(path: Path) -> contextlib.AbstractContextManager[BinaryIO]:
    """Like `atomic_text_file`, for bytes (e.g. a PNG from `egnc.plot.save_figure`)."""
    return _atomic_file(path, "wb")


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield the path of a new empty temporary beside `path`, for a writer that opens files itself
    (Rerun's file sink); it replaces `path` only if the block succeeds (deferred inside `all_or_nothing`).

    The writer must have closed the temporary when the block ends; it is then flushed to disk and renamed.

    Raises:
        EgncError: the temporary cannot be created, or cannot be flushed when the block ends.
    """
    with _temporary(path) as (temporary, descriptor):
        os.close(descriptor)
        yield temporary
        with open(temporary, "rb") as written:
            os.fsync(written.fileno())


@contextlib.contextmanager
def all_or_nothing() -> Iterator[None]:
    """Defer the renames of every atomic file written in the block until the block succeeds.

    On success all files appear (renamed with SIGINT and SIGTERM ignored, so an interruption
    cannot stop half-way); on any exception before that, interruptions included,
    every temporary is removed and no file is replaced.
    """
    renames: list[tuple[Path, Path]] = []
    token = _pending.set(renames)
    try:
        yield
        with _signals_held():
            for temporary, path in renames:
                _replace(temporary, path)
    except BaseException:
        for temporary, _ in renames:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(temporary)
        raise
    finally:
        _pending.reset(token)


def check_writable(path: Path) -> None:
    """Raise unless a file can be created or replaced at `path`: checked before a long solve or
    replay, so that a wrong path fails at once, not when the file is written.

    Raises:
        EgncError: `path` is a directory, or its directory does not exist or is not writable.
    """
    directory = path.parent
    if path.is_dir():
        problem = "is a directory"
    elif not directory.is_dir():
        problem = f"directory {directory} does not exist"
    elif not os.access(directory, os.W_OK | os.X_OK):
        problem = f"directory {directory} is not writable"
    else:
        return
    raise EgncError(f"{path}: cannot write file: {problem}")


def remove_stale_temporaries(path: Path) -> list[Path]:
    """Remove the temporaries of `path` left by processes that are no longer running.

    Returns:
        The removed files.
    """
    pattern = re.compile(rf"\.{re.escape(path.name)}\.(\d+)\.[0-9a-f]+\.tmp")
    removed = []
    with contextlib.suppress(OSError), os.scandir(path.parent) as entries:
        for entry in entries:
            match = pattern.fullmatch(entry.name)
            if match and not _process_exists(int(match.group(1))):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed.append(Path(entry.path))
    return removed


def _process_exists(pid: int) -> bool:
    """Whether a process with this id is running (signal 0 checks without sending anything)."""
    try:
        os.kill(pid, 0)
    except PermissionError:  # another user's process
        return True
    except (ProcessLookupError, OverflowError):
        return False
    return True


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Ignore SIGINT and SIGTERM during the block.

    The block is a few renames: once they start, finishing them (and the run) is the only way to
    leave no mix of old and new files, so an interruption in those milliseconds is not acted on.
    Python handlers are replaced rather than the signals masked, because a masked signal is still
    delivered to another thread (NumPy's BLAS workers), and only the main thread can do that; in
    other threads the block runs unprotected.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.signal(number, signal.SIG_IGN) for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for number, handler in previous.items():
            if handler is not None:  # None: installed from C, cannot be restored from Python
                signal.signal(number, handler)


def _replace(temporary: Path, path: Path) -> None:
    """Rename the finished temporary over `path`."""
    try:
        os.replace(temporary, path)
    except OSError as error:
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None


@contextlib.contextmanager
def _atomic_file(path: Path, mode: str, encoding: str | None = None, newline: str | None = None) -> Iterator:
    """The file objects' implementation: a temporary file beside `path` (`_temporary`), fsync, then rename."""
    with _temporary(path) as (_, descriptor):
        with os.fdopen(descriptor, mode, encoding=encoding, newline=newline) as out:
            yield out
            out.flush()
            os.fsync(out.fileno())


@contextlib.contextmanager
def _temporary(path: Path) -> Iterator[tuple[Path, int]]:
    """The one implementation: a new temporary beside `path` and its open descriptor (opened for
    writing), then `os.replace` over `path` (now or deferred) if the block succeeds, else removed."""
    remove_stale_temporaries(path)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        # os.open with mode 0o666 lets the umask decide permissions, as for a plain open().
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as error:
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None
    try:
        yield temporary, descriptor
        renames = _pending.get()
        if renames is None:
            _replace(temporary, path)
        else:
            renames.append((temporary, path))
    except OSError as error:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
