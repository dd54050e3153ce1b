"""Sorted sets of integer indices (pose rows, edge indices), by sorting.

NumPy 2's `np.unique` hashes integers; on the tens to thousands of indices an online update
handles, that took 4-25x as long as sorting and dropping repeats (BENCHMARKS.md, "Small-batch
costs of an online update"), and on the 4M vertex ids of a 1M-pose g2o file 2.3 s against
0.09 s.
"""

from __future__ import annotations

import numpy as np


def sorted_unique(values: np.ndarray) -> np.ndarray:
    """The distinct entries of the 1-D integer array `values`, in increasing order (`np.unique`)."""
    ordered = np.sort(values)
    return ordered[np.concatenate(([True], ordered[1:] != ordered[:-1]))] if len(ordered) else ordered
