"""GTSAM `Symbol` keys as vertex ids, decoded without GTSAM (`egnc.graph.symbols`)."""

from __future__ import annotations

import numpy as np
import pytest

from egnc.graph.symbols import symbol_characters, symbol_id, vertex_name


def test_a_symbol_id_is_the_character_in_the_top_byte_and_the_index_below():
    assert int(symbol_id("a", 12)) == (0x61 << 56) + 12
    np.testing.assert_array_equal(symbol_id("b", np.arange(3)), (0x62 << 56) + np.arange(3))


def test_ids_that_look_like_symbols_are_named_by_character_and_index():
    ids = np.array([symbol_id("a", 12), symbol_id("Z", 0), 17, 0, symbol_id("x", 2**55 - 1)], dtype=np.int64)
    assert symbol_characters(ids).tolist() == ["a", "Z", "", "", "x"]
    assert [vertex_name(int(i)) for i in ids] == ["a12", "Z0", "17", "0", f"x{2**55 - 1}"]


def test_ids_whose_top_byte_is_no_letter_keep_their_number():
    digit = int(symbol_id("7", 3))  # a Symbol of a digit: not taken for a robot's name
    high = -(1 << 62)  # a key of 2**63 or more (a character above 0x7f) is a negative id
    assert symbol_characters(np.array([digit, high])).tolist() == ["", ""]
    assert (vertex_name(digit), vertex_name(high)) == (str(digit), str(high))


def test_gtsam_symbols_decode_as_gtsam_prints_them():
    gtsam = pytest.importorskip("gtsam")
    # (GTSAM's own string keeps 10 characters at most: the indices here are shorter)
    for character, index in (("a", 12), ("b", 0), ("x", 12345678), ("L", 7)):
        key = gtsam.symbol(character, index)
        assert int(symbol_id(character, index)) == key
        assert vertex_name(key) == gtsam.Symbol(key).string()
