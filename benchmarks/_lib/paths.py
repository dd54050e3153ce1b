"""Where the benchmarks find their data.

`SHARED_DATASETS` is `../shared/datasets` beside the checkout (see that folder's README), or the
`EGNC_DATASETS` environment variable; `SHIPPED_DATASETS` the small graphs in the repository's own
`datasets/`.
"""

from __future__ import annotations

import os
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[2]
SHARED_DATASETS = Path(os.environ.get("EGNC_DATASETS", REPOSITORY.parent / "shared" / "datasets"))
SHIPPED_DATASETS = REPOSITORY / "datasets"
ENTRIES = REPOSITORY / "benchmarks"
"""The entry scripts' folder: a helper that starts a child process runs an entry from here."""


def dataset_path(name_or_path: str | os.PathLike[str]) -> Path:
    """Resolve a file path, or a bare dataset name such as `csail`, against `SHARED_DATASETS`."""
    path = Path(name_or_path)
    if path.exists():
        return path
    for candidate in (SHARED_DATASETS / path, SHARED_DATASETS / f"{path}.g2o"):
        if candidate.exists():
            return candidate
    raise FileNotFoundError(f"no such g2o file: {name_or_path} (also looked in {SHARED_DATASETS})")
