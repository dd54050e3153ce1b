"""Reading and writing g2o files: layout, exact round trips, one-line errors, atomic writes."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

import egnc.io.atomic as atomic_module
import egnc.io.g2o as g2o_module
from egnc.errors import EgncError, EgncWarning, G2oFormatError, GraphError
from egnc.graph import PoseGraph
from egnc.io import read_g2o, write_g2o
from egnc.io.numbers import is_float, is_integer, parse_floats, parse_integers
from egnc.lie import se2
from egnc.nonlinear.initialize import spanning_tree

# From ../shared/datasets/README.md: file -> (dim, VERTEX lines, EDGE lines). kitti_00 has no
# VERTEX line at all; its 4541 poses come from the edges.
DATASETS = {
    "csail.g2o": (2, 1045, 1172),
    "intel.g2o": (2, 943, 1837),
    "manhattanOlson3500.g2o": (2, 3500, 5598),
    "city10000.g2o": (2, 10000, 20687),
    "MIT.g2o": (2, 808, 827),
    "kitti_00.g2o": (2, 0, 4677),
    "sphere2500.g2o": (3, 2500, 4949),
    "sphere_a.g2o": (3, 2200, 8647),
    "parking-garage.g2o": (3, 1661, 6275),
    "cubicle.g2o": (3, 5750, 16869),
    "smallGrid3D.g2o": (3, 125, 297),
    "tinyGrid3D.g2o": (3, 9, 11),
}
# cubicle.g2o stores 5021 indefinite information matrices (first on line 5753), so it is rejected
# unless a repair is asked for.
UNREADABLE = {"cubicle.g2o": 5753}
READABLE = sorted(set(DATASETS) - set(UNREADABLE))
ARRAYS = ("vertex_ids", "poses", "edges", "measurements", "information", "fixed")


def info_upper(d: int, scale: float = 1.0) -> str:
    """The upper triangle of `scale * I_d`, row-major, as g2o text."""
    rows, cols = np.triu_indices(d)
    return " ".join(repr(scale * float(r == c)) for r, c in zip(rows, cols))


V2 = "VERTEX_SE2 0 0 0 0\n"
V2B = "VERTEX_SE2 1 1 0 0\n"
E2 = f"EDGE_SE2 0 1 1 0 0 {info_upper(3)}\n"
V3 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
E3 = f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {info_upper(6)}\n"

TINY_2D = f"""# tiny 2D graph: ids not contiguous, vertices out of order, an edge with i > j
VERTEX_SE2 10 0 0 0   
VERTEX_SE2 5 1.5 -2 0.25

VERTEX_SE2 20 3 4 3.5
FIX 10
EDGE_SE2 10 5 1.5 -2 0.25 500 10 0 400 0 1000  # odometry, trailing comment
EDGE_SE2 20 5 -0.1 0.2 -7 1 0 0 1 0 1
EDGE_SE2 5 20 1e-3 -0 3.14159 {info_upper(3, 2.0)}
"""

TINY_3D = f"""VERTEX_SE3:QUAT 2 0 0 0 0 0 0 2
VERTEX_SE3:QUAT 0 1 2 3 0.1 0.2 0.3 -0.9
EDGE_SE3:QUAT 0 2 1 0 0 0 0 0.7071 0.7071 {info_upper(6, 3.0)}
"""


def write_text(tmp_path: Path, text: str, name: str = "graph.g2o") -> Path:
    """Write `text` to a file under `tmp_path` and return its path."""
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_same_graph(a: PoseGraph, b: PoseGraph) -> None:
    """Assert bit-identical arrays (dtype, shape and bytes, so -0.0 differs from 0.0)."""
    assert a.dim == b.dim
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x.dtype, x.shape) == (y.dtype, y.shape), name
        assert x.tobytes() == y.tobytes(), name


def round_trip(graph: PoseGraph, tmp_path: Path, **kwargs) -> PoseGraph:
    """Write the graph and read it back."""
    path = tmp_path / "round_trip.g2o"
    write_g2o(graph, path, **kwargs)
    return read_g2o(path)


# --- Reading well-formed files ---------------------------------------------------------------


def test_tiny_2d_layout(tmp_path):
    graph = read_g2o(write_text(tmp_path, TINY_2D))
    assert graph.dim == 2
    np.testing.assert_array_equal(graph.vertex_ids, [5, 10, 20])
    np.testing.assert_array_equal(graph.poses, [[1.5, -2, 0.25], [0, 0, 0], [3, 4, 3.5]])
    np.testing.assert_array_equal(graph.edges, [[1, 0], [2, 0], [0, 2]])
    np.testing.assert_array_equal(graph.edge_lines, [7, 8, 9])
    np.testing.assert_array_equal(graph.fixed, [False, True, False])
    # Angles are stored as read, not wrapped.
    np.testing.assert_array_equal(graph.measurements[:, 2], [0.25, -7, 3.14159])
    np.testing.assert_array_equal(
        graph.information[0], [[500, 10, 0], [10, 400, 0], [0, 0, 1000]]
    )
    np.testing.assert_array_equal(graph.information[2], 2.0 * np.eye(3))
    assert np.signbit(graph.measurements[2, 1])  # "-0" stays negative zero


def test_tiny_3d_quaternions_stored_as_read(tmp_path):
    graph = read_g2o(write_text(tmp_path, TINY_3D))
    assert graph.dim == 3
    np.testing.assert_array_equal(graph.vertex_ids, [0, 2])
    np.testing.assert_array_equal(graph.poses[0, 3:], [0.1, 0.2, 0.3, -0.9])
    np.testing.assert_array_equal(graph.poses[1, 3:], [0, 0, 0, 2])
    np.testing.assert_array_equal(graph.measurements[0, 3:], [0, 0, 0.7071, 0.7071])
    np.testing.assert_array_equal(graph.information[0], 3.0 * np.eye(6))


def test_crlf_line_endings(tmp_path):
    path = tmp_path / "crlf.g2o"
    path.write_bytes(TINY_2D.replace("\n", "\r\n").encode())
    assert_same_graph(read_g2o(path), read_g2o(write_text(tmp_path, TINY_2D)))


def test_skip_unknown_ignores_other_tags_and_writes_them_back(tmp_path):
    unknown = ["VERTEX_XY 7 1 2", "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1  # offset", "VERTEX_XY 8 3 4"]
    text = V2 + "\n".join(unknown[:2]) + "\n" + E2 + unknown[2] + "\n"
    with pytest.warns(EgncWarning, match=r"skipped 3 lines .*\(VERTEX_XY 2, PARAMS_SE3OFFSET 1\)"):
        graph = read_g2o(write_text(tmp_path, text), skip_unknown=True)
    np.testing.assert_array_equal(graph.vertex_ids, [0, 1])
    np.testing.assert_array_equal(graph.edge_lines, [4])
    assert graph.unknown_lines == tuple(unknown)
    written = tmp_path / "out.g2o"
    write_g2o(graph.with_poses(graph.poses + 1), written)
    lines = written.read_text().splitlines()
    assert [line for line in lines if line in unknown] == unknown  # verbatim, in file order
    assert lines.index(unknown[-1]) < lines.index(next(line for line in lines if line.startswith("EDGE")))
    with pytest.raises(G2oFormatError, match="'2.5', which is not a record tag"):  # damage is never skipped
        read_g2o(write_text(tmp_path, text + "2.5 VERTEX_SE2 1 0 0\n"), skip_unknown=True)


def test_missing_vertex_composed_from_known_neighbour(tmp_path):
    # Vertex 1 has no VERTEX line; the edges are exact, so either neighbour gives the same pose.
    X = np.array([[1.0, 2.0, 0.5], [2.0, 3.0, 1.0], [2.5, 2.0, -2.0]])
    T = se2.from_xytheta(X)
    Z01 = se2.to_xytheta(se2.between(T[0], T[1]))
    Z21 = se2.to_xytheta(se2.between(T[2], T[1]))
    def fields(values: np.ndarray) -> str:
        return " ".join(map(repr, values.tolist()))

    info = info_upper(3)
    text = (
        f"VERTEX_SE2 0 {fields(X[0])}\nVERTEX_SE2 2 {fields(X[2])}\n"
        f"EDGE_SE2 0 1 {fields(Z01)} {info}\nEDGE_SE2 2 1 {fields(Z21)} {info}\n"
    )
    graph = read_g2o(write_text(tmp_path, text))
    np.testing.assert_array_equal(graph.poses[[0, 2]], X[[0, 2]])
    np.testing.assert_allclose(se2.from_xytheta(graph.poses[1]), T[1], atol=1e-12)


# --- Real datasets ----------------------------------------------------------------------------


def test_dataset_table_covers_every_file(shared_datasets):
    assert {path.name for path in shared_datasets.glob("*.g2o")} <= set(DATASETS)


@pytest.mark.parametrize("name", READABLE)
def test_dataset_counts_and_exact_round_trip(name, dataset_path, tmp_path):
    dim, vertex_lines, edge_lines = DATASETS[name]
    graph = read_g2o(dataset_path(name))
    assert graph.dim == dim
    assert graph.num_edges == edge_lines
    if vertex_lines:
        assert graph.num_poses == vertex_lines
    again = round_trip(graph, tmp_path)
    assert_same_graph(graph, again)
    # Rewritten files list vertices, then FIX lines, then edges, one per line.
    first_edge_line = graph.num_poses + int(graph.fixed.sum()) + 1
    np.testing.assert_array_equal(again.edge_lines, first_edge_line + np.arange(graph.num_edges))
    # A second write is byte-identical to the first.
    second = tmp_path / "second.g2o"
    write_g2o(again, second)
    assert second.read_bytes() == (tmp_path / "round_trip.g2o").read_bytes()


@pytest.mark.parametrize("name", sorted(UNREADABLE))
def test_dataset_with_indefinite_information_is_rejected(name, dataset_path):
    with pytest.raises(G2oFormatError) as caught:
        read_g2o(dataset_path(name))
    assert f"{name}:{UNREADABLE[name]}: information matrix is not positive definite" in str(caught.value)


def test_kitti_initial_guess_is_exact_along_spanning_tree(dataset_path):
    graph = read_g2o(dataset_path("kitti_00.g2o"))
    assert graph.num_poses == 4541 and graph.vertex_ids[0] == 0
    np.testing.assert_array_equal(graph.poses[0], [0.0, 0.0, 0.0])

    T = se2.from_xytheta(graph.poses)
    Z = se2.from_xytheta(graph.measurements)
    i, j = graph.edges.T
    # Per edge: how far X_j is from X_i Z_ij (matrix entries, metres and unitless).
    mismatch = np.abs(se2.between(T[i], T[j]) - Z).max(axis=(1, 2))

    parent, tree_edge = spanning_tree(graph.num_poses, graph.edges, np.array([0]))
    tree = tree_edge[parent >= 0]
    assert len(tree) == graph.num_poses - 1
    assert mismatch[tree].max() < 1e-9
    # Independent of which tree the reader chose: the exactly satisfied edges span the graph.
    from egnc.graph.connectivity import connected_components

    count, _ = connected_components(graph.num_poses, graph.edges[mismatch < 1e-9])
    assert count == 1


# --- Errors: one line, naming the file and the 1-based line -----------------------------------

QUAT_ZERO = "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 0\n"
ERROR_CASES = {
    "too few fields": (V2 + "VERTEX_SE2 1 0 0\n" + E2, 2, "VERTEX_SE2 needs 4 fields after the tag"),
    "too many fields": (V2 + V2B + E2.replace("\n", " 7\n"), 3, "EDGE_SE2 needs 11 fields"),
    "line numbers count comments and blanks": ("# header\n\n" + V2 + "VERTEX_SE2 1 0 0\n" + E2, 4, "found 3"),
    "non-numeric value": (V2 + "VERTEX_SE2 1 0 abc 0\n" + E2, 2, "field 3 is 'abc', expected a number"),
    "non-integer id": (
        V2 + V2B + E2.replace("0 1 ", "0 1.5 ", 1), 3, "field 2 is '1.5', expected an integer vertex id"
    ),
    "id out of range": (V2 + E2.replace("0 1 ", "0 99999999999999999999 ", 1), 2, "expected an integer vertex id"),
    "truncated last line": (V2 + V2B + E2[:30], 3, "file looks truncated"),
    "truncated inside a number": (V2 + V2B + E2.rstrip("\n") + "e", 3, "file looks truncated"),
    "unknown tag": (
        V2 + "VERTEX_XY 7 1 2\n" + E2, 2, "unknown tag 'VERTEX_XY'; pass skip_unknown=True / --skip-unknown"
    ),
    "number where the tag belongs": (V2 + "2.5 VERTEX_SE2 1 0 0\n" + E2, 2, "'2.5', which is not a record tag"),
    "nan": (V2 + "VERTEX_SE2 1 nan 0 0\n" + E2, 2, "field 2 is nan, expected a finite number"),
    "inf in information": (V2 + V2B + E2.replace(" 0.0 1.0\n", " inf 1.0\n"), 3, "is inf"),
    "indefinite information": (
        V2 + V2B + E2.replace("1.0 0.0 0.0 1.0", "1.0 2.0 0.0 1.0", 1), 3, "not positive definite"
    ),
    "zero information": (V2 + V2B + E2.replace("1.0", "0.0"), 3, "not positive definite"),
    "2D and 3D mixed": (V2 + V3.replace(" 0 ", " 1 ", 1) + E2, 2, "VERTEX_SE3:QUAT is 3D but line 1 is 2D"),
    "duplicate vertex id": (
        V2 + V2B + "VERTEX_SE2 0 1 1 1\n" + E2, 3, "vertex id 0 is defined twice, on lines 1 and 3"
    ),
    "edge to itself": (V2 + V2B + E2 + E2.replace("0 1 ", "1 1 ", 1), 4, "edge joins vertex 1 to itself"),
    "zero vertex quaternion": (V3 + QUAT_ZERO + E3, 2, "too small to normalize"),
    "zero edge quaternion": (V3 + E3.replace(" 0 0 1 1.0", " 0 0 0 1.0", 1), 2, "too small to normalize"),
    "FIX unknown vertex": (V2 + "FIX 7\n" + E2, 2, "FIX names vertex 7"),
    "FIX without id": (V2 + "FIX\n" + E2, 2, "FIX needs at least one vertex id"),
    "FIX non-integer": (V2 + "FIX 0 x\n" + E2, 2, "FIX field 2 is 'x'"),
}


@pytest.mark.parametrize("case", sorted(ERROR_CASES))
def test_format_error_names_file_and_line(case, tmp_path):
    text, line, fragment = ERROR_CASES[case]
    path = write_text(tmp_path, text, name="bad.g2o")
    with pytest.raises(G2oFormatError) as caught:
        read_g2o(path)
    message = str(caught.value)
    assert message.startswith(f"{path}:{line}: "), message
    assert caught.value.line == line
    assert fragment in message
    assert "\n" not in message


@pytest.mark.parametrize("text", ["", "# only a comment\n\n", V2 + V2B, "FIX 0\n"])
def test_file_without_edges_is_an_error(text, tmp_path):
    path = write_text(tmp_path, text, name="empty.g2o")
    with pytest.raises(G2oFormatError, match="no EDGE_SE2, EDGE2 or EDGE_SE3:QUAT lines") as caught:
        read_g2o(path)
    assert str(caught.value).startswith(f"{path}: ")


def test_unreadable_files(tmp_path):
    with pytest.raises(G2oFormatError, match="missing.g2o: cannot read file"):
        read_g2o(tmp_path / "missing.g2o")
    binary = tmp_path / "binary.g2o"
    binary.write_bytes(V2.encode() + b"\xff\xfe\x00\n")
    with pytest.raises(G2oFormatError, match=r"binary.g2o:2: not a text file"):
        read_g2o(binary)


def test_disconnected_graph_names_components(tmp_path):
    text = E2 + E2.replace("0 1 ", "5 6 ", 1) + E2.replace("0 1 ", "6 7 ", 1) + E2.replace("0 1 ", "9 10 ", 1)
    path = write_text(tmp_path, text + "VERTEX_SE2 20 0 0 0\n", name="islands.g2o")  # 20: isolated, ignored
    with pytest.raises(GraphError) as caught:
        read_g2o(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: ")
    assert "3 connected components: {0..1} (2 poses), {5..7} (3 poses), {9..10} (2 poses)" in message


@pytest.mark.parametrize("file_fixes", ["", "FIX 3\n"], ids=["no-fix", "fix"])
def test_vertices_without_edges_are_held_fixed_with_a_warning(tmp_path, file_fixes):
    # Kimera-RPGO style: vertices 0 and 9 are defined but no edge touches them.
    text = V2 + "VERTEX_SE2 9 5 5 1\n" + E2.replace("0 1 ", "3 4 ", 1) + E2.replace("0 1 ", "4 5 ", 1) + file_fixes
    path = write_text(tmp_path, text)
    with pytest.warns(EgncWarning, match=r"2 vertices that no edge touches .*: \{0, 9\}"):
        graph = read_g2o(path)
    np.testing.assert_array_equal(graph.vertex_ids, [0, 3, 4, 5, 9])
    # Isolated ones fixed; the gauge stays on the connected part: the file's FIX, else its lowest id.
    np.testing.assert_array_equal(graph.fixed, [True, True, False, False, True])
    np.testing.assert_array_equal(graph.poses[-1], [5, 5, 1])


def test_duplicate_edges_and_odometry_in_either_direction(tmp_path):
    reversed_edge = E2.replace("0 1 1 0 0", "1 0 -1 0 0", 1)
    graph = read_g2o(write_text(tmp_path, V2 + V2B + E2 + reversed_edge + E2))
    np.testing.assert_array_equal(graph.is_duplicate, [False, True, True])
    np.testing.assert_array_equal(graph.is_odometry, [True, True, True])  # either direction


def test_duplicates_are_repeats_of_an_unordered_pair():
    rng = np.random.default_rng(3)
    for _ in range(100):
        n = int(rng.integers(2, 12))
        starts = rng.integers(0, n, size=int(rng.integers(1, 40)))
        edges = np.stack((starts, (starts + rng.integers(1, n, size=len(starts))) % n), axis=1)  # no self-edge
        information = np.tile(np.eye(3), (len(edges), 1, 1))
        graph = PoseGraph(2, np.arange(n), np.zeros((n, 3)), edges, np.zeros((len(edges), 3)), information)
        seen: set[tuple[int, int]] = set()
        expected = []
        for i, j in edges.tolist():
            expected.append((min(i, j), max(i, j)) in seen)
            seen.add((min(i, j), max(i, j)))
        np.testing.assert_array_equal(graph.is_duplicate, expected)


# --- Numbers: one grammar, range checks ----------------------------------------------------------

STRICT_NUMBER_CASES = {
    "underscore": ("1_0", "expected a number"),
    "leading plus": ("+3", "expected a number"),
    "arabic-indic digit": ("\u0663", "character U+0663"),
    "file separator": ("1\x1c0", "character U+001C"),
    "line separator": ("1\u20280", "character U+2028"),
    "vertical tab": ("1\x0b0", "character U+000B"),
    "hex": ("0x10", "expected a number"),
}


@pytest.mark.parametrize("case", sorted(STRICT_NUMBER_CASES))
def test_numbers_follow_one_strict_grammar(case, tmp_path):
    token, fragment = STRICT_NUMBER_CASES[case]
    path = write_text(tmp_path, V2 + f"VERTEX_SE2 1 {token} 0 0\n" + E2)
    with pytest.raises(G2oFormatError) as caught:
        read_g2o(path)
    assert str(caught.value).startswith(f"{path}:2: ") and fragment in str(caught.value)


NUMBER_TOKENS = [
    "0", "-0", "007", "1.", ".5", "-.5", "1.5e-3", "1E+05", "1e5", "-7", "9223372036854775807",
    "-9223372036854775808", "9223372036854775808", "nan", "-Inf", "infinity",
    "+3", "+.5", "1_0", "0x10", "1e", "e5", ".", "-", "--1", "1-2", "1.2.3", "1e5e5", "1+", "",
    " 1", "1 ", "1,2", "\u0663",
]  # fmt: skip


@pytest.mark.parametrize("token", NUMBER_TOKENS)
def test_parsers_accept_exactly_the_grammar(token):
    # The parsers skip the per-token match for tokens of digits, `.`, `e`, `+`, `-`: same verdicts.
    floats = parse_floats(["1", token])
    assert (floats is not None) == is_float(token)
    if floats is not None:
        np.testing.assert_array_equal(floats, [1.0, float(token)])
    integers = parse_integers(["1", token])
    fits = is_integer(token) and -(2**63) <= int(token) < 2**63
    assert (integers is not None) == fits
    if integers is not None:
        np.testing.assert_array_equal(integers, [1, int(token)])


def _loop_tables(path: Path, text: str) -> tuple:
    """What the line loop reads from `text`: `(dim, vertices, edges, fixes)`, as `_plain_tables` returns it."""
    lines = text.split("\n")
    context = g2o_module._Context(path, text, len(lines))
    dim, vertices, edges, fixes, _ = g2o_module._split_records(lines, context, skip_unknown=False)
    tags = g2o_module._VERTEX_TAGS[dim], g2o_module._EDGE_TAGS[dim]
    return dim, *(g2o_module._to_table(records, tag, context) for records, tag in zip((vertices, edges), tags)), fixes


def assert_same_tables(plain: tuple, loop: tuple) -> None:
    assert plain[0] == loop[0] and plain[3] == loop[3]
    for ours, theirs in zip(plain[1:3], loop[1:3]):
        for field in ("ids", "values", "lines", "toro"):
            a, b = getattr(ours, field), getattr(theirs, field)
            assert a.dtype == b.dtype and a.shape == b.shape
            assert a.tobytes() == b.tobytes()  # the same bits: -0.0, subnormals and rounding included


@pytest.mark.parametrize("name", READABLE)
def test_plain_files_read_as_the_line_loop_reads_them(name, dataset_path):
    # The dataset files have no comment: the fast path reads them, and must agree with the loop.
    text = dataset_path(name).read_text()
    plain = g2o_module._plain_tables(text, text.split("\n"))
    assert plain is not None
    assert_same_tables(plain, _loop_tables(dataset_path(name), text))


TORO = "VERTEX2 0 0 0 0\nVERTEX2 1 1 0.5 0.2\nEDGE2 0 1 1 0.5 0.2 11 1 22 33 2 3\n"


@pytest.mark.parametrize(
    "text",
    [
        E2,  # no VERTEX line
        TORO,
        TORO.replace("VERTEX2", "VERTEX_SE2"),  # g2o vertices, TORO edges
        V2 + "FIX 0\n" + E2 + "FIX 0 1\n",
        "  \t" + V2 + "\n\n" + V2B + E2.rstrip("\n"),  # leading blanks, empty lines, no last newline
        V3 + f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {info_upper(6)}\n",
    ],
)
def test_plain_variants_read_as_the_line_loop_reads_them(tmp_path, text):
    plain = g2o_module._plain_tables(text, text.split("\n"))
    assert plain is not None
    assert_same_tables(plain, _loop_tables(tmp_path / "graph.g2o", text))


PLAIN_NUMBERS = ["1e+05", "-2.5E-3", ".5", "7.", "-0", "00012", "1e400", "-1e400", "1e-400", "2.5e-324", "4.9e-324",
                 "1.7976931348623159e308", "123456789012345678901234567890", "0.1", "5e-0", "-.5e5"]  # fmt: skip


@pytest.mark.parametrize("number", PLAIN_NUMBERS)
def test_plain_numbers_convert_as_python_does(tmp_path, number):
    # Over- and underflow, subnormals and long digit strings: the same float64 as the loop's `float`.
    text = f"VERTEX_SE2 0 0 0 0\n\tVERTEX_SE2  -1 {number} 1 2\nEDGE_SE2 -1 0 {number} 0 0 {info_upper(3)}"
    plain = g2o_module._plain_tables(text, text.split("\n"))
    assert plain is not None
    assert_same_tables(plain, _loop_tables(tmp_path / "graph.g2o", text))


@pytest.mark.parametrize("seed", range(5))
def test_plain_numbers_agree_on_random_files(tmp_path, seed):
    # Random values written in several forms (repr, %.3e, %g, integers), spaces and tabs mixed.
    rng = np.random.default_rng(seed)
    forms = [
        lambda v: repr(float(v)),
        lambda v: f"{v:.3e}",
        lambda v: f"{v:g}",
        lambda v: str(int(v)),
        lambda v: f"{v:.20f}",
    ]
    values = rng.standard_normal(400) * 10.0 ** rng.integers(-300, 300, 400)
    tokens = [forms[k](v) for k, v in zip(rng.integers(0, len(forms), 400), values)]
    gaps = rng.choice([" ", "\t", "  ", " \t"], size=100)
    vertices = "".join(f"VERTEX_SE2 {i}{gap}{' '.join(tokens[3 * i : 3 * i + 3])}\n" for i, gap in enumerate(gaps))
    edges = "".join(f"EDGE_SE2 {i} {i + 1} 1 0 0 {info_upper(3)}\n" for i in range(99))
    text = vertices + edges
    plain = g2o_module._plain_tables(text, text.split("\n"))
    assert plain is not None
    assert_same_tables(plain, _loop_tables(tmp_path / "graph.g2o", text))


@pytest.mark.parametrize(
    "text",
    [
        V2 + "FIX\n" + E2,  # a FIX without ids
        V2 + "FIX 0\n" + E2 + V3,  # 2D and 3D
        V2 + "VERTEX_SE2 1 0 0\n" + E2,  # a field short
        V2 + "VERTEX_XY 1 0 0\n" + E2,  # an unknown tag
        V2 + "VERTEX2 1 0 0 0\n" + E2,  # g2o and TORO vertices
        V2 + E2.replace("1 0 0", "1 0 1e", 1),  # a number read in part
        V2 + E2.replace("1 0 0", "1 0 1.2.3", 1),
        V2 + E2.replace("1 0 0", "1 0 +1", 1),  # a leading +
        V2 + E2.replace("1 0 0", "1 0 nan", 1),  # not plain
        V2 + E2.replace("EDGE_SE2 0 1", "EDGE_SE2 0 1.0", 1),  # an id that is not an integer
        V2 + E2.replace("EDGE_SE2 0 1", "EDGE_SE2 0 1234567890123456", 1),  # an id of 16 digits
        V2 + E2.replace("EDGE_SE2 0 1", "EDGE_SE2 0 -", 1),
        V2,  # no edge
        "",
    ],
)
def test_files_with_anything_to_report_are_left_to_the_line_loop(text):
    assert g2o_module._plain_tables(text, text.split("\n")) is None


def test_long_ids_are_read_by_the_line_loop(tmp_path):
    big = 2**62 + 1  # not exact as a float64: the plain path leaves it to the loop
    graph = read_g2o(write_text(tmp_path, f"VERTEX_SE2 {big} 0 0 0\n" + E2.replace("0 1", f"{big} 1", 1)))
    assert graph.vertex_ids.tolist() == [1, big]


def test_plain_fix_lines(tmp_path):
    graph = read_g2o(write_text(tmp_path, V2 + V2B + "FIX 1\n" + E2 + "FIX 0 1\n"))
    np.testing.assert_array_equal(graph.fixed, [True, True])


def test_accepted_number_forms(tmp_path):
    text = "VERTEX_SE2 0 1e+05 -2.5E-3 .5\nVERTEX_SE2 -1 7. -0 1e5\t# unicode in a comment: \u2028 \u0663\n"
    graph = read_g2o(write_text(tmp_path, text + E2.replace("0 1 ", "-1 0 ", 1)))
    np.testing.assert_array_equal(graph.poses, [[7.0, -0.0, 1e5], [1e5, -2.5e-3, 0.5]])


@pytest.mark.parametrize("component", ["1e300", "-2e200"])
def test_quaternion_too_large_to_normalize_is_a_format_error(component, tmp_path):
    path = write_text(tmp_path, V3 + f"VERTEX_SE3:QUAT 1 0 0 0 0 {component} 0 1\n" + E3)
    with pytest.raises(G2oFormatError, match="too large"):
        read_g2o(path)


# --- Information matrices: strict, nearest-pd, diagonal -----------------------------------------

INDEFINITE = E2.replace("1.0 0.0 0.0 1.0", "1.0 2.0 0.0 1.0", 1)  # [[1, 0, 0], [0, 1, 2], [0, 2, 1]]


def test_strict_information_error_names_the_repair_option(tmp_path):
    with pytest.raises(G2oFormatError, match="--information nearest-pd or diagonal"):
        read_g2o(write_text(tmp_path, V2 + V2B + INDEFINITE + E2))


@pytest.mark.parametrize("mode", ["nearest-pd", "diagonal"])
def test_information_repair_changes_only_the_bad_matrices(tmp_path, mode):
    path = write_text(tmp_path, V2 + V2B + INDEFINITE + E2.replace("0 1 ", "1 2 ", 1))
    with pytest.warns(EgncWarning, match=f"repaired 1 of 2 information matrices .*{mode}.*line 3") as caught:
        graph = read_g2o(path, information=mode)
    assert len(caught) == 1
    np.testing.assert_array_equal(graph.information[1], np.eye(3))
    repaired = graph.information[0]
    assert np.linalg.eigvalsh(repaired)[0] > 0
    if mode == "diagonal":
        np.testing.assert_array_equal(repaired, np.eye(3))
    else:  # eigenvalues 1, 3, -1 -> 1, 3, 3e-6: the negative direction clipped, the others kept
        np.testing.assert_allclose(np.linalg.eigvalsh(repaired), [3e-6, 1, 3], rtol=1e-9, atol=1e-15)


def test_diagonal_repair_refuses_a_non_positive_diagonal(tmp_path):
    text = V2 + V2B + E2.replace("1.0 0.0 0.0 1.0 0.0 1.0", "1.0 0.0 0.0 -1.0 0.0 1.0", 1)
    with pytest.raises(G2oFormatError, match="cannot repair"):
        read_g2o(write_text(tmp_path, text), information="diagonal")


def test_cubicle_reads_with_nearest_pd(dataset_path):
    with pytest.warns(EgncWarning, match="repaired 5021 of 16869 information matrices"):
        graph = read_g2o(dataset_path("cubicle.g2o"), information="nearest-pd")
    assert (np.linalg.eigvalsh(graph.information)[:, 0] > 0).all()


# --- Writing ----------------------------------------------------------------------------------


@pytest.mark.parametrize("text", [TINY_2D, TINY_3D], ids=["2d", "3d"])
def test_tiny_round_trip_is_exact(text, tmp_path):
    graph = read_g2o(write_text(tmp_path, text))
    assert_same_graph(graph, round_trip(graph, tmp_path))


def test_keep_edges_writes_a_subset(tmp_path):
    graph = read_g2o(write_text(tmp_path, TINY_2D))
    keep = np.array([True, False, True])
    assert_same_graph(graph.subgraph_edges(keep), round_trip(graph, tmp_path, keep_edges=keep))
    with pytest.raises(ValueError, match="boolean mask of shape"):
        write_g2o(graph, tmp_path / "x.g2o", keep_edges=np.array([0, 2]))
    assert not (tmp_path / "x.g2o").exists()


def test_write_uses_default_permissions(tmp_path):
    graph = read_g2o(write_text(tmp_path, TINY_2D))
    umask = os.umask(0)
    os.umask(umask)
    write_g2o(graph, tmp_path / "out.g2o")
    assert (tmp_path / "out.g2o").stat().st_mode & 0o777 == 0o666 & ~umask


@pytest.fixture
def tiny_graph(tmp_path) -> PoseGraph:
    return read_g2o(write_text(tmp_path, TINY_2D))


def test_failed_write_leaves_nothing(tiny_graph, tmp_path, monkeypatch):
    format_records = g2o_module._format_records

    def fail_on_edges(tag, ids, values):
        if tag.startswith("EDGE"):
            raise RuntimeError("disk full")
        return format_records(tag, ids, values)

    monkeypatch.setattr(g2o_module, "_format_records", fail_on_edges)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(RuntimeError, match="disk full"):
        write_g2o(tiny_graph, out_dir / "new.g2o")
    assert list(out_dir.iterdir()) == []

    existing = out_dir / "existing.g2o"
    existing.write_text("old content\n")
    with pytest.raises(RuntimeError, match="disk full"):
        write_g2o(tiny_graph, existing)
    assert list(out_dir.iterdir()) == [existing]
    assert existing.read_text() == "old content\n"


def test_failed_replace_removes_temporary(tiny_graph, tmp_path, monkeypatch):
    def refuse(src, dst):
        raise OSError("replace refused")

    monkeypatch.setattr(atomic_module.os, "replace", refuse)
    with pytest.raises(EgncError, match=r"new\.g2o: cannot write file: replace refused"):
        write_g2o(tiny_graph, tmp_path / "new.g2o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["graph.g2o"]


def test_all_or_nothing_renames_only_when_every_file_is_written(tiny_graph, tmp_path):
    first, second = tmp_path / "first.g2o", tmp_path / "second.g2o"
    first.write_text("old first\n")
    with pytest.raises(RuntimeError, match="second failed"), atomic_module.all_or_nothing():
        write_g2o(tiny_graph, first)
        assert first.read_text() == "old first\n"  # written to a temporary, not renamed yet
        with atomic_module.atomic_text_file(second) as out:
            out.write("partial")
            raise RuntimeError("second failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.g2o", "graph.g2o"]
    assert first.read_text() == "old first\n"

    with atomic_module.all_or_nothing():
        write_g2o(tiny_graph, first)
        write_g2o(tiny_graph, second)
    assert read_g2o(first).num_edges == read_g2o(second).num_edges == tiny_graph.num_edges


def test_interruption_during_the_renames_is_ignored(tiny_graph, tmp_path, monkeypatch):
    replace = atomic_module._replace

    def interrupted_replace(temporary, path):
        os.kill(os.getpid(), signal.SIGINT)  # would raise KeyboardInterrupt if it were delivered
        replace(temporary, path)

    monkeypatch.setattr(atomic_module, "_replace", interrupted_replace)
    with atomic_module.all_or_nothing():
        write_g2o(tiny_graph, tmp_path / "a.g2o")
        write_g2o(tiny_graph, tmp_path / "b.g2o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.g2o", "b.g2o", "graph.g2o"]


def test_non_finite_graph_is_not_written(tiny_graph, tmp_path):
    poses = tiny_graph.poses.copy()
    poses[1, 0] = np.nan
    with pytest.raises(GraphError, match="poses of vertex 10 is not finite"):
        write_g2o(tiny_graph.with_poses(poses), tmp_path / "nan.g2o")
    assert not (tmp_path / "nan.g2o").exists()


@pytest.mark.parametrize("name", ["intel.g2o", "kitti_00.g2o", "sphere2500.g2o"])
def test_matches_gtsam_reader(name, dataset_path):
    """Same edges, measurements and information as GTSAM's readG2o (an independent parser)."""
    gtsam = pytest.importorskip("gtsam")
    from egnc.lie import se3

    graph = read_g2o(dataset_path(name))
    factors, _ = gtsam.readG2o(str(dataset_path(name)), graph.dim == 3)
    assert factors.size() == graph.num_edges
    # GTSAM orders 3D tangents rotation-first; g2o (and egnc) translation-first.
    order = [0, 1, 2] if graph.dim == 2 else [3, 4, 5, 0, 1, 2]
    for k in range(graph.num_edges):
        factor = factors.at(k)
        assert tuple(factor.keys()) == tuple(graph.vertex_ids[graph.edges[k]])
        expected_information = graph.information[k][np.ix_(order, order)]
        information = factor.noiseModel().information()
        np.testing.assert_allclose(information, expected_information, rtol=1e-12, atol=0)
        if graph.dim == 2:
            measured = factor.measured()
            assert [measured.x(), measured.y()] == graph.measurements[k, :2].tolist()
        else:
            np.testing.assert_allclose(
                factor.measured().matrix(), se3.from_xyz_quat(graph.measurements[k]), atol=1e-12
            )


# --- Issue 19: huge integers, byte-order marks, endless input, TORO records ----------------------

HUGE = "1" * 5000  # Python's int() refuses more than 4300 digits with a ValueError of its own


@pytest.mark.parametrize(
    ("text", "line", "field"),
    [
        (V2 + f"VERTEX_SE2 {HUGE} 1 0 0\n" + E2, 2, "VERTEX_SE2 field 1"),
        (V2 + V2B + f"EDGE_SE2 0 -{HUGE} 1 0 0 {info_upper(3)}\n", 3, "EDGE_SE2 field 2"),
        (V2 + V2B + E2 + f"FIX 0 {HUGE}\n", 4, "FIX field 2"),
        (V2 + V2B + f"EDGE_SE2 0 {'0' * 4400}1 1 0 0 {info_upper(3)}\n" + f"FIX {HUGE}\n", 4, "FIX field 1"),
    ],
)
def test_integers_beyond_the_digit_limit_are_a_one_line_error(tmp_path, text, line, field):
    path = write_text(tmp_path, text)
    with pytest.raises(G2oFormatError, match=f"{field} is .*characters[)], expected an integer") as info:
        read_g2o(path)
    assert (info.value.path, info.value.line) == (str(path), line)
    assert len(str(info.value)) < 300  # the token is cut short in the message


def test_leading_zeros_do_not_count_against_the_id_range(tmp_path):
    graph = read_g2o(write_text(tmp_path, V2 + V2B + f"EDGE_SE2 0 {'0' * 4400}1 1 0 0 {info_upper(3)}\n"))
    np.testing.assert_array_equal(graph.vertex_ids, [0, 1])


def test_a_byte_order_mark_is_skipped(tmp_path):
    path = tmp_path / "bom.g2o"
    path.write_bytes(b"\xef\xbb\xbf" + (V2 + V2B + E2).encode())
    assert_same_graph(read_g2o(path), read_g2o(write_text(tmp_path, V2 + V2B + E2)))


def test_an_endless_line_is_refused_after_a_bounded_read(tmp_path):
    import egnc.io.text as text_module

    with pytest.raises(G2oFormatError, match="^/dev/zero:1: line longer than 1048576 bytes") as info:
        read_g2o("/dev/zero")
    assert info.value.line == 1
    # A long line after good ones names its own line, and an invalid byte in a later block too.
    path = tmp_path / "long.g2o"
    path.write_bytes((V2 + V2B).encode() + b"# " + b"x" * (2 * text_module.MAX_LINE_BYTES + 5))
    with pytest.raises(G2oFormatError, match="long.g2o:3: line longer"):
        read_g2o(path)
    path.write_bytes((V2 * 10).encode() + b"#" * (text_module.BLOCK_SIZE + 7) + b"\n\xff\n")
    with pytest.raises(G2oFormatError, match="long.g2o:12: not a text file"):
        read_g2o(path)


def test_toro_records_read_as_gtsam_load2d_reads_them(tmp_path):
    # TORO's information order is I11 I12 I22 I33 I13 I23 (x, y, theta).
    toro = "VERTEX2 0 0 0 0\nVERTEX2 1 1 0.5 0.2\nEDGE2 0 1 1 0.5 0.2 11 1 22 33 2 3\n"
    graph = read_g2o(write_text(tmp_path, toro, "toro.graph"))
    expected = np.array([[11.0, 1.0, 2.0], [1.0, 22.0, 3.0], [2.0, 3.0, 33.0]])
    np.testing.assert_array_equal(graph.information[0], expected)
    np.testing.assert_array_equal(graph.measurements, [[1.0, 0.5, 0.2]])
    np.testing.assert_array_equal(graph.poses, [[0.0, 0.0, 0.0], [1.0, 0.5, 0.2]])
    # The same edge as EDGE_SE2 (g2o order), mixed with TORO lines in one file: file order is kept.
    mixed = toro + "EDGE_SE2 1 0 -1 0 0 11 1 2 22 3 33\n" + "EDGE2 1 0 -1 0 0 11 1 22 33 2 3\n"
    graph = read_g2o(write_text(tmp_path, mixed, "mixed.graph"))
    np.testing.assert_array_equal(graph.information, np.stack([expected] * 3))
    np.testing.assert_array_equal(graph.edges, [[0, 1], [1, 0], [1, 0]])
    assert_same_graph(graph, read_g2o(write_text(tmp_path, mixed + "# comment: the line-by-line path\n")))


def test_toro_information_matches_gtsam(tmp_path):
    gtsam = pytest.importorskip("gtsam")
    path = write_text(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0.5 0.2 11 1 22 33 2 3\n", "t.graph")
    factors, _ = gtsam.load2D(str(path), noiseFormat=gtsam.NoiseFormat.NoiseFormatTORO, smart=False)
    R = factors.at(0).noiseModel().R()
    np.testing.assert_allclose(read_g2o(path).information[0], R.T @ R, rtol=1e-12)


def test_toro_errors_name_the_toro_tag(tmp_path):
    with pytest.raises(G2oFormatError, match=":3: EDGE2 field 8 is nan, expected a finite number"):
        read_g2o(write_text(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 nan 1 0 0\n"))
    with pytest.raises(G2oFormatError, match=":1: EDGE2 needs 11 fields after the tag"):
        read_g2o(write_text(tmp_path, "EDGE2 0 1 1 0 0 1 0 1 1 0\n"))
