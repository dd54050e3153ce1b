"""GTSAM `Symbol` keys as vertex ids: a character in the top 8 bits, an index in the lower 56.

GTSAM names a variable `Symbol('a', 12)` (shown `a12`); its key is `ord('a') << 56 | 12`, and
`egnc.interop.gtsam` keeps each key's 64 bits as the vertex id. Multi-robot code gives each
robot one character, so the character of an id names its robot. This module encodes and
decodes that layout without GTSAM, for messages that name vertices as their user does.

An id "looks like a Symbol" when its top byte is an ASCII letter: the ids of a g2o file (small
non-negative integers) have a top byte of 0 and keep their number.
"""

from __future__ import annotations

import numpy as np

__all__ = ["symbol_characters", "symbol_id", "vertex_name"]

_SHIFT = 56
_INDEX_MASK = (1 << _SHIFT) - 1


def symbol_id(character: str, index: np.ndarray | int) -> np.ndarray:
    """The int64 id of GTSAM's `Symbol(character, index)` key (character in the top 8 bits)."""
    return (np.int64(ord(character)) << np.int64(_SHIFT)) + np.asarray(index, dtype=np.int64)


def symbol_characters(vertex_ids: np.ndarray) -> np.ndarray:
    """`(N,)` str: the `Symbol` character of each id that looks like a Symbol, `""` for the others."""
    top = (np.asarray(vertex_ids, dtype=np.int64).view(np.uint64) >> np.uint64(_SHIFT)).astype(np.uint8)
    letter = ((top >= ord("a")) & (top <= ord("z"))) | ((top >= ord("A")) & (top <= ord("Z")))
    return np.where(letter, np.where(letter, top, ord(" ")).view("S1").astype(str), "")


def vertex_name(vertex_id: int) -> str:
    """`"a12"` for an id that looks like `Symbol('a', 12)`, else the id's number (`"17"`)."""
    (character,) = symbol_characters(np.array([vertex_id]))
    return f"{character}{int(vertex_id) & _INDEX_MASK}" if character else str(int(vertex_id))
