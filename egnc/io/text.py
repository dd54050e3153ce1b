"""Reading a text file for the parsers, block by block: I/O and encoding failures become one-line errors.

The file is read in blocks of `BLOCK_SIZE` bytes, decoded as it comes, and refused as soon as a
line grows past `MAX_LINE_BYTES` (`egnc-solve /dev/zero` used to read 19 GB before the kernel
killed it) or a byte is not UTF-8 (`/dev/urandom`). Between blocks the interpreter runs signal
handlers, so SIGINT and SIGTERM end a long read at once (one large `read` ran in C to the end). A
UTF-8 byte-order mark at the start (some Windows editors write one) is skipped.
"""

from __future__ import annotations

import codecs
from pathlib import Path

from egnc.errors import G2oFormatError

BLOCK_SIZE = 1 << 20
"""Bytes per read (1 MiB): large enough to keep the reading fast, small enough to react to signals."""

MAX_LINE_BYTES = 1 << 20
"""Longest line accepted, in bytes (1 MiB). A g2o or IRL record takes under 2 kB (an `EDGE_SE3:QUAT`
line of 30 doubles, or a 3D IRL `LOOP` of 42); a line a thousand times longer is not a pose graph."""


def read_text(path: Path) -> str:
    """The file's UTF-8 text, without a leading byte-order mark.

    Raises:
        G2oFormatError: the file cannot be read, holds an invalid UTF-8 byte, or a line longer
            than `MAX_LINE_BYTES` (each names the line).
    """
    decoder = codecs.getincrementaldecoder("utf-8-sig")()
    parts: list[str] = []
    line = 1  # the line the next block starts in
    line_bytes = 0  # bytes of that line before the block
    try:
        with path.open("rb") as file:
            while block := file.read(BLOCK_SIZE):
                try:
                    parts.append(decoder.decode(block))
                except UnicodeDecodeError as error:
                    raise _not_utf8(path, line + error.object.count(b"\n", 0, error.start)) from None
                newlines = block.count(b"\n")
                line_bytes = len(block) - 1 - block.rfind(b"\n") if newlines else line_bytes + len(block)
                line += newlines
                if line_bytes > MAX_LINE_BYTES:
                    raise G2oFormatError(
                        f"line longer than {MAX_LINE_BYTES} bytes without a newline: not a pose-graph file", path, line
                    )
            try:
                parts.append(decoder.decode(b"", final=True))
            except UnicodeDecodeError:  # a multi-byte character cut by the end of the file
                raise _not_utf8(path, line) from None
    except OSError as error:
        raise G2oFormatError(f"cannot read file: {error.strerror or error}", path) from None
    return "".join(parts)


def _not_utf8(path: Path, line: int) -> G2oFormatError:
    return G2oFormatError("not a text file (invalid UTF-8 byte)", path, line)
