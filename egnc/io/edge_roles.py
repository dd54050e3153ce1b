"""Read which edges are known inliers from a file: a list of edge indices or an egnc labels file.

- A text file of 0-based edge indices (in the edge order of the g2o file), separated by spaces,
  tabs or newlines; `#` starts a comment. Exactly the listed edges are known inliers (list the
  odometry too if it should stay quadratic).
- An egnc labels file (`egnc.datasets.read_labels`, JSON starting with `{`): its
  `outlier_edges` are the ground-truth false edges, so every other edge is a known inlier and
  only the listed outliers remain candidates for rejection. This is the oracle setting: the best
  a front end that knew which loop closures are right could hand the solver.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from egnc.errors import EgncError, G2oFormatError
from egnc.io.numbers import check_line_characters, parse_id, shown
from egnc.io.text import read_text


def read_known_inliers(path: str | os.PathLike, num_edges: int) -> np.ndarray:
    """The `(E,)` bool known-inlier mask a file describes (see the module docstring).

    Raises:
        G2oFormatError: a token is not an index in `[0, num_edges)` (names file and line), or the
            file cannot be read.
        EgncError: a labels file describes a graph with another number of edges.
    """
    path = Path(path)
    text = read_text(path)
    if text.lstrip().startswith("{"):
        # Imported here: egnc.datasets loads every dataset generator, which egnc-solve rarely needs.
        from egnc.io.labels import read_labels

        is_outlier, _ = read_labels(path)
        if len(is_outlier) != num_edges:
            raise EgncError(f"{path}: labels describe {len(is_outlier)} edges, the graph has {num_edges}")
        return ~is_outlier
    known = np.zeros(num_edges, dtype=bool)
    for number, line in enumerate(text.split("\n"), start=1):
        line = line.partition("#")[0].removesuffix("\r")
        problem = check_line_characters(line)
        if problem:
            raise G2oFormatError(problem, path, number)
        for token in line.split():
            index = parse_id(token)
            if index is None or not 0 <= index < num_edges:
                raise G2oFormatError(f"{shown(token)} is not an edge index in [0, {num_edges})", path, number)
            known[index] = True
    return known
