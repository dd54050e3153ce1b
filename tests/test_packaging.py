"""The installed distribution says what it is: MIT licensed, with the LICENSE text shipped beside it."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import pytest

LICENSE = Path(__file__).parents[1] / "LICENSE"


@pytest.fixture(scope="module")
def distribution() -> importlib.metadata.Distribution:
    try:
        return importlib.metadata.distribution("egnc")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("egnc is imported from a source tree that was never installed")


def test_metadata_carries_the_mit_license_expression(distribution):
    metadata = distribution.metadata
    # PEP 639 (core metadata 2.4): an SPDX expression, not free text; an older install of this
    # tree (before setuptools 77 built it) has none: reinstall with `pip install -e .`.
    assert metadata["License-Expression"] == "MIT", "stale metadata? reinstall: pip install -e ."
    assert metadata.get_all("License-File") == ["LICENSE"]
    assert "Typing :: Typed" in metadata.get_all("Classifier")


def test_license_text_is_shipped(distribution):
    shipped = [path for path in distribution.files or () if path.name == "LICENSE"]
    assert shipped, "the distribution lists no LICENSE file"
    text = shipped[0].read_text(encoding="utf-8")
    assert text.startswith("MIT License") and "the egnc developers" in text
    if LICENSE.is_file():  # a source checkout: the shipped copy is this one
        assert text == LICENSE.read_text(encoding="utf-8")
