"""Every record of a plain text file at once: each line's tag and the numbers after it.

A plain file (printable ASCII, fields separated by spaces and tabs, no comment and no CR; the
caller checks that) holds one record a line: a tag, then numbers. Read line by line, Python
makes a list of strings for every line, and on a large map that is most of the reading
(BENCHMARKS.md, "Reading a large g2o file"). Here the text is read as bytes once: where each
field starts and ends and on which line, which field heads its line, and every other field
converted by one NumPy call (`np.fromstring`, whose text conversion gives the same float64 as
Python's `float`).

The numbers must be plain by `egnc.io.numbers`' grammar: made of `0-9 . e E + -`, none starting
with `+`, and each a whole number (a field the conversion reads only in part, such as `1e` or
`1.2.3`, leaves the count of numbers short). Anything else (a field of other characters, an
unknown tag) returns None: the caller's line loop then finds the first bad line and its message.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

_SPACE, _TAB, _NEWLINE, _PLUS, _MINUS = (ord(character) for character in " \t\n+-")
_NUMBER_OR_SEPARATOR = np.zeros(256, dtype=bool)
_NUMBER_OR_SEPARATOR[np.frombuffer(b"0123456789.eE+- \t\n", dtype=np.uint8)] = True
_DIGITS = np.zeros(256, dtype=bool)
_DIGITS[np.frombuffer(b"0123456789", dtype=np.uint8)] = True
EXACT_INTEGER_DIGITS = 15
"""Most digits of an integer field `PlainRecords.integers` converts: every such value is exact as a float64."""


@dataclass(frozen=True, eq=False)
class PlainRecords:
    """The records of a plain file, in file order (`plain_records`).

    Attributes:
        lines: `(R,)` 1-based line number of each record (each non-empty line).
        tags: `(R,)` index of each record's tag in the caller's `tags`.
        counts: `(R,)` fields after each record's tag.
    """

    lines: np.ndarray
    tags: np.ndarray
    counts: np.ndarray
    _first: np.ndarray  # (R,) index in _values of each record's first field after the tag
    _values: np.ndarray  # (F,) float64, every field after a tag
    _data: np.ndarray  # the text's bytes (padded, `_windows`), and where each of those F fields starts and ends
    _starts: np.ndarray
    _ends: np.ndarray

    def floats(self, records: np.ndarray, start: int, count: int) -> np.ndarray:
        """`(K, count)` float64, fields `start .. start + count - 1` (0 is the first after the tag) of
        the records `records` `(K,)`, each of which has that many."""
        return self._values[self._first[records, None] + start + np.arange(count)]

    def integers(self, records: np.ndarray, count: int) -> np.ndarray | None:
        """`(K, count)` int64, the first `count` fields of the records `records` `(K,)`, or None
        where one is not an optional `-` and 1 to `EXACT_INTEGER_DIGITS` digits (longer
        integers are left to the caller's own parser)."""
        fields = self._first[records, None] + np.arange(count)
        starts, ends = self._starts[fields], self._ends[fields]
        signed = self._data[starts] == _MINUS
        digits = ends - starts - signed
        if np.any(digits < 1) or np.any(digits > EXACT_INTEGER_DIGITS):
            return None
        window = _windows(self._data, EXACT_INTEGER_DIGITS, (starts + signed).ravel()).reshape(*fields.shape, -1)
        if np.any((np.arange(EXACT_INTEGER_DIGITS) < digits[..., None]) & ~_DIGITS[window]):
            return None
        return self._values[fields].astype(np.int64)


def plain_records(text: str, tags: Sequence[str]) -> PlainRecords | None:
    """Read the records of the plain `text` (module docstring) at once.

    Args:
        text: the whole file, printable ASCII with tabs and newlines only.
        tags: the record tags to recognise.

    Returns:
        The records, or None where a line's first field is not one of `tags`, a later field is
        not a plain number, or the text holds no record.
    """
    padding = max(EXACT_INTEGER_DIGITS, *map(len, tags))  # every window of `_windows` ends inside `data`
    data = np.frombuffer(text.encode("ascii") + b" " * padding, dtype=np.uint8)
    separator = (data == _SPACE) | (data == _TAB) | (data == _NEWLINE)
    change = np.diff(separator.view(np.int8), prepend=np.int8(1), append=np.int8(1))
    starts, ends = np.flatnonzero(change == -1), np.flatnonzero(change == 1)  # of every field
    if not len(starts):
        return None
    line = np.searchsorted(np.flatnonzero(data == _NEWLINE), starts)  # 0-based line of each field
    heads = np.flatnonzero(np.diff(line, prepend=-1) != 0)  # each line's first field: its tag
    tag = _tag_indices(data, starts[heads], ends[heads], tags)
    if tag is None:
        return None
    in_tag = np.zeros(len(data) + 1, dtype=np.int8)
    in_tag[starts[heads]], in_tag[ends[heads]] = 1, -1
    numbers_only = data.copy()
    numbers_only[np.cumsum(in_tag[:-1], dtype=np.int8).view(bool)] = _SPACE
    number = np.ones(len(starts), dtype=bool)
    number[heads] = False
    if not np.all(_NUMBER_OR_SEPARATOR[numbers_only]) or np.any(data[starts[number]] == _PLUS):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NumPy warns (later: raises) where it stops short of the end
        try:
            values = np.fromstring(numbers_only.tobytes(), dtype=np.float64, sep=" ")
        except (DeprecationWarning, ValueError):
            return None
    if len(values) != np.count_nonzero(number):
        return None
    counts = np.diff(np.append(heads, len(starts))) - 1
    first = np.cumsum(counts) - counts
    return PlainRecords(line[heads] + 1, tag, counts, first, values, data, starts[number], ends[number])


def _tag_indices(data: np.ndarray, starts: np.ndarray, ends: np.ndarray, tags: Sequence[str]) -> np.ndarray | None:
    """`(R,)` index in `tags` of each field `data[starts:ends]`, or None where one is not a tag."""
    window = _windows(data, max(map(len, tags)), starts)
    lengths = ends - starts
    index = np.full(len(starts), -1)
    for k, name in enumerate(tags):
        spelled = np.frombuffer(name.encode("ascii"), dtype=np.uint8)
        index[(lengths == len(spelled)) & np.all(window[:, : len(spelled)] == spelled, axis=1)] = k
    return None if np.any(index < 0) else index


def _windows(data: np.ndarray, width: int, starts: np.ndarray) -> np.ndarray:
    """`(K, width)` the bytes `data[starts[k] : starts[k] + width]`; `data` ends in at least
    `width` spaces, so every window lies inside it."""
    return np.lib.stride_tricks.sliding_window_view(data, width)[starts]
