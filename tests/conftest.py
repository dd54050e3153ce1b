"""Shared fixtures: the benchmark datasets, read in place from `../shared/datasets`.

The datasets are reference data that live beside the checkout and are never copied into the
repository; tests that need them skip when the folder or file is absent.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

SHARED_DATASETS = Path(__file__).parents[2] / "shared" / "datasets"
"""Where the benchmark pose graphs live: `<checkout>/../shared/datasets`."""


@pytest.fixture(scope="session")
def shared_datasets() -> Path:
    """The shared datasets folder; skips the test when it is absent."""
    if not SHARED_DATASETS.is_dir():
        pytest.skip(f"shared datasets not found at {SHARED_DATASETS}")
    return SHARED_DATASETS


@pytest.fixture(scope="session")
def dataset_path(shared_datasets: Path) -> Callable[[str], Path]:
    """A function `name -> Path` of one dataset file (e.g. `"intel.g2o"`), skipping if absent."""

    def find(name: str) -> Path:
        path = shared_datasets / name
        if not path.is_file():
            pytest.skip(f"dataset {name} not found in {shared_datasets}")
        return path

    return find
