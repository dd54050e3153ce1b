"""`egnc-solve` outputs and failures: paths that would destroy data, all-or-nothing writing, stale
temporaries, interruptions, numerical failures, strict JSON, and the ecosystem outputs
(`--trajectory`, `--edges`), all through a subprocess."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from test_cli import DATASETS, GRID2D, assert_one_line_error, egnc_solve

import egnc
from egnc.datasets import read_labels
from egnc.lie import se3

GRID3D = DATASETS / "grid3d.g2o"


def run_with_stub(stub: str, *args: str | Path) -> subprocess.Popen:
    """Start `egnc-solve args...` in a child whose `egnc.cli` module `cli` was changed by `stub` first."""
    script = (
        "import sys\nimport egnc.cli.solve as cli\n" + textwrap.dedent(stub) + "\nsys.exit(cli.main(sys.argv[1:]))\n"
    )
    return subprocess.Popen(
        [sys.executable, "-c", script, *map(str, args)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def finish(process: subprocess.Popen) -> subprocess.CompletedProcess:
    """Wait for a child of `run_with_stub` and return what it did."""
    stdout, stderr = process.communicate(timeout=120)
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


# --- Output paths that would destroy data are refused before reading --------------------------------


def test_output_that_is_the_input_is_refused_before_reading(tmp_path):
    graph = tmp_path / "graph.g2o"
    graph.write_text("this is not a g2o file\n")  # a parse error would come first if it were read
    for option in ("-o", "--report", "--trajectory", "--edges"):
        run = egnc_solve(graph, option, graph, "--trajectory-format", "tum")
        assert_one_line_error(run, f"{graph}: {option} names the input file")
    link = tmp_path / "link.g2o"
    link.symlink_to(graph)
    assert_one_line_error(egnc_solve(graph, "-o", link), "names the input file")
    assert graph.read_text() == "this is not a g2o file\n"


def test_two_outputs_on_one_path_are_refused(tmp_path):
    same = tmp_path / "x"
    run = egnc_solve(GRID2D, "-o", same, "--report", tmp_path / "." / "x")
    assert_one_line_error(run, "given to both -o and --report")
    assert list(tmp_path.iterdir()) == []


def test_missing_output_directory_fails_before_the_solve_and_keeps_old_files(tmp_path):
    out = tmp_path / "out.g2o"
    out.write_text("old\n")
    run = run_with_stub(
        "cli.solve = lambda *a, **k: sys.exit('solve was called')", GRID2D, "-o", out, "--report", "/nonexistent/r.json"
    )
    assert_one_line_error(finish(run), "/nonexistent/r.json: cannot write file: directory /nonexistent does not exist")
    assert out.read_text() == "old\n"


FAILING_LAST_OUTPUT = """
import egnc.cli.outputs as outputs
from egnc.errors import EgncError
def failing(*args, **kwargs):
    raise EgncError("edges.csv: cannot write file: disk full")
outputs.write_edges_csv = failing
"""


def test_failure_in_a_later_output_leaves_every_previous_file_untouched(tmp_path):
    out, report, edges = tmp_path / "out.g2o", tmp_path / "report.json", tmp_path / "edges.csv"
    out.write_text("old graph\n")
    report.write_text("old report\n")
    # The edges CSV is written after the graph and the report.
    args = ("--method", "l2", "-q", "-o", out, "--report", report, "--edges", edges)
    run = run_with_stub(FAILING_LAST_OUTPUT, GRID2D, *args)
    assert_one_line_error(finish(run), "edges.csv: cannot write file: disk full")
    assert (out.read_text(), report.read_text()) == ("old graph\n", "old report\n")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out.g2o", "report.json"]


def test_unknown_figure_format_is_refused_before_reading(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "out.g2o"
    run = egnc_solve(tmp_path / "not_read.g2o", "-o", out, "--plot", tmp_path / "t.xyz")
    assert_one_line_error(run, "t.xyz: cannot write figures as 'xyz'")
    assert list(tmp_path.iterdir()) == []


def test_stale_temporaries_of_dead_runs_are_removed(tmp_path):
    out = tmp_path / "out.g2o"
    dead = tmp_path / ".out.g2o.999999999.deadbeef.tmp"  # above any pid_max: that process cannot exist
    alive = tmp_path / f".out.g2o.{os.getpid()}.cafe0123.tmp"  # this test's own process is running
    other = tmp_path / ".other.g2o.999999999.deadbeef.tmp"  # belongs to another output
    for path in (dead, alive, other):
        path.write_text("half-written\n")
    assert egnc_solve(GRID2D, "--method", "l2", "-q", "-o", out).returncode == 0
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted([out.name, alive.name, other.name])


# --- Interruptions -----------------------------------------------------------------------------------

SLOW_SOLVE = """
import time
def slow(*args, **kwargs):
    print("solving", file=sys.stderr, flush=True)
    time.sleep(60)
cli.solve = slow
"""

SLOW_LAST_OUTPUT = """
import time
import egnc.cli.outputs as outputs
def slow(*args, **kwargs):
    print("writing", file=sys.stderr, flush=True)
    time.sleep(60)
outputs.write_edges_csv = slow
"""


def wait_for_line(process: subprocess.Popen, expected: str) -> None:
    """Read the child's stderr until the stub's marker line arrives."""
    assert process.stderr is not None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if process.stderr.readline().strip() == expected:
            return
    raise AssertionError(f"no {expected!r} line from the child")


@pytest.mark.parametrize(
    ("signum", "code", "word"), [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]
)
@pytest.mark.parametrize(
    ("stub", "marker"), [(SLOW_SOLVE, "solving"), (SLOW_LAST_OUTPUT, "writing")], ids=["solve", "write"]
)
def test_interruption_is_one_line_and_leaves_no_file(tmp_path, signum, code, word, stub, marker):
    out, report, edges = tmp_path / "out.g2o", tmp_path / "report.json", tmp_path / "edges.csv"
    out.write_text("old\n")
    process = run_with_stub(stub, GRID2D, "--method", "l2", "-q", "-o", out, "--report", report, "--edges", edges)
    wait_for_line(process, marker)
    process.send_signal(signum)
    run = finish(process)
    assert run.returncode == code
    assert run.stdout == ""
    assert run.stderr.splitlines() == [f"egnc-solve: {word} ({signal.Signals(signum).name}); no output written"]
    assert [path.name for path in tmp_path.iterdir()] == ["out.g2o"]  # no temporaries, no new file
    assert out.read_text() == "old\n"


# --- Numerical failures: exit 3, one line, no output --------------------------------------------------

MARKED_FAILURE = """
import dataclasses
real_solve = cli.solve
def failing(*args, **kwargs):
    result = real_solve(*args, **kwargs)
    return dataclasses.replace(result, status=5, message="numerical failure: the cost became non-finite")
cli.solve = failing
"""

RAISED_FAILURE = """
from egnc.errors import NumericalError
def failing(*args, **kwargs):
    raise NumericalError("pose 7 is 1e+300 m from the origin: a double cannot hold its differences")
cli.solve = failing
"""

NON_FINITE_POSES = """
real_solve = cli.solve
def failing(*args, **kwargs):
    result = real_solve(*args, **kwargs)
    return result.__class__(**{**result.__dict__, "graph": result.graph.with_poses(result.graph.poses * float("nan"))})
cli.solve = failing
"""


@pytest.mark.parametrize(
    ("stub", "fragment"),
    [
        (MARKED_FAILURE, "the cost became non-finite"),
        (RAISED_FAILURE, "a double cannot hold"),
        (NON_FINITE_POSES, "the solution holds non-finite numbers"),
    ],
    ids=["status-5", "NumericalError", "nan-poses"],
)
def test_numerical_failure_exits_3_in_one_line_without_output(tmp_path, stub, fragment):
    run = finish(
        run_with_stub(stub, GRID2D, "--method", "l2", "-q", "-o", tmp_path / "out.g2o", "--report", tmp_path / "r.json")
    )
    assert run.returncode == 3, run.stderr
    assert run.stdout == ""
    [line] = run.stderr.splitlines()
    assert line.startswith("egnc-solve: numerical failure: ") and fragment in line
    assert list(tmp_path.iterdir()) == []


FAR_POSE = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1e20 0 0\nEDGE_SE2 0 1 1 0 0 100 0 0 100 0 100\n"
"""An edge whose 0.1 m standard deviation a double cannot hold at x = 1e20 m (line 3)."""


FAR_STEP = (
    "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 0 1e20 0 0 100 0 0 100 0 100\n"
)
"""Replayed, the second odometry edge (line 4, a duplicate: one warning) measures a step of 1e20 m to 0.1 m."""

UNREPRESENTABLE = {
    "batch": (FAR_POSE, [], 3),
    "batch-with-warning": (FAR_POSE.replace("\nEDGE", "\nVERTEX_SE2 5 0 0 0\nEDGE"), [], 4),  # 5 is untouched
    "online-with-warning": (FAR_STEP, ["--online"], 4),
}


@pytest.mark.parametrize("case", sorted(UNREPRESENTABLE))
def test_unrepresentable_edge_is_one_line_naming_file_and_line(tmp_path, case):
    """Issue 56: the failure named no file, and a warning (the untouched vertex 5, the duplicate
    edge) came before it: a failure is one line."""
    text, options, line = UNREPRESENTABLE[case]
    graph = tmp_path / "far.g2o"
    graph.write_text(text)
    run = egnc_solve(graph, "-o", tmp_path / "out.g2o", "-q", *options)
    assert run.returncode == 3, run.stderr
    assert run.stderr.startswith(f"egnc-solve: numerical failure: {graph}:{line}: "), run.stderr
    assert "cannot be represented in double precision" in run.stderr
    assert len(run.stderr.splitlines()) == 1, run.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["far.g2o"]


def test_odometry_that_does_not_reach_every_pose_names_the_file(tmp_path):
    graph = tmp_path / "o.g2o"
    graph.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
        "EDGE_SE2 0 2 2 0 0 1 0 0 1 0 1\nEDGE_SE2 2 1 -1 0 0 1 0 0 1 0 1\n"
    )
    run = egnc_solve(graph, "--init", "odometry", "-q")
    assert_one_line_error(run, f"egnc-solve: error: {graph}: init 'odometry': cannot initialize")


REPLAY_ERROR = """
from egnc.errors import EgncError
def failing(*args, **kwargs):
    raise EgncError("the replay did not take in every pose of the graph")
cli.replay = failing
"""


@pytest.mark.parametrize("resumed", [False, True])
def test_replay_errors_name_the_input_and_the_checkpoint_resumed_from(tmp_path, resumed):
    """Issue 56: a replay's own errors named no file; after a resume the checkpoint may be at fault."""
    checkpoint = tmp_path / "run.npz"
    if resumed:
        checkpoint.write_bytes(b"a checkpoint")  # the stub never reads it
    run = finish(run_with_stub(REPLAY_ERROR, GRID2D, "--online", "-q", "--checkpoint", checkpoint))
    tail = f" (resumed from the checkpoint {checkpoint})" if resumed else ""
    expected = f"egnc-solve: error: {GRID2D}: the replay did not take in every pose of the graph{tail}"
    assert (run.returncode, run.stderr.splitlines()) == (1, [expected])


# --- Strict JSON, warnings, honest summary --------------------------------------------------------------

INFINITE_INITIAL_COST = """
import dataclasses
real_solve = cli.solve
def with_warnings(*args, **kwargs):
    result = real_solve(*args, **kwargs)
    return dataclasses.replace(result, initial_cost=float("inf"), warnings=("most loop closures were rejected",))
cli.solve = with_warnings
"""


def reject_constants(name: str) -> None:
    raise AssertionError(f"{name} is not JSON")


def test_report_is_strict_json_with_nulls_and_warnings(tmp_path):
    report = tmp_path / "report.json"
    run = finish(run_with_stub(INFINITE_INITIAL_COST, GRID2D, "--method", "l2", "--report", report))
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text(), parse_constant=reject_constants)
    assert content["initial_cost_all_edges"] is None
    assert content["initial_cost"] is None  # its deprecated name, written as null too but named once below
    assert content["warnings"] == [
        "most loop closures were rejected",
        "report field initial_cost_all_edges is inf, written as null",
    ]
    warning_lines = [line for line in run.stderr.splitlines() if line.startswith("warning: ")]
    assert warning_lines == [f"warning: {note}" for note in content["warnings"]]


def test_summary_says_iteration_limit_not_converged(tmp_path):
    run = egnc_solve(GRID2D, "--method", "l2", "--max-iters", "1", "-o", tmp_path / "out.g2o")
    assert run.returncode == 0, run.stderr
    assert "iteration limit reached in stage 1" in run.stdout
    assert "converged" not in run.stdout
    assert f"wrote {tmp_path / 'out.g2o'}" in run.stdout


def test_summary_and_report_name_the_edges_each_cost_sums_over(tmp_path):
    """The summary's cost leaves the rejected loops out, `Result.cost` does not: both say so."""
    report = tmp_path / "report.json"
    run = egnc_solve(DATASETS / "grid2d_outliers.g2o", "--report", report)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    accepted = content["edges"] - len(content["rejected_edges"])
    [line] = [line for line in run.stdout.splitlines() if line.startswith("least-squares cost")]
    assert line == (
        f"least-squares cost {content['final_cost_accepted_edges']:.10g} over the {accepted} accepted edges"
        f" ({content['final_cost_all_edges']:.10g} over all {content['edges']} edges, rejected ones included)"
    )
    assert content["final_cost_accepted_edges"] < content["final_cost_all_edges"]  # the rejected loops are left out
    result = egnc.solve(str(DATASETS / "grid2d_outliers.g2o"))
    assert content["final_cost_all_edges"] == pytest.approx(result.cost, rel=1e-9)


# --- Input repairs and edge roles from the command line ---------------------------------------------------

VERTICES = "".join(f"VERTEX_SE2 {k} {k}.0 0 0\n" for k in range(4))
EDGES = "".join(f"EDGE_SE2 {k} {k + 1} 1 0 0 1 0 0 1 0 1\n" for k in range(3))
INDEFINITE_LOOP = "EDGE_SE2 3 0 -3 0 0 1 0 0 1 2 1\n"


def test_information_flag_repairs_and_the_error_names_it(tmp_path):
    graph = tmp_path / "g.g2o"
    graph.write_text(VERTICES + EDGES + INDEFINITE_LOOP)
    assert_one_line_error(egnc_solve(graph), f"{graph}:8: information matrix is not positive definite", "--information")
    run = egnc_solve(graph, "--information", "nearest-pd", "--method", "l2", "-q")
    assert run.returncode == 0, run.stderr
    assert run.stderr.startswith(f"warning: {graph}: repaired 1 of 4 information matrices")


def test_vertices_without_edges_are_written_back_unchanged(tmp_path):
    graph, out = tmp_path / "kimera.g2o", tmp_path / "out.g2o"
    loose = ["VERTEX_SE2 1000 5.5 6.5 0.25", "VERTEX_SE2 1001 -1.0 2.0 3.0", "VERTEX_SE2 1002 0.0 0.0 -1.5"]
    graph.write_text(GRID2D.read_text() + "\n".join(loose) + "\n")
    run = egnc_solve(graph, "-q", "-o", out)
    assert run.returncode == 0, run.stderr
    assert "3 vertices that no edge touches are kept unchanged and not optimized: {1000..1002}" in run.stderr
    written = out.read_text().splitlines()
    assert all(line in written for line in loose)
    solved, source = egnc.read_g2o(out), egnc.read_g2o(GRID2D)
    assert not np.array_equal(solved.poses[:-3], source.poses)  # the rest was optimized


def test_duplicate_edges_are_counted_in_one_warning(tmp_path):
    graph = tmp_path / "g.g2o"
    reversed_first = "EDGE_SE2 1 0 -1 0 0 1 0 0 1 0 1\n"
    graph.write_text(VERTICES + EDGES + reversed_first + EDGES.splitlines()[2] + "\n")
    run = egnc_solve(graph, "--method", "l2", "-q")
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        f"warning: {graph}: 2 duplicate edges (the same two vertices as an earlier edge, in either direction); "
        "all are kept and solved"
    ]


def test_known_inliers_from_an_index_file_and_from_labels(tmp_path):
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    is_false, _ = read_labels(DATASETS / "grid2d_outliers.labels.json")
    chosen = np.flatnonzero(graph.is_odometry)[:10]
    indices = tmp_path / "inliers.txt"
    indices.write_text(
        "# ten odometry edges\n" + " ".join(map(str, chosen[:5])) + "\n" + "\n".join(map(str, chosen[5:]))
    )
    report = tmp_path / "r.json"
    run = egnc_solve(
        DATASETS / "grid2d_outliers.g2o", "--known-inliers", indices, "--method", "l2", "-q", "--report", report
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(report.read_text())["known_inliers"] == 10

    labels = DATASETS / "grid2d_outliers.labels.json"
    run = egnc_solve(DATASETS / "grid2d_outliers.g2o", "--known-inliers", labels, "-q", "--report", report)
    assert run.returncode == 0, run.stderr
    content = json.loads(report.read_text())
    assert content["known_inliers"] == int((~is_false).sum())
    assert set(content["rejected_edges"]) <= set(np.flatnonzero(is_false).tolist())  # only the listed ones can go


def test_bad_known_inliers_file_names_file_and_line(tmp_path):
    indices = tmp_path / "inliers.txt"
    indices.write_text("1 2\n3 99999\n")
    assert_one_line_error(egnc_solve(GRID2D, "--known-inliers", indices), f"{indices}:2: '99999' is not an edge index")


# --- Trajectories and the edge table ------------------------------------------------------------------------


def test_tum_trajectory_runs_through_evo_ape(tmp_path):
    pytest.importorskip("evo")
    evo_ape = shutil.which("evo_ape", path=str(Path(sys.executable).parent)) or shutil.which("evo_ape")
    if evo_ape is None:
        pytest.skip("evo is importable but its evo_ape command is not installed")
    reference, estimate = tmp_path / "ref.tum", tmp_path / "est.tum"
    assert egnc_solve(GRID2D, "--method", "l2", "-q", "--max-iters", "0", "--trajectory", reference).returncode == 0
    assert egnc_solve(GRID2D, "--method", "l2", "-q", "--trajectory", estimate).returncode == 0
    run = subprocess.run([evo_ape, "tum", reference, estimate], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "rmse" in run.stdout

    from evo.tools import file_interface

    trajectory = file_interface.read_tum_trajectory_file(str(estimate))
    solved = egnc.solve(GRID2D, "l2")
    np.testing.assert_array_equal(trajectory.timestamps, solved.graph.vertex_ids)
    np.testing.assert_allclose(trajectory.positions_xyz[:, :2], solved.graph.poses[:, :2], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(trajectory.positions_xyz[:, 2], 0.0)


def test_kitti_trajectory_holds_the_pose_matrices(tmp_path):
    out = tmp_path / "poses.txt"
    run = egnc_solve(
        GRID3D, "--method", "l2", "-q", "--max-iters", "0", "--trajectory", out, "--trajectory-format", "kitti"
    )
    assert run.returncode == 0, run.stderr
    rows = np.loadtxt(out)
    graph = egnc.read_g2o(GRID3D)
    np.testing.assert_allclose(rows, se3.from_xyz_quat(graph.poses)[:, :3, :].reshape(-1, 12), atol=1e-12)


def test_trajectory_suffix_txt_needs_a_format(tmp_path):
    assert_one_line_error(egnc_solve(GRID2D, "--trajectory", tmp_path / "t.txt"), "--trajectory-format")


def test_edges_csv_matches_the_report(tmp_path):
    edges, report = tmp_path / "edges.csv", tmp_path / "r.json"
    run = egnc_solve(DATASETS / "grid2d_outliers.g2o", "-q", "--edges", edges, "--report", report)
    assert run.returncode == 0, run.stderr
    with edges.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == ["index", "i", "j", "kind", "r", "weight", "mu", "inlier"]
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    assert [int(row["index"]) for row in rows] == list(range(graph.num_edges))
    ids = graph.vertex_ids[graph.edges]
    assert [(int(row["i"]), int(row["j"])) for row in rows] == [tuple(pair) for pair in ids.tolist()]
    rejected = [int(row["index"]) for row in rows if row["inlier"] == "false"]
    assert rejected == json.loads(report.read_text())["rejected_edges"]
    kinds = np.array([row["kind"] for row in rows])
    np.testing.assert_array_equal(kinds == "odometry", graph.is_odometry)
    assert set(kinds) == {"odometry", "loop"}
    assert all(row["mu"] == "" for row in rows if row["kind"] == "odometry")  # no kernel on known inliers
