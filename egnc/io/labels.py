"""Ground-truth outlier labels, kept in a JSON sidecar beside a pose-graph file.

A corrupted g2o file must not reveal which of its edges are false, so the labels live in their own
small file (`name.labels.json` next to `name.g2o` by convention):

    {
      "format": "egnc-labels-1",
      "num_edges": 1234,
      "outlier_edges": [17, 40, ...],
      ...any further metadata (generator, seed, percent, ...)
    }

`outlier_edges` holds 0-based indices in the edge order of the pose-graph file, i.e. the order of
`PoseGraph.edges` after `read_g2o`. A graph with labelled priors adds `"num_priors"` and
`"outlier_priors"`, 0-based indices in the order of `PoseGraph.priors` (`read_prior_labels`);
files without them read as before.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

from egnc.errors import EgncError
from egnc.io.atomic import atomic_text_file

LABELS_FORMAT = "egnc-labels-1"
"""Value of the `format` key written by `write_labels` and required by `read_labels`."""

_RESERVED_KEYS = ("format", "num_edges", "outlier_edges", "num_priors", "outlier_priors")


def write_labels(
    path: str | Path,
    is_outlier: np.ndarray,
    meta: dict[str, Any] | None = None,
    prior_outliers: np.ndarray | None = None,
) -> None:
    """Write the outlier labels of a graph's edges to a JSON sidecar, atomically.

    Args:
        path: file to write; it is replaced only once the new content is complete.
        is_outlier: `(E,)` bool, true for the false edges, in the graph file's edge order.
        meta: extra JSON-serializable entries stored after the reserved keys (which it must not
            contain), e.g. the generator's seed and parameters.
        prior_outliers: `(K,)` bool, true for the false priors (e.g. multipath GNSS fixes), in
            the order of `PoseGraph.priors`; None writes no priors' entries.

    Raises:
        EgncError: `is_outlier` is not one-dimensional or `meta` uses a reserved key.
    """
    is_outlier = np.asarray(is_outlier)
    if is_outlier.ndim != 1 or is_outlier.dtype != bool:
        raise EgncError(f"is_outlier must be a 1-D bool array, got {is_outlier.dtype} {is_outlier.shape}")
    meta = dict(meta or {})
    clash = [key for key in _RESERVED_KEYS if key in meta]
    if clash:
        raise EgncError(f"labels metadata must not use the reserved keys {', '.join(clash)}")
    content: dict[str, Any] = {
        "format": LABELS_FORMAT,
        "num_edges": len(is_outlier),
        "outlier_edges": np.flatnonzero(is_outlier).tolist(),
    }
    if prior_outliers is not None:
        prior_outliers = np.asarray(prior_outliers, dtype=bool)
        content.update(num_priors=len(prior_outliers), outlier_priors=np.flatnonzero(prior_outliers).tolist())
    content.update(meta)
    # One key per line keeps the file readable and diff-friendly while the index list stays compact.
    lines = [f"  {json.dumps(key)}: {json.dumps(value)}" for key, value in content.items()]
    with atomic_text_file(Path(path)) as out:
        out.write("{\n" + ",\n".join(lines) + "\n}\n")


def read_labels(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """Read a labels sidecar written by `write_labels`.

    Args:
        path: the JSON file.

    Returns:
        `(is_outlier, meta)`: `(E,)` bool outlier flags in file edge order, and the remaining
        metadata (everything but the reserved keys).

    Raises:
        EgncError: the file is missing, not JSON, of another format, or its indices are invalid.
    """
    path = Path(path)
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise EgncError(f"{path}: cannot read labels: {error.strerror or error}") from None
    except json.JSONDecodeError as error:
        raise EgncError(f"{path}:{error.lineno}: labels file is not valid JSON: {error.msg}") from None
    if not isinstance(content, dict) or content.get("format") != LABELS_FORMAT:
        raise EgncError(f'{path}: not an egnc labels file (expected "format": "{LABELS_FORMAT}")')
    num_edges = content.get("num_edges")
    indices = content.get("outlier_edges")
    if not _is_int(num_edges) or num_edges < 0:
        raise EgncError(f"{path}: num_edges must be a non-negative integer, got {num_edges!r}")
    if not isinstance(indices, list) or not all(_is_int(index) for index in indices):
        raise EgncError(f"{path}: outlier_edges must be a list of integers")
    outlier_edges = np.array(indices, dtype=np.int64)
    if len(outlier_edges) and (outlier_edges.min() < 0 or outlier_edges.max() >= num_edges):
        raise EgncError(f"{path}: outlier_edges must lie in [0, num_edges = {num_edges})")
    if len(np.unique(outlier_edges)) != len(outlier_edges):
        raise EgncError(f"{path}: outlier_edges lists an edge more than once")
    is_outlier = np.zeros(num_edges, dtype=bool)
    is_outlier[outlier_edges] = True
    meta = {key: value for key, value in content.items() if key not in _RESERVED_KEYS}
    return is_outlier, meta


def read_prior_labels(path: str | Path) -> np.ndarray | None:
    """`(K,)` bool, the false priors of a labels sidecar (`write_labels(prior_outliers=...)`), or
    None where it labels no priors.

    Raises:
        EgncError: the file is not an egnc labels file, or its priors' entries are invalid.
    """
    path = Path(path)
    read_labels(path)  # the edges' part and the format, checked
    content = json.loads(path.read_text(encoding="utf-8"))
    if "outlier_priors" not in content:
        return None
    num_priors, indices = content.get("num_priors"), content["outlier_priors"]
    if not _is_int(num_priors) or num_priors < 0:
        raise EgncError(f"{path}: num_priors must be a non-negative integer, got {num_priors!r}")
    if not isinstance(indices, list) or not all(_is_int(index) and 0 <= index < num_priors for index in indices):
        raise EgncError(f"{path}: outlier_priors must be a list of integers in [0, num_priors = {num_priors})")
    is_outlier = np.zeros(num_priors, dtype=bool)
    is_outlier[np.array(indices, dtype=np.int64)] = True
    return is_outlier


def _is_int(value: object) -> TypeGuard[int]:
    """Whether a parsed JSON value is an integer (JSON booleans are not)."""
    return isinstance(value, int) and not isinstance(value, bool)
