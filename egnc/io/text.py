"""Reading a text file for the parsers: I/O and encoding failures become one-line errors."""

from __future__ import annotations

from pathlib import Path

from egnc.errors import G2oFormatError


def read_text(path: Path) -> str:
    """The file's UTF-8 text.

    Raises:
        G2oFormatError: the file cannot be read, or holds an invalid UTF-8 byte (names its line).
    """
    try:
        data = path.read_bytes()
    except OSError as error:
        raise G2oFormatError(f"cannot read file: {error.strerror or error}", path) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise G2oFormatError("not a text file (invalid UTF-8 byte)", path, line) from None
