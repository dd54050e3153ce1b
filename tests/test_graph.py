"""`PoseGraph` checks what the readers check, owns its arrays, and prints a short repr (issue 19)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from egnc.api import solve
from egnc.errors import G2oFormatError, GraphError, OptionError
from egnc.graph import PoseGraph
from egnc.graph.validity import NO_EDGES
from egnc.io import read_g2o


def chain(n: int = 4, dim: int = 2) -> PoseGraph:
    """`n` poses on a line, odometry edges and one loop closure from the last to the first."""
    p, d = (3, 3) if dim == 2 else (7, 6)
    poses = np.zeros((n, p))
    poses[:, 0] = np.arange(n)
    if dim == 3:
        poses[:, 6] = 1.0
    edges = np.array([[k, k + 1] for k in range(n - 1)] + [[n - 1, 0]])
    measurements = np.zeros((n, p))
    measurements[: n - 1, 0] = 1.0
    measurements[n - 1, 0] = -(n - 1.0)
    if dim == 3:
        measurements[:, 6] = 1.0
    return PoseGraph(dim, np.arange(n), poses, edges, measurements, np.tile(np.eye(d), (n, 1, 1)))


@pytest.mark.parametrize("dim", [2, 3])
def test_negative_definite_information_is_refused_like_the_reader(dim, tmp_path):
    graph = chain(dim=dim)
    information = np.array(graph.information)
    information[2] = -information[2]
    with pytest.raises(GraphError, match=r"^edge 2: information matrix is not positive definite .*1 of the 4 edges"):
        dataclasses.replace(graph, information=information)
    # The reader's message carries the same words for the same matrix.
    path = tmp_path / "bad.g2o"
    text = "\n".join(
        f"EDGE_SE2 {i} {j} 1 0 0 {-1 if k == 2 else 1} 0 0 {-1 if k == 2 else 1} 0 {-1 if k == 2 else 1}"
        for k, (i, j) in enumerate(chain().edges.tolist())
    )
    path.write_text(text + "\n")
    message = r"bad.g2o:3: information matrix is not positive definite .*1 of the 4 edges"
    with pytest.raises(G2oFormatError, match=message):
        read_g2o(path)


def test_only_self_loops_and_no_edges_are_refused():
    graph = chain()
    with pytest.raises(GraphError, match="^edge 0: edge joins vertex 1 to itself$"):
        dataclasses.replace(graph, edges=np.array([[1, 1], [2, 2], [3, 3], [0, 0]]))
    with pytest.raises(GraphError, match=f"no edges: {NO_EDGES}"):
        PoseGraph(2, np.arange(2), np.zeros((2, 3)), np.zeros((0, 2), int), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    with pytest.raises(GraphError, match="no edges"):
        graph.subgraph_edges(np.zeros(graph.num_edges, dtype=bool))


def test_unsorted_or_repeated_ids_and_bad_quaternions_are_refused():
    graph = chain()
    with pytest.raises(GraphError, match="sorted ascending and unique"):
        dataclasses.replace(graph, vertex_ids=np.array([0, 1, 1, 2]))
    graph3 = chain(dim=3)
    measurements = np.array(graph3.measurements)
    measurements[1, 3:] = 0.0
    with pytest.raises(GraphError, match=r"^edge 1: measurement quaternion .* too small"):
        dataclasses.replace(graph3, measurements=measurements)


def test_no_invalid_graph_built_in_code_reaches_a_converged_solve():
    # Before issue 19 each of these solved and reported "converged" (the first at cost 0.0).
    graph = chain()
    bad = [
        dict(information=-np.array(graph.information)),
        dict(edges=np.array([[1, 1], [2, 2], [3, 3], [0, 0]])),
        dict(edges=np.zeros((0, 2), int), measurements=np.zeros((0, 3)), information=np.zeros((0, 3, 3)),
             edge_lines=np.zeros(0, int)),
    ]  # fmt: skip
    for change in bad:
        with pytest.raises(GraphError):
            solve(dataclasses.replace(graph, **change), "l2")


def test_the_caller_cannot_change_the_graph_nor_the_graph_the_caller():
    poses = np.zeros((4, 3))
    poses[:, 0] = np.arange(4)
    source = chain()
    graph = dataclasses.replace(source, poses=poses)
    for name in ("vertex_ids", "poses", "edges", "measurements", "information", "fixed", "edge_lines"):
        array = getattr(graph, name)
        assert not array.flags.writeable
        with pytest.raises(ValueError):
            array.setflags(write=True)  # a read-only view of a private copy cannot be made writable
        assert array.base is not None and not np.shares_memory(array, poses)
    poses[0, 0] = 99.0
    assert graph.poses[0, 0] == 0.0
    assert poses.flags.writeable  # the caller's array is neither frozen nor aliased


def test_derived_graphs_share_the_checked_arrays_instead_of_copying():
    graph = chain()
    moved = graph.with_poses(np.array(graph.poses) + 1.0)
    assert moved.information is graph.information and moved.edges is graph.edges
    assert moved.poses is not graph.poses


def test_subgraph_mask_of_the_wrong_length_or_type_is_an_option_error():
    graph = chain()
    with pytest.raises(OptionError, match=r"keep must be a bool mask of shape \(4,\)"):
        graph.subgraph_edges(np.ones(3, dtype=bool))
    with pytest.raises(OptionError, match="keep"):
        graph.subgraph_edges(np.ones(4))
    assert graph.subgraph_edges(np.array([True, True, True, False])).num_edges == 3


def test_first_poses_keeps_those_poses_and_the_edges_among_them():
    graph = dataclasses.replace(chain(6), fixed=np.array([False, True, False, False, False, False]))
    first = graph.first_poses(4)
    np.testing.assert_array_equal(first.vertex_ids, graph.vertex_ids[:4])
    np.testing.assert_array_equal(first.poses, graph.poses[:4])
    np.testing.assert_array_equal(first.fixed, graph.fixed[:4])
    # The odometry 0-1, 1-2, 2-3: the edges 3-4, 4-5 and the loop 5-0 reach beyond pose 3.
    np.testing.assert_array_equal(first.edges, [[0, 1], [1, 2], [2, 3]])
    np.testing.assert_array_equal(first.measurements, graph.measurements[:3])
    np.testing.assert_array_equal(first.edge_lines, graph.edge_lines[:3])
    assert graph.first_poses(6).num_edges == graph.num_edges
    with pytest.raises(OptionError, match="count must be at most the 6 poses, got 7"):
        graph.first_poses(7)
    with pytest.raises(OptionError, match="count must be an integer"):
        graph.first_poses(2.0)  # type: ignore[arg-type]
    with pytest.raises(GraphError, match="no edges"):
        graph.first_poses(1)


def test_repr_is_short():
    graph = read_g2o(Path(__file__).parents[1] / "datasets" / "grid2d_outliers.g2o")
    text = repr(graph)
    assert text == (
        f"PoseGraph(dim=2, poses={graph.num_poses}, edges={graph.num_edges}, "
        f"loop_closures={int(graph.is_loop_closure.sum())}, fixed=0)"
    )
    assert len(text) < 100


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(edges="x"), "edges must be an array of integers, got 'x'"),
        (dict(edges=None), "edges must be an array of integers, got None"),
        (dict(edges=np.array([[0.0, 1.5], [1, 2], [2, 3], [3, 0]])), "edges must be an array of integers"),
        (dict(poses="x"), "poses must be an array of numbers, got 'x'"),
        (dict(vertex_ids=None), "vertex_ids must be an array of integers"),
        (dict(dim=[2]), r"dim must be 2 or 3, got \[2\]"),
        (dict(dim=2.0), "dim must be 2 or 3, got 2.0"),
    ],
)
def test_arrays_that_are_not_numbers_name_the_field(change, message):
    # Found by benchmarks/_lib/fuzz_api.py: NumPy's own ValueError or an AttributeError named nothing,
    # and float ids were truncated (1.5 -> 1) without a word.
    with pytest.raises(GraphError, match=f"^{message}"):
        dataclasses.replace(chain(), **change)


def test_integral_floats_are_accepted_as_ids():
    graph = chain()
    as_floats = dataclasses.replace(graph, edges=np.array(graph.edges, dtype=float))
    np.testing.assert_array_equal(as_floats.edges, graph.edges)


def test_fixed_must_be_bools_or_zeros_and_ones_naming_the_first_that_is_not():
    # NumPy turns None into False and 0.5 or 2 into True: a pose meant to be held (or not) was
    # silently solved (or held).
    bad = [
        ([None, True, False, False], "element 0 is None"),
        ([False, None, None, None], "element 1 is None"),
        ([0.5, 0, 0, 0], "element 0 is 0.5"),
        (["no", "", "", ""], "element 0 is 'no'"),
        ([2, 0, 0, 0], "element 0 is 2"),
    ]
    for fixed, message in bad:
        with pytest.raises(GraphError, match=rf"^fixed must be an array of bools \(True/False or 0/1\), {message}$"):
            dataclasses.replace(chain(), fixed=fixed)
    graph = dataclasses.replace(chain(), fixed=[0, 1, 0, 0.0])
    np.testing.assert_array_equal(graph.fixed, [False, True, False, False])


INT64 = np.iinfo(np.int64)


def test_ids_at_the_int64_limits_are_valid_and_never_wrap(tmp_path):
    """Issue 56: `np.diff` of `[int64 min, 1]` wrapped to a negative step, refusing valid ids; and
    `id + 1` at int64's maximum made an edge from the largest id to the smallest "odometry"."""
    graph = PoseGraph(2, [INT64.min, 1], np.zeros((2, 3)), [[0, 1]], [[1.0, 0.0, 0.0]], [np.eye(3)])
    assert graph.is_odometry.tolist() == [False]
    ends = PoseGraph(
        2, [INT64.min, INT64.min + 1, INT64.max - 1, INT64.max], np.zeros((4, 3)),
        [[1, 0], [0, 3], [3, 0], [2, 3], [1, 2]], np.tile([1.0, 0.0, 0.0], (5, 1)), np.tile(np.eye(3), (5, 1, 1)),
    )  # fmt: skip
    assert ends.is_odometry.tolist() == [True, False, False, True, False]
    with pytest.raises(GraphError, match="vertex_ids must be sorted ascending and unique"):
        PoseGraph(2, [INT64.max, INT64.min], np.zeros((2, 3)), [[0, 1]], [[1.0, 0.0, 0.0]], [np.eye(3)])
    path = tmp_path / "limits.g2o"
    path.write_text(
        f"VERTEX_SE2 {INT64.min} 0 0 0\nVERTEX_SE2 {INT64.max} 1 0 0\n"
        f"EDGE_SE2 {INT64.min} {INT64.max} 1 0 0 1 0 0 1 0 1\n"
    )
    read = read_g2o(path)
    assert read.vertex_ids.tolist() == [INT64.min, INT64.max]
    assert solve(read, "l2").converged
