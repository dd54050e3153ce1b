"""The benchmark grid: method specs, a tiny grid end to end (library and CLI), timeouts and
errors of isolated runs, the IRL mode, aggregation, and the optional GTSAM baselines."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc.bench as bench
from egnc.bench import (
    CSV_COLUMNS,
    BenchCase,
    MethodSpec,
    RunRecord,
    format_markdown,
    parse_method,
    parse_methods,
    run_case,
    run_grid,
    run_irl,
    summarize,
    write_outputs,
)
from egnc.datasets import grid_world, read_labels
from egnc.errors import EgncError
from egnc.io import IrlLog, read_g2o, write_g2o, write_irl

DATASETS = Path(__file__).parents[1] / "datasets"


# --- method specs -------------------------------------------------------------------------------


def test_method_specs_with_options():
    assert parse_method("egnc") == MethodSpec("egnc", "egnc", ())
    spec = parse_method("egnc[max_stages=50, threshold=distance,refine=false]")
    assert spec.method == "egnc" and spec.label == "egnc[max_stages=50, threshold=distance,refine=false]"
    options = spec.gnc_options()
    assert (options.max_stages, options.threshold, options.refine) == (50, "distance", False)
    assert parse_method("risam[c=2.5]").gnc_options().c == 2.5
    assert parse_method("gtsam-gnc-tls").is_gtsam
    specs = parse_methods("egnc[max_stages=50,c=2],risam, l2,gtsam-lm")
    assert [s.label for s in specs] == ["egnc[max_stages=50,c=2]", "risam", "l2", "gtsam-lm"]


def test_method_specs_choose_the_starts_by_name():
    assert parse_method("egnc[starts=chordal+regrouped]").gnc_options().starts == ("chordal", "regrouped")
    assert parse_method("egnc[starts=()]").gnc_options().starts == ()
    with pytest.warns(DeprecationWarning, match="starts="):  # the former booleans, for one release
        assert "chordal" not in parse_method("egnc[chordal_start=false]").gnc_options().starts


def test_option_values_follow_the_field_types():
    convert = bench.methods._convert
    assert convert("none", int | None, "x") is None
    assert convert("7", int | None, "x") == 7
    assert convert("yes", bool, "x") is True
    with pytest.raises(EgncError, match="x: 'maybe' is not a valid bool"):
        convert("maybe", bool, "x")
    with pytest.raises(EgncError, match="is not a valid int or none"):
        convert("1.5", int | None, "x")


@pytest.mark.parametrize(
    "text, message",
    [
        ("foo", "unknown method 'foo'"),
        ("egnc[bar=1]", "unknown option 'bar'"),
        ("egnc[max_stages=x]", "not a valid int"),
        ("egnc[c=-1]", r"GncOptions.c must be a finite number in \(0, inf\)"),
        ("egnc[threshold=abs]", "threshold"),
        ("egnc[c]", "not of the form name=value"),
        ("egnc[c=1,c=2]", "given twice"),
        ("gtsam-lm[c=1]", "take no options"),
        ("egnc[c=1", "unbalanced"),
        ("egnc,egnc", "listed twice"),
        (" , ", "no method"),
    ],
)
def test_method_spec_errors(text, message):
    with pytest.raises(EgncError, match=message):
        parse_methods(text)


# --- a tiny grid end to end ---------------------------------------------------------------------


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    assert rows and tuple(rows[0]) == CSV_COLUMNS
    return rows


def test_tiny_grid_writes_csv_and_markdown(tmp_path):
    lines: list[str] = []
    records = run_grid(
        ["grid2d"], [30], [1], ["egnc", "l2"], data_dir=DATASETS, time_limit_s=120, progress=lines.append
    )
    assert lines[0].startswith("[1/2] grid2d 30% seed 1 egnc: ok P 1.000 R 1.000") and lines[1].startswith("[2/2]")
    written = write_outputs(records, tmp_path / "out", baseline_method="egnc", header="my header")
    rows = {row["method"]: row for row in read_csv(written["csv"])}
    assert set(rows) == {"egnc", "l2"}
    egnc_row, l2_row = rows["egnc"], rows["l2"]
    # The corrupted graph of datasets/grid2d_outliers.g2o uses seed 2; seed 1 adds the same count.
    num_loops, num_false = 227, 97
    for row in (egnc_row, l2_row):
        assert (row["dataset"], row["percent"], row["seed"], row["status"]) == ("grid2d", "30.0", "1", "ok")
        assert (int(row["loops"]), int(row["outliers"])) == (num_loops + num_false, num_false)
        assert float(row["time_s"]) > 0 and float(row["wall_s"]) >= float(row["time_s"])
    # egnc rejects exactly the false loops and then recovers the outlier-free optimum.
    assert (egnc_row["precision"], egnc_row["recall"], egnc_row["success"]) == ("1.0", "1.0", "true")
    assert int(egnc_row["rejected"]) == num_false and int(egnc_row["stages"]) >= 2  # mu = 1, refinement
    assert float(egnc_row["ate"]) < 1e-6 and float(egnc_row["rpe_percent"]) < 1e-4
    # Least squares rejects nothing: every false loop stays in and drags the trajectory metres off.
    assert l2_row["success"] == "false" and int(l2_row["rejected"]) == 0 and float(l2_row["recall"]) == 0.0
    assert float(l2_row["ate"]) > 1.0 and l2_row["stages"] == "1"

    table = written["md"].read_text()
    assert table.startswith("my header\n\n| dataset | outliers % | method |")
    assert "| grid2d | 30 | egnc | 1.0000 | 1.0000 | 1/1 |" in table
    assert "| 1.00 |" in table  # egnc relative to itself
    assert table.rstrip().endswith(bench.SUCCESS_DEFINITION)  # the table says what success means
    if "runtime" in written:
        assert written["runtime"].stat().st_size > 0 and written["precision_recall"].stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(p.name for p in written.values())


def test_cli_runs_the_grid_quietly_and_reports_usage_errors(tmp_path):
    command = [sys.executable, "-m", "egnc.cli.bench"]
    run = subprocess.run(
        [*command, "--datasets", "grid2d", "--data-dir", DATASETS, "--percent", "10", "--seeds", "3",
         "--methods", "egnc[threshold=distance]", "--out", tmp_path / "out", "-q"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stdout == "" and run.stderr == ""
    (row,) = read_csv(tmp_path / "out" / "results.csv")
    assert (row["method"], row["percent"], row["seed"], row["status"]) == (
        "egnc[threshold=distance]", "10.0", "3", "ok"
    )
    assert "`egnc-bench --datasets grid2d" in (tmp_path / "out" / "results.md").read_text()

    run = subprocess.run([*command, "--datasets", "nowhere", "--data-dir", DATASETS, "--out", tmp_path / "x"],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 1 and run.stderr.startswith("egnc-bench: error: dataset 'nowhere' not found")
    assert run.stderr.count("\n") == 1 and not (tmp_path / "x").exists()
    run = subprocess.run([*command, "--irl", "x.irl", "--seeds", "1"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 2 and "--seeds" in run.stderr


# --- isolation: timeouts and errors -------------------------------------------------------------


def test_a_run_over_the_time_limit_is_reported_as_timeout(tmp_path):
    world = grid_world(2, 4000, seed=11, noise_scale=0.3)
    write_g2o(world.graph, tmp_path / "big.g2o")
    (record,) = run_grid([tmp_path / "big.g2o"], [30], [1], ["risam"], time_limit_s=0.02)
    assert record.status == "timeout"
    assert 0.02 <= record.wall_s < 10.0
    assert math.isnan(record.precision) and not record.success


def test_a_failing_run_is_an_error_record_not_an_exception():
    graph = read_g2o(DATASETS / "grid2d_outliers.g2o")
    is_outlier, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    bad_reference = np.zeros((3, 3))  # wrong number of poses: scoring fails in the child
    case = BenchCase("grid2d_outliers", 30.0, 2, graph, is_outlier, graph.is_odometry, bad_reference)
    record = run_case(case, parse_method("l2"), time_limit_s=60)
    assert record.status.startswith("error: ") and "reference has 3" in record.status
    assert "\n" not in record.status


def test_a_dataset_that_cannot_be_corrupted_is_reported_per_run(tmp_path):
    # A pure odometry chain has no loop closure to set the percentage against.
    world = grid_world(2, 30, seed=1, loop_probability=0.0)
    write_g2o(world.graph, tmp_path / "chain.g2o")
    records = run_grid([tmp_path / "chain.g2o"], [10], [1, 2], ["egnc", "l2"], time_limit_s=60)
    assert len(records) == 4
    assert all(r.status.startswith("error: add_false_loops") and "no loop closures" in r.status for r in records)


# --- IRL mode -----------------------------------------------------------------------------------


def test_irl_mode_scores_against_the_log_labels(tmp_path):
    graph = read_g2o(DATASETS / "grid2d_outliers.g2o")
    is_outlier, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    write_irl(IrlLog.from_graph(graph, is_outlier, name="grid", date="2024-01-01"), tmp_path / "grid.irl")
    (record,) = run_irl(tmp_path / "grid.irl", ["egnc"], time_limit_s=120)
    assert record.status == "ok" and record.seed is None and record.dataset == "grid"
    assert record.percent == pytest.approx(100 * 97 / 324)
    assert (record.precision, record.recall, record.success) == (1.0, 1.0, True)
    assert record.ate < 1e-6  # the reference is the optimum without the labelled outliers


def test_noisy_manhattan_irl(dataset_path):
    (record,) = run_irl(dataset_path("manhattan_noisy.irl"), ["l2"], time_limit_s=120)
    assert record.status == "ok" and (record.loops, record.outliers) == (733, 223)
    assert record.recall < 1.0 or record.precision < 1.0  # least squares cannot sort these out


# --- aggregation --------------------------------------------------------------------------------


def test_summary_means_over_seeds_time_ratio_and_failures():
    def run(method: str, seed: int, time_s: float, recall: float = 1.0, status: str = "ok") -> RunRecord:
        # 10 loops of which 4 false; precision 1: only false loops are rejected
        return RunRecord("d", 30.0, seed, method, status, precision=1.0, recall=recall,
                         success=recall == 1.0, ate=0.5, rpe_percent=2.0, time_s=time_s,
                         loops=10, outliers=4, rejected=round(4 * recall))  # fmt: skip

    records = [
        run("risam", 1, 2.0), run("risam", 2, 4.0),
        run("egnc", 1, 1.0), run("egnc", 2, 2.0, recall=0.5), run("egnc", 3, math.nan, status="timeout"),
    ]  # fmt: skip
    risam, egnc = summarize(records, "risam")
    assert (risam.runs, risam.ok, risam.time_s, risam.time_ratio) == (2, 2, 3.0, 1.0)
    assert (egnc.runs, egnc.ok, egnc.successes, egnc.failures) == (3, 2, 1, "1 timeout")
    assert egnc.recall == 0.75 and egnc.time_s == 1.5 and egnc.time_ratio == 0.5
    table = format_markdown([risam, egnc], "risam")
    # riSAM's convention: seed 2 keeps 2 false loops beside the 6 true ones, P = 0.75; mean 0.875
    assert egnc.kept_precision == 0.875 and egnc.kept_recall == 1.0
    row = "| d | 30 | egnc | 1.0000 | 0.7500 | 1/3 | 0.8750 | 1.0000 | 0.5 | 2.00 | 1.500 | 0.50 | 1 timeout |"
    assert row in table
    (alone,) = summarize(records[2:], "risam")
    assert math.isnan(alone.time_ratio) and "| - |" in format_markdown([alone])


# --- GTSAM baselines ----------------------------------------------------------------------------


def test_gtsam_methods_are_skipped_without_gtsam(monkeypatch):
    monkeypatch.setattr(bench.runner, "gtsam_available", lambda: False)
    notes: list[str] = []
    records = run_grid(["grid2d"], [10], [1], ["l2", "gtsam-gnc-tls"], data_dir=DATASETS, progress=notes.append)
    assert [r.method for r in records] == ["l2"]
    assert "skipping gtsam-gnc-tls" in notes[0]
    with pytest.raises(EgncError, match="nothing to run: gtsam is not importable .* for gtsam-lm"):
        run_grid(["grid2d"], [10], [1], ["gtsam-lm"], data_dir=DATASETS)


def test_cli_exits_1_when_no_method_can_run(tmp_path):
    # gtsam blocked in the child interpreter: the only method asked for cannot run.
    script = "import sys; sys.modules['gtsam'] = None; from egnc.cli.bench import main; sys.exit(main(sys.argv[1:]))"
    run = subprocess.run(
        [sys.executable, "-c", script, "--datasets", "grid2d", "--data-dir", DATASETS, "--methods", "gtsam-lm",
         "--out", tmp_path / "out"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert run.returncode == 1
    assert run.stderr.startswith("egnc-bench: error: nothing to run") and run.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_a_grid_without_cases_is_an_error():
    with pytest.raises(EgncError, match="no case"):
        run_grid(["grid2d"], [], [1], ["l2"], data_dir=DATASETS)


def test_gtsam_gnc_tls_on_the_tiny_grid():
    pytest.importorskip("gtsam")
    (record,) = run_grid(["grid2d"], [30], [1], ["gtsam-gnc-tls"], data_dir=DATASETS, time_limit_s=120)
    assert record.status == "ok", record.status
    assert (record.precision, record.recall) == (1.0, 1.0)
    assert record.ate < 1e-3 and record.stages == -1
