"""The number grammar of the g2o and IRL readers, as one regular expression each for floats and ids.

Python's `float()` and `int()` accept more than a pose-graph file should hold: `1_0`, a leading
`+`, non-ASCII digits, surrounding Unicode whitespace. The readers accept exactly:

- a float: an optional `-`, ASCII digits with an optional decimal point (`1`, `1.`, `.5`,
  `1.5`), an optional exponent with an optional sign (`1e5`, `1E-05`, `1e+05`, as C++ streams
  write it), or `nan` / `inf` / `infinity` in any case with an optional `-` (C++ streams write
  these; the readers then reject them as not finite, with their own message);
- an integer (vertex id): an optional `-` and ASCII digits.

A leading `+` is refused: no g2o or IRL writer emits one, so it marks a hand-edited or corrupted
field. Lines are split on ASCII spaces and tabs only (`check_line_characters`).
"""

from __future__ import annotations

import re

import numpy as np

FLOAT = r"-?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|(?i:nan|inf|infinity))"
"""A float token, as a regular expression (no anchors)."""

INTEGER = r"-?[0-9]+"
"""A vertex-id token, as a regular expression (no anchors)."""

_FLOAT_RE = re.compile(FLOAT)
_INTEGER_RE = re.compile(INTEGER)
_NOT_PLAIN_FLOAT = re.compile(r"[^0-9.eE+\-,]")
_NOT_PLAIN_INTEGER = re.compile(r"[^0-9\-,]")
_INT64_MIN, _INT64_MAX = int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max)
_INT64_DIGITS = len(str(_INT64_MAX))
_SHOWN_CHARACTERS = 40
_FORBIDDEN_CHARACTER = re.compile(r"[^\t\x20-\x7e]")
"""Anything but printable ASCII and tab: other whitespace (`\\x1c`, `\\u2028`, ...) and controls."""


def is_float(token: str) -> bool:
    """Whether the token is a float by the grammar above."""
    return _FLOAT_RE.fullmatch(token) is not None


def is_integer(token: str) -> bool:
    """Whether the token is an integer by the grammar above (range not checked)."""
    return _INTEGER_RE.fullmatch(token) is not None


def parse_id(token: str) -> int | None:
    """The token as an int64 vertex id, or None when it is not an integer by the grammar or out of range.

    The digits are counted before `int()` is called: Python refuses to convert more than 4300
    digits (a `ValueError` of its own), and an int64 has at most 19 anyway.
    """
    if not is_integer(token):
        return None
    digits = token.lstrip("-").lstrip("0")
    if len(digits) > _INT64_DIGITS:
        return None
    value = int(digits or "0") * (-1 if token.startswith("-") else 1)
    return value if _INT64_MIN <= value <= _INT64_MAX else None


def shown(token: str) -> str:
    """The token quoted for an error message, cut short when long (a message stays one short line)."""
    if len(token) <= _SHOWN_CHARACTERS:
        return repr(token)
    return f"{token[:_SHOWN_CHARACTERS]!r}... ({len(token)} characters)"


def parse_floats(tokens: list[str]) -> np.ndarray | None:
    """The tokens as a `(len(tokens),)` float64 array, or None when any is not a float by the grammar.

    NumPy converts them all (Python's `float()`, about 0.1 s per million tokens). Tokens made of
    `0-9 . e E + -` alone, none starting with `+`, need no other check: on those characters
    `float()` accepts exactly the grammar (it adds only a leading `+`), so one scan of their joined
    text replaces a match per token. Others (`nan`, `inf`, damage) are matched one distinct token
    at a time.
    """
    if not _plain(tokens, _NOT_PLAIN_FLOAT):
        if not all(map(_FLOAT_RE.fullmatch, set(tokens))):
            return None
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:  # only plain tokens get here unmatched, e.g. `1e` or `1.2.3`
        return None


def parse_integers(tokens: list[str]) -> np.ndarray | None:
    """The tokens as a `(len(tokens),)` int64 array, or None when any is not an integer by the grammar
    or does not fit in int64 (the same shortcut as `parse_floats`, on `0-9 -`)."""
    if not _plain(tokens, _NOT_PLAIN_INTEGER):
        if not all(map(_INTEGER_RE.fullmatch, set(tokens))):
            return None
    try:
        return np.array(tokens, dtype=np.int64)
    except (ValueError, OverflowError):  # out of range, or over 4300 digits (leading zeros included)
        values = [parse_id(token) for token in tokens]
        return None if None in values else np.array(values, dtype=np.int64)


def _plain(tokens: list[str], not_plain: re.Pattern[str]) -> bool:
    """Whether the tokens hold none of the characters `not_plain` finds, and none starts with `+`.

    Joined by commas, which `float()` and `int()` refuse anywhere, unlike the whitespace they strip.
    """
    joined = ",".join(tokens)
    return not_plain.search(joined) is None and not joined.startswith("+") and ",+" not in joined


def check_line_characters(line: str) -> str | None:
    """Why the data part of a line cannot be split into fields, or None when it can.

    Fields are separated by ASCII spaces and tabs only; other whitespace and control characters
    (which Python's `str.split` would also split on) are refused outside comments.
    """
    match = _FORBIDDEN_CHARACTER.search(line)
    if match is None:
        return None
    return f"character U+{ord(match.group()):04X} outside a comment: fields must be ASCII, separated by spaces or tabs"


def format_floats(values: np.ndarray) -> str:
    """Space-separated shortest exact text of the floats (`repr`): reading it back gives the same bits."""
    return " ".join(map(repr, np.asarray(values, dtype=np.float64).tolist()))
