"""The JSON report of `egnc-solve`: versioned, every field documented in docs/cli.md, renamed fields kept."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from egnc.cli.report import DEPRECATED_NAMES, SCHEMA_VERSION

REPO = Path(__file__).parents[1]
OUTLIERS = REPO / "datasets" / "grid2d_outliers.g2o"  # rejects loops, so `rejected` has objects
FIELD_ROW = re.compile(r"^\| `([^`]+)` \| ([^|]+) \|", flags=re.MULTILINE)


def report_of(tmp_path: Path, *args: str, input_path: Path = OUTLIERS) -> dict[str, Any]:
    """The report of `egnc-solve INPUT --report ... args` run through a subprocess (INPUT: OUTLIERS)."""
    report = tmp_path / "report.json"
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", str(input_path), "--report", str(report), "-q", *args],
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    return json.loads(report.read_text())


@pytest.fixture(scope="module")
def reports(tmp_path_factory) -> dict[str, dict[str, Any]]:
    """A batch and an `--online` report of the same graph."""
    return {
        "batch": report_of(tmp_path_factory.mktemp("batch")),
        "online": report_of(tmp_path_factory.mktemp("online"), "--online"),
        "priors": report_of(tmp_path_factory.mktemp("priors"), input_path=gnss_file(tmp_path_factory.mktemp("gnss"))),
    }


def gnss_file(folder: Path) -> Path:
    """OUTLIERS with a position prior every 5th pose, a tenth of them moved by multipath jumps."""
    import egnc
    from egnc.datasets import add_multipath_outliers, add_position_priors
    from egnc.io.g2o import read_g2o, write_g2o

    graph = read_g2o(OUTLIERS)
    optimum = egnc.solve(graph).graph.poses
    corrupted = add_multipath_outliers(add_position_priors(graph, optimum, every=5, sigma=1.0), 10, seed=1)
    path = folder / "gnss.g2o"
    write_g2o(corrupted.graph, path)
    return path


def documented_fields() -> dict[str, str]:
    """`{field path: type}` of the table of fields in docs/cli.md's "JSON report" section."""
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    section = text.split("\n## JSON report\n", 1)[1].split("\n## ", 1)[0]
    return {path: kind.strip() for path, kind in FIELD_ROW.findall(section)}


def fields(value: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """Every field of a JSON value with its value, by path: `a.b` for field `b` of object `a`, `a[].b` in a list."""
    found = [(prefix, value)] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += fields(item, f"{prefix}.{key}" if prefix else key)
    elif isinstance(value, list):
        for item in value:
            if isinstance(item, dict):
                found += fields(item, f"{prefix}[]")[1:]
    return found


def conforms(value: Any, kind: str) -> bool:
    """Whether a JSON value is of a type as docs/cli.md names it (`integer`, `list of strings`, ...)."""
    if kind.startswith("list of "):
        item_kind = {"integers": "integer", "strings": "string", "objects": "object"}[kind.removeprefix("list of ")]
        return isinstance(value, list) and all(conforms(item, item_kind) for item in value)
    if kind == "number or null" and value is None:
        return True
    types = {"integer": int, "number": (int, float), "number or null": (int, float), "string": str, "object": dict}
    if kind == "boolean":
        return isinstance(value, bool)
    return isinstance(value, types[kind]) and not isinstance(value, bool)


def test_docs_list_exactly_the_fields_of_a_batch_and_an_online_report(reports):
    batch = {path for path, _ in fields(reports["batch"])}
    online = {path for path, _ in fields(reports["online"])}
    priors = {path for path, _ in fields(reports["priors"])}
    assert "online" not in batch and "online.update_ms.p99" in online
    assert "rejected[].r_robust" in batch and "timings_s.factorize" in batch
    assert "rejected_priors" not in batch and reports["priors"]["rejected_priors"]
    assert sorted(batch | online | priors) == sorted(documented_fields())


def test_fields_have_their_documented_types(reports):
    documented = documented_fields()
    for report in reports.values():
        for path, value in fields(report):
            assert conforms(value, documented[path]), f"{path}: {value!r} is not {documented[path]}"


def test_report_carries_its_schema_version(reports):
    assert SCHEMA_VERSION == 2
    for report in reports.values():
        assert next(iter(report)) == "schema_version" and report["schema_version"] == SCHEMA_VERSION


def test_renamed_fields_keep_their_old_name_for_one_version(reports):
    """The costs renamed in version 2 (a script reading `final_cost` got nothing) are written under both names."""
    assert DEPRECATED_NAMES["final_cost"] == "final_cost_all_edges"
    for report in reports.values():
        assert report["deprecated"] == DEPRECATED_NAMES
        for old, new in DEPRECATED_NAMES.items():
            assert report[old] == report[new] is not None
    docs = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    for old, new in DEPRECATED_NAMES.items():
        assert f'| `deprecated.{old}` | string | | `"{new}"` |' in docs
        assert f"| `{old}` | number | | deprecated since version 2, removed in 3: `{new}` |" in docs
