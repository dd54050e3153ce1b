"""Write the per-edge outcome of a solve as CSV, for spreadsheets and pandas.

Header `index,i,j,kind,r,weight,mu,inlier`, one row per edge in file order:

- `index`: 0-based edge index (the order of the EDGE lines);
- `i`, `j`: the vertex ids the edge joins;
- `kind`: `odometry` (a known inlier between consecutive ids), `known-inlier` (another known
  inlier, e.g. from `--known-inliers FILE`) or `loop` (a candidate for rejection);
- `r`: whitened residual norm at the solution; `weight`: final IRLS weight; `mu`: final kernel
  parameter, empty where the kernel has none; `inlier`: `true`, or `false` for a rejected edge.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from egnc.io.atomic import atomic_text_file

if TYPE_CHECKING:  # the result is written, never built here
    from egnc.api import Result

EDGES_CSV_HEADER = "index,i,j,kind,r,weight,mu,inlier"


def edge_kinds(result: Result) -> np.ndarray:
    """`(E,)` str: `odometry`, `known-inlier` or `loop` (see the module docstring)."""
    odometry = result.known_inliers & result.graph.is_odometry
    return np.where(odometry, "odometry", np.where(result.known_inliers, "known-inlier", "loop"))


def write_edges_csv(result: Result, path: str | os.PathLike) -> None:
    """Write one CSV row per edge of `result`, atomically."""
    ids = result.graph.vertex_ids[result.graph.edges].tolist()
    rows = zip(
        ids,
        edge_kinds(result).tolist(),
        result.residual_norms.tolist(),
        result.weights.tolist(),
        result.mu.tolist(),
        result.inliers.tolist(),
    )
    with atomic_text_file(Path(path)) as out:
        out.write(EDGES_CSV_HEADER + "\n")
        for index, ((i, j), kind, r, weight, mu, inlier) in enumerate(rows):
            mu_text = "" if mu != mu else repr(mu)  # NaN: no kernel parameter
            out.write(f"{index},{i},{j},{kind},{r!r},{weight!r},{mu_text},{str(inlier).lower()}\n")
