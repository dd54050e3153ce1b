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


LONG_TIER_MODULES = frozenset(
    {
        "test_notebooks",  # every notebook executed in a kernel
        "test_fuzz",  # the fuzzers' own runs
        "test_bench_isam2",  # GTSAM's ISAM2 replays
        "test_bench_parallel",  # worker pools and a Dask cluster
        "test_bench_scale",  # the scale benchmarks end to end
        "test_bench_online",  # online benchmark repeats end to end
        "test_bench_arrival",
        "test_bench_online_as_batch",
        "test_bench_online_growth",
    }
)
"""Test modules of the long tier as a whole (docs/development.md, "Tests")."""

LONG_TIER_FIXTURES = frozenset({"shared_datasets", "dataset_path"})
"""A test that reads the real datasets is in the long tier."""

LONG_TIER_WORDS = ("gtsam", "cholmod", "rslab", "rerun")
"""A test whose id names a cross-check with GTSAM, an optional backend or Rerun recordings is in the long tier
(but for the layout checks, whose ids are module names such as `bench.gtsam`)."""


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the long tier `slow`: real datasets, notebooks, fuzz, GTSAM cross-checks, backends.

    The default run (`pytest`, pyproject's `-m "not slow"`) is the fast tier; `pytest -m slow`
    runs the long tier and `pytest -m "slow or not slow"` both (docs/development.md).
    """
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if item.module else ""
        nodeid = item.nodeid.lower()
        if (
            module in LONG_TIER_MODULES
            or LONG_TIER_FIXTURES.intersection(getattr(item, "fixturenames", ()))
            or (module != "test_architecture" and any(word in nodeid for word in LONG_TIER_WORDS))
        ):
            item.add_marker(pytest.mark.slow)
