"""Atomic file output: a file egnc writes is either complete or not there at all."""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO, TextIO

from egnc.errors import EgncError


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
def _atomic_file(path: Path, mode: str, encoding: str | None = None, newline: str | None = None) -> Iterator:
    """The one implementation: temporary file beside `path`, fsync, `os.replace`, cleanup on failure."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        # os.open with mode 0o666 lets the umask decide permissions, as for a plain open().
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as error:
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None
    try:
        with os.fdopen(descriptor, mode, encoding=encoding, newline=newline) as out:
            yield out
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, path)
    except OSError as error:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise EgncError(f"{path}: cannot write file: {error.strerror or error}") from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
