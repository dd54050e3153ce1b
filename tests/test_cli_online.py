"""`egnc-solve` on IRL logs, in batch and with `--online`, through a subprocess."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.datasets import read_labels
from egnc.io import IrlLog, read_irl, write_irl
from egnc.metrics import precision_recall

DATASETS = Path(__file__).parents[1] / "datasets"
ONLINE_KEYS = {"steps", "resumed_from", "total_s", "iterations", "update_ms"}


def egnc_solve(*args: str | Path) -> subprocess.CompletedProcess:
    """Run `egnc-solve args...` with this interpreter."""
    return subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", *map(str, args)],
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        timeout=300,
    )


def rejected_mask(report: Path, num_edges: int) -> np.ndarray:
    mask = np.zeros(num_edges, dtype=bool)
    mask[json.loads(report.read_text())["rejected_edges"]] = True
    return mask


@pytest.fixture(scope="module")
def grid_log(tmp_path_factory) -> tuple[Path, IrlLog]:
    """`grid2d_outliers.g2o` written as an IRL log with its labels (in a temporary folder)."""
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    labels, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    path = tmp_path_factory.mktemp("irl") / "grid2d_outliers.irl"
    write_irl(IrlLog.from_graph(graph, labels, date="2026-11-25"), path)
    return path, read_irl(path)


def test_batch_solve_of_riSAMs_manhattan_log(dataset_path, tmp_path):
    path = dataset_path("manhattan_noisy.irl")
    log = read_irl(path)
    report = tmp_path / "report.json"
    run = egnc_solve(path, "--report", report, "-o", tmp_path / "out.g2o", "-q")
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert content["edges"] == log.num_edges and "online" not in content
    assert content["known_inliers"] == int(log.is_odometry.sum())  # the ODOMETRY entries
    precision, recall = precision_recall(rejected_mask(report, log.num_edges), log.is_outlier)
    assert precision == 1.0 and recall == 1.0
    assert egnc.read_g2o(tmp_path / "out.g2o").num_edges == log.num_edges


def test_an_irl_log_is_recognised_by_its_header_whatever_its_name(grid_log, tmp_path):
    path, log = grid_log
    renamed = tmp_path / "log.txt"
    renamed.write_bytes(path.read_bytes())
    report = tmp_path / "report.json"
    run = egnc_solve(renamed, "--report", report, "-q")
    assert run.returncode == 0, run.stderr
    assert precision_recall(rejected_mask(report, log.num_edges), log.is_outlier) == (1.0, 1.0)


def test_online_replay_of_a_log_reports_latency_and_the_final_decision(grid_log, tmp_path):
    path, log = grid_log
    report, trajectory, edges = tmp_path / "report.json", tmp_path / "t.tum", tmp_path / "e.csv"
    run = egnc_solve(path, "--online", "--report", report, "--trajectory", trajectory, "--edges", edges)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    online = content["online"]
    assert set(online) == ONLINE_KEYS
    assert online["steps"] == log.graph.num_poses - 1  # one update per pose after the prior's
    latency = online["update_ms"]
    assert 0.0 < latency["p50"] <= latency["p99"] <= latency["max"] <= 1e3 * online["total_s"]
    assert online["iterations"] > 0 and online["resumed_from"] == 0
    assert precision_recall(rejected_mask(report, log.num_edges), log.is_outlier) == (1.0, 1.0)
    assert "online:" in run.stdout and "step " in run.stderr
    assert len(trajectory.read_text().splitlines()) == log.graph.num_poses
    assert len(edges.read_text().splitlines()) == log.num_edges + 1


def test_online_replay_of_a_g2o_file_keeps_file_edge_order(tmp_path):
    graph = egnc.read_g2o(DATASETS / "grid3d_outliers.g2o")
    labels, _ = read_labels(DATASETS / "grid3d_outliers.labels.json")
    report = tmp_path / "report.json"
    run = egnc_solve(DATASETS / "grid3d_outliers.g2o", "--online", "--method", "risam", "--report", report, "-q")
    assert run.returncode == 0, run.stderr
    assert run.stdout == "" and json.loads(report.read_text())["method"] == "risam"
    assert precision_recall(rejected_mask(report, graph.num_edges), labels) == (1.0, 1.0)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--online", "--method", "gnc-gm"], "--online replays"),
        (["--checkpoint", "x.npz"], "add --online"),
        (["--online", "--checkpoint-every", "5"], "add --checkpoint"),
        (["--region-hops", "4"], "add --online"),
        (["--boundary-share", "0.01"], "add --online"),
        (["--decide-at-arrival"], "--decide-at-arrival"),
        (["--online", "--method", "risam", "--decide-at-arrival"], "--decide-at-arrival"),
        (["--online", "--init", "chordal"], "--init does not apply"),
    ],
)
def test_options_that_cannot_apply_are_refused(options, message):
    run = egnc_solve(DATASETS / "grid2d.g2o", *options)
    assert run.returncode == 1 and message in run.stderr


def test_region_hops_zero_solves_every_loop_update_on_the_whole_map(tmp_path):
    reports = {}
    for hops in ("0", "8"):
        reports[hops] = tmp_path / f"hops{hops}.json"
        run = egnc_solve(
            DATASETS / "grid2d_outliers.g2o", "--online", "--region-hops", hops, "--report", reports[hops], "-q"
        )
        assert run.returncode == 0, run.stderr
    whole, local = (json.loads(reports[hops].read_text()) for hops in ("0", "8"))
    assert whole["rejected_edges"] == local["rejected_edges"]
    # Every loop update of the whole map takes its steps over all poses; regions take others too.
    assert whole["online"]["iterations"] != local["online"]["iterations"]


def test_decide_at_arrival_makes_the_same_decision_with_fewer_iterations(tmp_path):
    reports = {flag: tmp_path / f"{bool(flag)}.json" for flag in ("", "--decide-at-arrival")}
    for flag, report in reports.items():
        run = egnc_solve(DATASETS / "grid2d_outliers.g2o", "--online", *filter(None, [flag]), "--report", report, "-q")
        assert run.returncode == 0, run.stderr
    solved, decided = (json.loads(report.read_text()) for report in reports.values())
    assert decided["rejected_edges"] == solved["rejected_edges"]
    assert decided["online"]["iterations"] < 0.9 * solved["online"]["iterations"]


def _run_until(args: list[str | Path], kill_at_step: int) -> int:
    """Start `egnc-solve args`, SIGKILL it once its progress reports step `kill_at_step` or later; its exit code."""
    process = subprocess.Popen(
        [sys.executable, "-m", "egnc.cli.solve", *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    assert process.stderr is not None
    for line in process.stderr:
        if line.startswith("step ") and int(line.split()[1].split("/")[0]) >= kill_at_step:
            process.kill()
            break
    process.stderr.close()
    return process.wait(timeout=300)


@pytest.mark.parametrize("extra", [[], ["--decide-at-arrival"]])
def test_a_killed_replay_resumes_to_the_uninterrupted_result(tmp_path, extra):
    source = DATASETS / "grid2d_outliers.g2o"
    whole_out, whole_report = tmp_path / "whole.g2o", tmp_path / "whole.json"
    run = egnc_solve(source, "--online", *extra, "-o", whole_out, "--report", whole_report, "-q")
    assert run.returncode == 0, run.stderr

    checkpoint, out, report = tmp_path / "run.ckpt", tmp_path / "out.g2o", tmp_path / "report.json"
    args = [source, "--online", *extra, "-o", out, "--report", report, "--checkpoint", checkpoint]
    args += ["--checkpoint-every", "20"]
    # Progress lines come every tenth of the 499 steps: kill after the 2nd, then (resumed) the 6th.
    assert _run_until(args, 98) == -9 and checkpoint.exists() and not out.exists()
    assert _run_until(args, 294) == -9 and not out.exists()
    run = egnc_solve(*args)
    assert run.returncode == 0, run.stderr
    online = json.loads(report.read_text())["online"]
    assert 280 <= online["resumed_from"] < 499 and online["steps"] == 499
    np.testing.assert_allclose(egnc.read_g2o(out).poses, egnc.read_g2o(whole_out).poses, atol=1e-9, rtol=0)
    assert json.loads(report.read_text())["rejected_edges"] == json.loads(whole_report.read_text())["rejected_edges"]
    assert online["iterations"] == json.loads(whole_report.read_text())["online"]["iterations"]


LOOP_FIRST_G2O = (
    "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
    "EDGE_SE2 0 2 2 0 0 1 0 0 1 0 1\nEDGE_SE2 2 1 -1 0 0 1 0 0 1 0 1\n"
)
_COVARIANCE = "1 0 0 0 1 0 0 0 1"
PRIOR_LATER_IRL = (
    f"t\n2024-01-01\n2\nnonlinear\n\nPRIOR 1 0 2 0 0 0 {_COVARIANCE}\n"
    f"ODOMETRY 1 0 0 1 1 0 0 {_COVARIANCE}\nODOMETRY 1 0 1 2 1 0 0 {_COVARIANCE}\n"
)


@pytest.mark.parametrize(("name", "text"), [("loop_first.g2o", LOOP_FIRST_G2O), ("prior_later.irl", PRIOR_LATER_IRL)])
def test_online_replays_what_the_batch_solver_accepts(tmp_path, name, text):
    # A pose first reached by a loop closure, a prior on a later pose: found by the files fuzzer.
    path = tmp_path / name
    path.write_text(text)
    outputs = {}
    for mode in ([], ["--online"]):
        out = tmp_path / f"out{len(mode)}.g2o"
        run = egnc_solve(path, *mode, "-o", out, "-q")
        assert run.returncode == 0, run.stderr
        outputs[len(mode)] = egnc.read_g2o(out).poses
    np.testing.assert_allclose(outputs[1], outputs[0], atol=1e-9)
