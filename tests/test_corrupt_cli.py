"""`egnc-corrupt` through a subprocess: reproducible files, labels that match, one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from egnc.datasets import false_loop_count, read_labels
from egnc.io import read_g2o

DATASETS = Path(__file__).parents[1] / "datasets"
GRID2D = DATASETS / "grid2d.g2o"


def egnc_corrupt(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `egnc-corrupt args...` with this interpreter, as `python -m egnc.cli.corrupt`."""
    return subprocess.run(
        [sys.executable, "-m", "egnc.cli.corrupt", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        timeout=300,
    )


def test_same_seed_gives_byte_identical_files_and_consistent_labels(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    for folder in (first, second):
        run = egnc_corrupt(GRID2D, "--percent", "30", "--seed", "1", "-o", folder / "out.g2o")
        assert run.returncode == 0, run.stderr
        assert run.stderr == ""
        assert sorted(p.name for p in folder.iterdir()) == ["out.g2o", "out.labels.json"]
    for name in ("out.g2o", "out.labels.json"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name

    clean, corrupted = read_g2o(GRID2D), read_g2o(first / "out.g2o")
    is_outlier, meta = read_labels(first / "out.labels.json")
    assert len(is_outlier) == corrupted.num_edges
    num_loops = int(clean.is_loop_closure.sum())
    assert int(is_outlier.sum()) == false_loop_count(num_loops, 30) == corrupted.num_edges - clean.num_edges
    assert not np.any(is_outlier & corrupted.is_odometry)
    # The original edges are all there, in their order, once the false loops are dropped.
    np.testing.assert_array_equal(corrupted.edges[~is_outlier], clean.edges)
    np.testing.assert_array_equal(corrupted.measurements[~is_outlier], clean.measurements)
    assert meta["percent"] == 30 and meta["seed"] == 1 and meta["variant"] == "random"
    assert meta["graph"] == "out.g2o" and meta["clean_graph"] == "grid2d.g2o"


def test_reproduces_the_shipped_corrupted_grid(tmp_path):
    # datasets/generate.py made grid2d_outliers.g2o the same way: 30 %, seed 2, SciPy reference.
    out = tmp_path / "grid2d_outliers.g2o"
    run = egnc_corrupt(GRID2D, "--percent", "30", "--seed", "2", "-o", out, "-q")
    assert run.returncode == 0, run.stderr
    assert run.stdout == ""
    assert out.read_bytes() == (DATASETS / "grid2d_outliers.g2o").read_bytes()
    ours, _ = read_labels(tmp_path / "grid2d_outliers.labels.json")
    shipped, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    np.testing.assert_array_equal(ours, shipped)


def test_other_seed_variant_and_labels_path(tmp_path):
    labels = tmp_path / "custom.json"
    run = egnc_corrupt(
        GRID2D, "--percent", "20", "--seed", "3", "--variant", "group", "--group-size", "4",
        "-o", tmp_path / "g.g2o", "--labels", labels,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "g.g2o" in run.stdout and "custom.json" in run.stdout
    is_outlier, meta = read_labels(labels)
    assert meta["variant"] == "group" and meta["group_size"] == 4
    corrupted = read_g2o(tmp_path / "g.g2o")
    false_edges = corrupted.edges[is_outlier]
    # Groups of consecutive false loops (a + k, b + k): most false loops have a neighbour.
    pairs = {tuple(edge) for edge in false_edges.tolist()}
    assert sum((a + 1, b + 1) in pairs or (a - 1, b - 1) in pairs for a, b in pairs) >= 0.75 * len(pairs)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["custom.json", "g.g2o"]


def test_errors_are_one_line_and_leave_nothing_behind(tmp_path):
    out = tmp_path / "out.g2o"
    run = egnc_corrupt(GRID2D, "--percent", "100", "--seed", "1", "-o", out)
    assert run.returncode == 1
    assert run.stderr.startswith("egnc-corrupt: error: ") and run.stderr.count("\n") == 1
    assert "percent" in run.stderr

    run = egnc_corrupt(tmp_path / "missing.g2o", "--percent", "10", "--seed", "1", "-o", out)
    assert run.returncode == 1 and "missing.g2o" in run.stderr and run.stderr.count("\n") == 1

    # The labels cannot be written (no such folder): the graph written before is removed again.
    run = egnc_corrupt(GRID2D, "--percent", "10", "--seed", "1", "-o", out, "--labels", tmp_path / "no" / "l.json")
    assert run.returncode == 1 and "l.json" in run.stderr and run.stderr.count("\n") == 1
    assert list(tmp_path.iterdir()) == []

    run = egnc_corrupt(GRID2D, "--seed", "1", "-o", out)  # --percent missing: usage error
    assert run.returncode == 2
    assert list(tmp_path.iterdir()) == []
