"""Tests of egnc.graph.index_sets against NumPy's own set routines."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from egnc.graph.index_sets import sorted_unique


@settings(max_examples=50, deadline=None)
@given(values=st.lists(st.integers(-5, 40), max_size=60))
def test_sorted_unique_is_numpys_unique(values):
    array = np.array(values, dtype=np.int64)
    result = sorted_unique(array)
    np.testing.assert_array_equal(result, np.unique(array))
    assert result.dtype == array.dtype


def test_sorted_unique_of_rows_and_a_union():
    edges = np.array([[3, 1], [1, 2], [2, 3], [7, 3]])
    np.testing.assert_array_equal(sorted_unique(edges.ravel()), [1, 2, 3, 7])
    np.testing.assert_array_equal(sorted_unique(np.concatenate(([9, 4], [1, 4, 6]))), np.union1d([9, 4], [1, 4, 6]))
    assert sorted_unique(np.zeros(0, dtype=np.int64)).shape == (0,)
