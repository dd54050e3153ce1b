"""API misuse and graphs with nothing to optimize give one clear error or warning (issue 19).

Before, a dict as `options`, swapped option classes, `write_g2o` with its arguments swapped and
`marginal_covariances(None)` escaped as AttributeError from inside the library, and a graph
whose poses were all fixed ended in an IndexError traceback on every method and backend.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc.api import METHODS, marginal_covariances, solve
from egnc.errors import OptionError, OptionTypeError
from egnc.io import read_g2o, read_irl, write_g2o, write_irl
from egnc.linalg.linear_solvers import cholmod_available, rslab_available
from egnc.nonlinear.least_squares import NOTHING_TO_OPTIMIZE

GRID2D = Path(__file__).parents[1] / "datasets" / "grid2d.g2o"
BACKENDS = [
    "scipy",
    pytest.param("cholmod", marks=pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")),
    pytest.param("rslab", marks=pytest.mark.skipif(not rslab_available(), reason="no rslab")),
]
TWO_POSES_ALL_FIXED = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0.5\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nFIX 0 1\n"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(options={}), "options must be a SolverOptions, got dict"),
        (dict(options=egnc.GncOptions()), "options must be a SolverOptions, got GncOptions"),
        (dict(gnc_options=egnc.SolverOptions()), "gnc_options must be a GncOptions, got SolverOptions"),
        (dict(gnc_options={"c": 3.0}), "gnc_options must be a GncOptions"),
        (dict(method=None), "unknown method None"),
        (dict(init=1), "unknown init 1"),
        (dict(on_stage="print"), "on_stage must be callable"),
        (dict(on_iteration=3), "on_iteration must be callable"),
    ],
)
def test_wrong_arguments_to_solve_name_the_argument(kwargs, match):
    with pytest.raises(OptionError, match=match):
        solve(GRID2D, **kwargs)


def test_graph_of_the_wrong_type_is_named():
    with pytest.raises(OptionTypeError, match="graph must be a PoseGraph or a g2o file path, got int"):
        solve(42)  # type: ignore[arg-type]


def test_swapped_and_wrong_io_arguments_are_named(tmp_path):
    graph = read_g2o(GRID2D)
    with pytest.raises(OptionTypeError, match="graph must be a PoseGraph, got str"):
        write_g2o("x.g2o", graph)  # type: ignore[arg-type]
    assert not (tmp_path / "x.g2o").exists() and not Path("x.g2o").exists()
    with pytest.raises(OptionTypeError, match="path must be a g2o file path"):
        read_g2o(graph)  # type: ignore[arg-type]
    with pytest.raises(OptionTypeError, match="skip_unknown must be True or False"):
        read_g2o(GRID2D, skip_unknown="yes")  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="unknown information 'repair'"):
        read_g2o(GRID2D, information="repair")  # type: ignore[arg-type]
    with pytest.raises(OptionTypeError, match="path must be an IRL file path"):
        read_irl(None)  # type: ignore[arg-type]
    with pytest.raises(OptionTypeError, match="log must be an IrlLog, got PoseGraph"):
        write_irl(graph, tmp_path / "x.irl")  # type: ignore[arg-type]


def test_marginal_covariances_of_not_a_result_is_named():
    with pytest.raises(OptionTypeError, match="result must be a Result, got NoneType"):
        marginal_covariances(None)  # type: ignore[arg-type]


@pytest.fixture
def all_fixed(tmp_path: Path) -> Path:
    path = tmp_path / "fixed.g2o"
    path.write_text(TWO_POSES_ALL_FIXED)
    return path


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_every_pose_fixed_returns_the_graph_unchanged_with_a_warning(all_fixed, method, backend):
    graph = read_g2o(all_fixed)
    result = solve(graph, method, linear_solver=backend, init="chordal")
    np.testing.assert_array_equal(result.graph.poses, graph.poses)
    assert result.status == NOTHING_TO_OPTIMIZE and not result.converged
    assert result.iterations == 0 and result.stages == ()
    assert result.inliers.all() and result.cost == result.initial_cost > 0
    assert any("nothing to optimize" in warning for warning in result.warnings)
    assert marginal_covariances(result).shape == (2, 3, 3) and not marginal_covariances(result).any()


def test_every_pose_fixed_from_the_cli_writes_the_graph_unchanged(all_fixed, tmp_path):
    out, report = tmp_path / "out.g2o", tmp_path / "report.json"
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", str(all_fixed), "-o", str(out), "--report", str(report)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    assert "warning: all 2 poses are fixed: there is nothing to optimize" in run.stderr
    written = read_g2o(out)
    original = read_g2o(all_fixed)
    np.testing.assert_array_equal(written.poses, original.poses)
    np.testing.assert_array_equal(written.fixed, [True, True])
    np.testing.assert_array_equal(written.measurements, original.measurements)


@pytest.mark.parametrize("ids", [["a"], [[0, 1], [2]], [1.5], "x", [[0]]])
def test_marginal_covariances_ids_that_are_not_vertex_ids_are_named(ids):
    result = solve(GRID2D, "l2")
    with pytest.raises(OptionError, match="^ids must be a vertex id or a 1-D sequence of them"):
        marginal_covariances(result, ids)
    assert marginal_covariances(result, np.int64(3)).shape == (1, 3, 3)


def test_marginal_covariances_ids_outside_int64_are_refused_not_wrapped():
    """Issue 56: uint64 `2**64 - 1` became id -1 and returned that vertex's covariance."""
    graph = egnc.PoseGraph(2, [-1, 0], np.zeros((2, 3)), [[0, 1]], [[1.0, 0.0, 0.0]], [np.eye(3)])
    result = solve(graph, "l2")
    for ids in (np.array([2**64 - 1], dtype=np.uint64), [2**63], np.uint64(2**63)):
        with pytest.raises(OptionError, match=r"^ids: \d+ is outside int64"):
            marginal_covariances(result, ids)
    for ids in ([-(2**63) - 1], [0, 2**70]):  # Python ints beyond 64 bits: NumPy holds them as objects
        with pytest.raises(OptionError, match="^ids"):
            marginal_covariances(result, ids)
    assert marginal_covariances(result, np.array([0], dtype=np.uint64)).shape == (1, 3, 3)
    assert marginal_covariances(result, [-1]).shape == (1, 3, 3)


def test_unknown_lines_given_as_one_string_are_refused():
    """Issue 56: `unknown_lines="LANDMARK"` was kept as eight lines of one character each."""
    arrays = (2, [0, 1], np.zeros((2, 3)), [[0, 1]], [[1.0, 0.0, 0.0]], [np.eye(3)])
    for lines in ("LANDMARK", b"LANDMARK", None, ["VERTEX_XY 9 1 2", 3]):
        with pytest.raises(egnc.GraphError, match="^unknown_lines must"):
            egnc.PoseGraph(*arrays, unknown_lines=lines)  # type: ignore[arg-type]
    assert egnc.PoseGraph(*arrays, unknown_lines=["VERTEX_XY 9 1 2"]).unknown_lines == ("VERTEX_XY 9 1 2",)


def test_keep_edges_of_the_wrong_shape_is_an_option_error(tmp_path):
    graph = read_g2o(GRID2D)
    with pytest.raises(OptionError, match=r"keep_edges must be a boolean mask of shape"):
        write_g2o(graph, tmp_path / "out.g2o", keep_edges=np.ones(3, dtype=bool))
    assert not (tmp_path / "out.g2o").exists()
