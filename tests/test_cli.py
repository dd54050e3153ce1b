"""Smoke tests of `egnc-solve` through a subprocess, on the shipped and the shared g2o files."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.api import METHODS
from egnc.datasets import read_labels

DATASETS = Path(__file__).parents[1] / "datasets"
GRID2D = DATASETS / "grid2d.g2o"

# The report fields docs/cli.md documents; the CLI may add more, never fewer.
REPORT_KEYS = {
    "method", "linear_solver", "time_s", "initial_cost_all_edges", "final_cost_all_edges",
    "final_cost_accepted_edges", "truncated_cost", "start", "iterations", "status",
    "message", "converged", "poses", "edges", "loop_closures", "known_inliers", "rejected_edges",
    "stages", "timings_s",
}  # fmt: skip
PROGRESS_LINE = re.compile(
    r"^stage \d+: (mu \S+|least squares), \d+ iterations( \(iteration limit\))?, cost \S+, \d+ edges,"
    r" [\d.]+ s \(elapsed [\d.]+ s\)$"
)
STAGE_KEYS = {
    "mu_min", "mu_mean", "mu_max", "iterations", "cost", "time_s", "status", "active_edges", "cg_iterations",
    "kind", "start",
}  # fmt: skip


def egnc_solve(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `egnc-solve args...` with this interpreter, as `python -m egnc.cli.solve`."""
    return subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        timeout=300,
    )


def lsq_cost(graph: egnc.PoseGraph) -> float:
    """Least-squares cost `0.5 sum r^2` of a graph at its own poses (no solver step taken)."""
    return egnc.solve(graph, "l2", options=egnc.SolverOptions(max_iterations=0)).initial_cost


def test_solve_writes_the_same_graph_with_new_poses(tmp_path):
    out, report = tmp_path / "solved.g2o", tmp_path / "report.json"
    run = egnc_solve(GRID2D, "--method", "l2", "-o", out, "--report", report)
    assert run.returncode == 0, run.stderr
    [progress] = run.stderr.splitlines()  # least squares is one stage
    assert PROGRESS_LINE.match(progress), progress
    assert "500" in run.stdout  # the summary names the graph's size

    source, solved = egnc.read_g2o(GRID2D), egnc.read_g2o(out)
    for name in ("vertex_ids", "edges", "measurements", "information", "fixed"):
        np.testing.assert_array_equal(getattr(solved, name), getattr(source, name), err_msg=name)
    assert not np.array_equal(solved.poses, source.poses)
    # The written poses are the solution the report describes (floats are written exactly).
    content = json.loads(report.read_text())
    assert lsq_cost(solved) == pytest.approx(content["final_cost_all_edges"], rel=1e-12)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["report.json", "solved.g2o"]


def test_report_has_the_documented_fields_with_sane_values(tmp_path):
    report = tmp_path / "report.json"
    run = egnc_solve(GRID2D, "--method", "l2", "--linear-solver", "scipy", "--report", report)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert REPORT_KEYS <= content.keys()

    graph = egnc.read_g2o(GRID2D)
    assert content["method"] == "l2"
    assert content["linear_solver"] == "scipy"
    assert (content["poses"], content["edges"]) == (graph.num_poses, graph.num_edges)
    assert content["loop_closures"] == int(graph.is_loop_closure.sum()) > 0
    assert content["known_inliers"] == int(graph.is_odometry.sum())
    rejected = content["rejected_edges"]
    assert rejected == sorted(set(rejected)) and graph.is_loop_closure[rejected].all()  # never odometry
    [stage] = content["stages"]  # least squares is one stage, its kernel has no mu
    assert stage.keys() == STAGE_KEYS
    assert (stage["mu_min"], stage["mu_mean"], stage["mu_max"]) == (None, None, None)
    assert stage["iterations"] == content["iterations"]
    assert 0 < content["final_cost_all_edges"] < content["initial_cost_all_edges"]
    assert content["initial_cost_all_edges"] == pytest.approx(lsq_cost(graph), rel=1e-12)
    assert content["iterations"] >= 1
    assert content["converged"] is True
    assert content["status"] in (1, 2, 3)
    assert content["message"].startswith("converged")
    timings = content["timings_s"]
    assert timings and all(isinstance(value, float) and value >= 0 for value in timings.values())
    assert 0 < sum(timings.values()) <= content["time_s"]


@pytest.mark.parametrize(
    ("name", "linear_solver", "gtsam_optimum"),
    [
        # GTSAM 4.3 LM optima, as in tests/test_least_squares.py.
        ("intel.g2o", "auto", 273.2315612),  # 2D
        ("parking-garage.g2o", "scipy", 0.6341923996),  # 3D
    ],
)
def test_least_squares_on_shared_datasets_reaches_gtsam_optimum(
    dataset_path, tmp_path, name, linear_solver, gtsam_optimum
):
    report = tmp_path / "report.json"
    args = (dataset_path(name), "--method", "l2", "--linear-solver", linear_solver, "--report", report, "-q")
    run = egnc_solve(*args)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert content["final_cost_all_edges"] == pytest.approx(gtsam_optimum, rel=1e-8)
    assert content["converged"] is True


def test_default_method_drops_exactly_the_false_loops(tmp_path):
    graph_path = DATASETS / "grid2d_outliers.g2o"
    out, report = tmp_path / "inliers.g2o", tmp_path / "report.json"
    run = egnc_solve(graph_path, "--drop-outliers", "-o", out, "--report", report)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert content["method"] == "egnc"
    assert len(content["stages"]) > 1

    is_false, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    assert content["rejected_edges"] == np.flatnonzero(is_false).tolist()
    source, kept = egnc.read_g2o(graph_path), egnc.read_g2o(out)
    np.testing.assert_array_equal(kept.edges, source.edges[~is_false])
    np.testing.assert_array_equal(kept.measurements, source.measurements[~is_false])
    np.testing.assert_array_equal(kept.vertex_ids, source.vertex_ids)


def test_known_inliers_none_makes_every_edge_a_candidate(tmp_path):
    report = tmp_path / "report.json"
    run = egnc_solve(GRID2D, "--method", "huber", "--known-inliers", "none", "--report", report, "-q")
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert (content["method"], content["known_inliers"]) == ("huber", 0)


def test_quiet_prints_nothing(tmp_path):
    run = egnc_solve(GRID2D, "--method", "l2", "-q", "-o", tmp_path / "out.g2o")
    assert (run.returncode, run.stdout, run.stderr) == (0, "", "")
    assert (tmp_path / "out.g2o").is_file()


def test_version_is_the_package_version():
    run = egnc_solve("--version")
    assert run.returncode == 0
    assert run.stdout.strip() == f"egnc {egnc.__version__}"


def test_help_lists_every_option_and_the_examples():
    run = egnc_solve("--help")
    assert run.returncode == 0
    for option in ("--output", "--method", "--known-inliers", "--drop-outliers", "--linear-solver", "--solver",
                   "--max-iters", "--skip-unknown", "--report", "--quiet", "--version", "--information",
                   "--trajectory", "--trajectory-format", "--edges"):  # fmt: skip
        assert option in run.stdout
    assert "{" + ",".join(METHODS) + "}" in run.stdout
    assert "examples:" in run.stdout and "3 numerical failure" in run.stdout
    assert "egnc-solve datasets/grid2d_outliers.g2o -o solved.g2o" in run.stdout


def test_skip_unknown_writes_every_landmark_line_back(tmp_path):
    # A SLAM graph with landmarks: poses, then point vertices and pose-point edges egnc does not read.
    landmarks = [f"VERTEX_XY {9000 + k} {k}.5 -{k}.25" for k in range(5)]
    observations = [f"EDGE_SE2_XY {k} {9000 + k} 0.5 0.25 100 0 100" for k in range(5)]
    graph = tmp_path / "landmarks.g2o"
    graph.write_text("\n".join(landmarks) + "\n" + GRID2D.read_text() + "\n".join(observations) + "\n")
    assert egnc_solve(graph, "--method", "l2", "-q").returncode == 1
    out = tmp_path / "out.g2o"
    run = egnc_solve(graph, "--method", "l2", "-q", "--skip-unknown", "-o", out)
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        f"warning: {graph}: skipped 10 lines with tags egnc does not read (VERTEX_XY 5, EDGE_SE2_XY 5); "
        "write_g2o (egnc-solve -o) writes them back unchanged"
    ]
    written = out.read_text().splitlines()
    assert [line for line in written if not line.startswith(("VERTEX_SE2", "EDGE_SE2 ", "FIX"))] == [
        *landmarks, *observations
    ]
    np.testing.assert_array_equal(egnc.read_g2o(out, skip_unknown=True).edges, egnc.read_g2o(GRID2D).edges)


@pytest.mark.parametrize(
    "args",
    [
        (),  # no input file
        (GRID2D, "--method", "no-such-method"),
        (GRID2D, "--linear-solver", "umfpack"),
        (GRID2D, "--max-iters", "-1"),
        (GRID2D, "--max-iters", "many"),
    ],
)
def test_usage_errors_exit_2(args):
    run = egnc_solve(*args)
    assert run.returncode == 2
    assert run.stdout == ""
    assert run.stderr.startswith("usage: egnc-solve")
    assert run.stderr.splitlines()[-1].startswith("egnc-solve: error: ")


GOOD_EDGE = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
VERTICES = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
BAD_INPUTS = {
    # name: (file content, expected message after "file:line: ")
    "short_edge": (VERTICES + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", ":3: EDGE_SE2 needs 11 fields"),
    "not_a_number": (VERTICES + GOOD_EDGE.replace(" 1 0 0 1 0 0", " 1 0 0 x 0 0", 1), ":3: EDGE_SE2 field 6 is 'x'"),
    "unknown_tag": (VERTICES + "POINT 3 1 2\n" + GOOD_EDGE, ":3: unknown tag 'POINT'"),
    "not_positive_definite": (VERTICES + "EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n", ":3: information matrix is not positive"),
    "truncated": (VERTICES + GOOD_EDGE.rstrip("\n")[:-4], ":3: file looks truncated"),
    "disconnected": (VERTICES + GOOD_EDGE + GOOD_EDGE.replace("0 1 ", "5 6 ", 1), ": the pose graph is disconnected"),
    "empty": ("# nothing here\n", ": no EDGE_SE2, EDGE2 or EDGE_SE3:QUAT lines"),
    "huge_id": (VERTICES + GOOD_EDGE + f"FIX {'9' * 5000}\n", ":4: FIX field 1 is '9999"),
}


def assert_one_line_error(run: subprocess.CompletedProcess, *fragments: str) -> None:
    """Exit code 1, nothing on stdout, one `egnc-solve: error:` line holding every fragment.

    Stage progress lines may precede it when the error comes after the solve (e.g. writing).
    """
    assert run.returncode == 1, run.stderr
    assert run.stdout == ""
    lines = [line for line in run.stderr.splitlines() if not PROGRESS_LINE.match(line)]
    assert len(lines) == 1, run.stderr
    assert lines[0].startswith("egnc-solve: error: ")
    for fragment in fragments:
        assert fragment in lines[0]


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_one_line_naming_file_and_line(tmp_path, case):
    content, message = BAD_INPUTS[case]
    graph = tmp_path / f"{case}.g2o"
    graph.write_text(content)
    out, report = tmp_path / "out.g2o", tmp_path / "report.json"
    run = egnc_solve(graph, "-o", out, "--report", report, cwd=tmp_path)
    assert_one_line_error(run, f"{graph}{message}")
    assert [path.name for path in tmp_path.iterdir()] == [graph.name]


def test_missing_input_is_one_line(tmp_path):
    run = egnc_solve(tmp_path / "missing.g2o", "-o", tmp_path / "out.g2o")
    assert_one_line_error(run, f"{tmp_path / 'missing.g2o'}: cannot read file")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flag", ["-o", "--report"])
@pytest.mark.parametrize("parent", ["missing_dir", "a_file"])
def test_unwritable_output_is_one_line_and_leaves_nothing(tmp_path, flag, parent):
    (tmp_path / "a_file").write_text("not a folder\n")
    target = tmp_path / parent / "result"
    # The other output is writable: a failed run must not leave it behind either.
    other = ("--report", tmp_path / "report.json") if flag == "-o" else ("-o", tmp_path / "out.g2o")
    run = egnc_solve(GRID2D, "--method", "l2", flag, target, *other)
    assert_one_line_error(run, f"{target}: cannot write file")
    assert [path.name for path in tmp_path.iterdir()] == ["a_file"]


def test_installed_entry_point_runs():
    script = Path(sys.executable).with_name("egnc-solve")
    if not script.is_file():
        pytest.skip(f"egnc-solve is not installed beside {sys.executable}")
    run = subprocess.run([script, "--version"], capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stdout.strip()) == (0, f"egnc {egnc.__version__}")


def test_linear_method_changes_how_steps_are_solved_not_what_is_rejected(tmp_path):
    reports = {}
    for method in ("direct", "auto"):
        report = tmp_path / f"{method}.json"
        run = egnc_solve(DATASETS / "grid3d_outliers.g2o", "--linear-method", method, "--report", report, "-q")
        assert run.returncode == 0, run.stderr
        reports[method] = json.loads(report.read_text())
    assert reports["auto"]["rejected_edges"] == reports["direct"]["rejected_edges"]
    assert len(reports["auto"]["rejected_edges"]) > 0
    assert sum(stage["cg_iterations"] for stage in reports["auto"]["stages"]) > 0
    assert sum(stage["cg_iterations"] for stage in reports["direct"]["stages"]) == 0


def test_endless_input_is_refused_at_once():
    run = egnc_solve("/dev/zero")
    assert_one_line_error(run, "/dev/zero:1: line longer than 1048576 bytes")


ENDLESS_COMMENTS = """
import sys, time
written = 0
while True:
    sys.stdout.write("# endless\\n" * 10000)
    sys.stdout.flush()
    written += 100000
    if written == 2_000_000:
        print("flowing", file=sys.stderr, flush=True)  # far more than a pipe holds: the reader reads
    time.sleep(0.01)
"""


def test_sigterm_ends_a_read_of_endless_input():
    producer = subprocess.Popen(
        [sys.executable, "-c", ENDLESS_COMMENTS], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert producer.stdout is not None and producer.stderr is not None
    solver = subprocess.Popen(
        [sys.executable, "-m", "egnc.cli.solve", "/dev/stdin"], stdin=producer.stdout, stderr=subprocess.PIPE, text=True
    )
    producer.stdout.close()
    try:
        assert producer.stderr.readline().strip() == "flowing"
        solver.send_signal(signal.SIGTERM)
        _, stderr = solver.communicate(timeout=60)  # before issue 19 the read ignored SIGTERM
    finally:
        solver.kill()
        producer.kill()
        producer.wait()
    assert solver.returncode == 143, stderr
    assert stderr.strip() == "egnc-solve: terminated (SIGTERM); no output written"


def test_every_option_is_in_the_options_table_of_docs_cli():
    """docs/cli.md says it lists every option; the --online ones were missing from it."""
    from egnc.cli.solve import build_parser

    docs = (Path(__file__).parents[1] / "docs" / "cli.md").read_text(encoding="utf-8")
    table = docs.split("\n## Options\n", 1)[1].split("\n## ", 1)[0]
    first_cells = [row.split("|")[1] for row in table.splitlines() if row.startswith("| `")]
    documented = {option for cell in first_cells for option in re.findall(r"`(-[-\w]+)", cell)}
    options = {option for action in build_parser()._actions for option in action.option_strings}
    assert sorted(options - documented) == []
