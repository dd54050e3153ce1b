"""Read and write pose graphs in the g2o text format.

One record per line, fields separated by ASCII spaces or tabs; blank lines and `#` comments are
ignored; numbers follow the grammar of `egnc.io.numbers`:

- `VERTEX_SE2 id x y theta`
- `EDGE_SE2 i j dx dy dtheta` + 6 information entries
- `VERTEX_SE3:QUAT id x y z qx qy qz qw`
- `EDGE_SE3:QUAT i j dx dy dz qx qy qz qw` + 21 information entries
- `FIX id [id ...]`
- priors: `EDGE_SE2_PRIOR`, `EDGE_SE2_XYPRIOR`, `EDGE_SE3_PRIOR`, `EDGE_SE3_XYZPRIOR` and the
  `PARAMS_SE3OFFSET` they name (`egnc.io.g2o_priors`); edges and priors are the graph's factors,
  numbered in file order (`PoseGraph.edge_factor_index`, `prior_factor_index`).
- TORO's 2D records as GTSAM's `load2D` reads them with `NoiseFormatTORO` (checked against the
  gtsam 4.3 wheel): `VERTEX2 id x y theta`, `EDGE2 i j dx dy dtheta I11 I12 I22 I33 I13 I23`
  (information in TORO's order); `write_g2o` writes them as `VERTEX_SE2` and `EDGE_SE2`.

Information matrices are given as their upper triangle, row-major, ordered translation-then-rotation
(`x y theta` in 2D, `x y z rx ry rz` in 3D). Values are stored exactly as read: angles are not
wrapped and quaternions are not normalized (that happens when converting to matrices).

Reading validates everything first: a bad file gives a one-line `G2oFormatError` naming the file
and 1-based line. Poses without a VERTEX line are initialized by `egnc.nonlinear.initialize`.
"""

from __future__ import annotations

import collections
import itertools
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from egnc.errors import EgncWarning, G2oFormatError, GraphError, OptionError
from egnc.graph import POSE_SIZE, TANGENT_SIZE, PoseGraph
from egnc.graph.checks import check_bool, check_choice, check_instance
from egnc.graph.connectivity import describe_ids, hold_isolated_fixed, isolated_vertices, require_connected
from egnc.graph.index_sets import sorted_unique
from egnc.graph.validity import (
    NO_EDGES,
    first_bad_quaternion,
    first_self_edge,
    not_positive_definite,
    not_positive_definite_message,
)
from egnc.io.atomic import atomic_text_file
from egnc.io.g2o_priors import PriorRecords, merged_with_priors, priors_of, split_prior_lines
from egnc.io.information import INFORMATION_MODES, InformationMode, repair_information
from egnc.io.numbers import check_line_characters, is_float, parse_floats, parse_id, parse_integers, shown
from egnc.io.plain_records import plain_records
from egnc.io.text import read_text
from egnc.nonlinear.initialize import initialize_poses


@dataclass(frozen=True)
class _Tag:
    """The fixed layout of one g2o record type."""

    name: str
    kind: str  # "vertex" or "edge"
    dim: int
    num_ids: int
    num_values: int
    layout: str
    toro: bool = False

    @property
    def num_fields(self) -> int:
        """Fields after the tag."""
        return self.num_ids + self.num_values


_VERTEX_TAGS = {
    2: _Tag("VERTEX_SE2", "vertex", 2, 1, 3, "id x y theta"),
    3: _Tag("VERTEX_SE3:QUAT", "vertex", 3, 1, 7, "id x y z qx qy qz qw"),
}
_EDGE_TAGS = {
    2: _Tag("EDGE_SE2", "edge", 2, 2, 3 + 6, "i j dx dy dtheta and 6 information entries"),
    3: _Tag("EDGE_SE3:QUAT", "edge", 3, 2, 7 + 21, "i j dx dy dz qx qy qz qw and 21 information entries"),
}
_TORO_TAGS = (
    _Tag("VERTEX2", "vertex", 2, 1, 3, "id x y theta", toro=True),
    _Tag("EDGE2", "edge", 2, 2, 3 + 6, "i j dx dy dtheta I11 I12 I22 I33 I13 I23", toro=True),
)
_TAGS = {tag.name: tag for tag in (*_VERTEX_TAGS.values(), *_EDGE_TAGS.values(), *_TORO_TAGS)}
_TORO_NAMES = {tag.kind: tag.name for tag in _TORO_TAGS}
_TORO_TO_G2O_UPPER = np.array([0, 1, 4, 2, 5, 3])
"""TORO's `I11 I12 I22 I33 I13 I23` to g2o's row-major upper triangle `I11 I12 I13 I22 I23 I33`."""
_FIX = "FIX"
_TAG_NAME = re.compile(r"[A-Z][A-Z0-9_:]*", re.IGNORECASE)
"""What a record tag looks like (`VERTEX_XY`, `PARAMS_SE3OFFSET`, ...): anything else is damage, never skipped."""
_NOT_PLAIN_TEXT = re.compile(r"[^\t\n\x20-\x22\x24-\x7e]")
"""A character that needs `_split_records`' line loop: a comment's `#`, CR, non-ASCII, controls."""


@dataclass
class _Records:
    """Raw fields of one record type, in file order."""

    rows: list[list[str]]
    lines: list[int]


@dataclass(frozen=True, eq=False)
class _Table:
    """The records of one kind (vertex or edge), converted, in file order.

    Attributes:
        ids: `(n, num_ids)` int64 vertex ids.
        values: `(n, num_values)` float64, the fields after the ids.
        lines: `(n,)` int64 1-based line numbers.
        toro: `(n,)` bool, which records are TORO's (`VERTEX2`, `EDGE2`).
    """

    ids: np.ndarray
    values: np.ndarray
    lines: np.ndarray
    toro: np.ndarray

    @classmethod
    def empty(cls, tag: _Tag) -> _Table:
        """No record of `tag`'s kind."""
        ids, lines = np.zeros((0, tag.num_ids), dtype=np.int64), np.zeros(0, dtype=np.int64)
        return cls(ids, np.zeros((0, tag.num_values)), lines, np.zeros(0, dtype=bool))

    def tag_name(self, row: int, tag: _Tag) -> str:
        """The tag of record `row`, of the kind of the g2o `tag`."""
        return _TORO_NAMES[tag.kind] if self.toro[row] else tag.name


class _Context:
    """What error messages need to know about the file being read."""

    def __init__(self, path: Path, text: str, num_lines: int):
        self.path = path
        # A last line without a newline that fails to parse was most likely cut short.
        self.cut_line = num_lines if text and not text.endswith("\n") else None
        self.priors: PriorRecords | None = None  # the file's prior records (`egnc.io.g2o_priors`)

    def error(self, message: str, line: int | None = None) -> G2oFormatError:
        """Build the error to raise, flagging a probably truncated last line."""
        if line is not None and line == self.cut_line:
            message = f"file looks truncated (last line has no newline): {message}"
        return G2oFormatError(message, self.path, line)


def read_g2o(
    path: str | os.PathLike, *, skip_unknown: bool = False, information: InformationMode = "strict"
) -> PoseGraph:
    """Read a 2D or 3D g2o file into a `PoseGraph`.

    Args:
        path: the `.g2o` file.
        skip_unknown: ignore lines with tags other than the ones above (landmarks, parameters,
            ...) instead of raising; they are kept verbatim in `PoseGraph.unknown_lines`, and
            `write_g2o` writes them back.
        information: what to do with information matrices that are not positive definite:
            `"strict"` raises, `"nearest-pd"` or `"diagonal"` repair them
            (`egnc.io.information`).

    Returns:
        The graph, vertex ids sorted ascending, edges in file order. Vertices referenced by edges
        but without a VERTEX line get their pose from `egnc.nonlinear.initialize.initialize_poses`.
        Vertices that no edge touches are held fixed (see `hold_isolated_fixed`).

    Warns:
        EgncWarning: one per kind of accepted oddity: skipped lines (count per tag), repaired
            information matrices (count, largest change), vertices without edges.

    Raises:
        G2oFormatError: the file cannot be read or is malformed; names the file and line.
        GraphError: the file is well formed but its graph is disconnected.
        OptionError: an argument has the wrong type or value.
    """
    check_instance("path", path, (str, os.PathLike), "a g2o file path (str or os.PathLike)")
    check_bool("skip_unknown", skip_unknown)
    check_choice("information", information, INFORMATION_MODES)
    path = Path(path)
    dim, vertices, edges, fixes, unknown, context = _read_tables(path, skip_unknown)
    notes = [_describe_skipped(path, unknown)] if unknown else []
    measurements, information_matrices, repair_note = _checked_values(dim, vertices, edges, information, context)
    notes += [repair_note] if repair_note else []

    vertex_ids = vertices.ids[:, 0]
    all_ids = sorted_unique(np.concatenate((vertex_ids, edges.ids.ravel())))
    fixed = _fixed_mask(fixes, all_ids, context)
    edge_rows = np.searchsorted(all_ids, edges.ids)
    isolated = isolated_vertices(len(all_ids), edge_rows)
    require_connected(all_ids, edge_rows, source=str(path), ignore=isolated)
    if isolated.any():
        fixed = hold_isolated_fixed(fixed, isolated)
        notes.append(
            f"{path}: {int(isolated.sum())} vertices that no edge touches are kept unchanged and not optimized: "
            f"{describe_ids(all_ids[isolated])}"
        )

    graph = PoseGraph(
        dim=dim,
        vertex_ids=all_ids,
        poses=_initial_poses(dim, all_ids, vertices, edge_rows, measurements, isolated),
        edges=edge_rows,
        measurements=measurements,
        information=information_matrices,
        fixed=fixed,
        edge_lines=edges.lines,
        unknown_lines=tuple(unknown) + tuple(context.priors.param_lines if context.priors else ()),
        priors=priors_of(context.priors, dim, all_ids, context.error) if context.priors else None,  # type: ignore[arg-type]
    )
    for note in notes:
        warnings.warn(note, EgncWarning, stacklevel=2)
    return graph


def _read_tables(path: Path, skip_unknown: bool) -> tuple[int, _Table, _Table, _Records, list[str], _Context]:
    """`(dim, vertices, edges, fixes, unknown lines, context)` of a g2o file, each record parsed.

    Plain text takes the fast path (`egnc.io.plain_records`); anything else, and every error, the
    line-by-line one that names the line.
    """
    text = read_text(path)
    context = _Context(path, text, text.count("\n") + 1)
    text, context.priors = split_prior_lines(text, context.error)
    lines = text.split("\n")
    plain = _plain_tables(text, lines) if _NOT_PLAIN_TEXT.search(text) is None else None
    if plain is not None:
        dim, vertices, edges, fixes = plain
        return dim, vertices, edges, fixes, [], context
    found, vertex_records, edge_records, fixes, unknown = _split_records(lines, context, skip_unknown)
    if found is None or not edge_records.rows:
        raise context.error(f"no EDGE_SE2, EDGE2 or EDGE_SE3:QUAT lines: {NO_EDGES}")
    vertices = _to_table(vertex_records, _VERTEX_TAGS[found], context)
    edges = _to_table(edge_records, _EDGE_TAGS[found], context)
    return found, vertices, edges, fixes, unknown, context


def _checked_values(
    dim: int, vertices: _Table, edges: _Table, information: InformationMode, context: _Context
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """`(measurements (E, P), information (E, d, d), repair note)` of the edges, once every value is checked.

    Checked in this order, the first failure raised: finite numbers, unit quaternions (3D),
    unique vertex ids, no edge from a vertex to itself, positive-definite information (or its
    repair, `information`).
    """
    p, d = POSE_SIZE[dim], TANGENT_SIZE[dim]
    measurements = edges.values[:, :p]
    upper = edges.values[:, p:]
    if edges.toro.any():
        upper = upper.copy()
        upper[edges.toro] = upper[edges.toro][:, _TORO_TO_G2O_UPPER]
    information_matrices = _information_from_upper(upper, d)
    _check_finite(vertices, _VERTEX_TAGS[dim], context)
    _check_finite(edges, _EDGE_TAGS[dim], context)
    if dim == 3:
        _check_quaternions(vertices.values[:, 3:7], vertices.lines, context)
        _check_quaternions(measurements[:, 3:7], edges.lines, context)
    _check_unique_vertices(vertices.ids[:, 0], vertices.lines, context)
    _check_no_self_edges(edges.ids, edges.lines, context)
    information_matrices, repair_note = _positive_definite(information_matrices, edges.lines, information, context)
    return measurements, information_matrices, repair_note


def _initial_poses(
    dim: int,
    all_ids: np.ndarray,
    vertices: _Table,
    edge_rows: np.ndarray,
    measurements: np.ndarray,
    isolated: np.ndarray,
) -> np.ndarray:
    """`(N, P)` the VERTEX lines' poses, and for vertices without one `initialize_poses`' guess."""
    poses = np.zeros((len(all_ids), POSE_SIZE[dim]))
    known = np.zeros(len(all_ids), dtype=bool)
    vertex_rows = np.searchsorted(all_ids, vertices.ids[:, 0])
    poses[vertex_rows] = vertices.values
    known[vertex_rows] = True
    if not known.all():  # isolated vertices are known (they have VERTEX lines): initialize the rest
        rows = np.flatnonzero(~isolated)
        poses[rows] = initialize_poses(
            dim, np.searchsorted(rows, edge_rows), measurements, poses=poses[rows], known=known[rows]
        )
    return poses


def write_g2o(graph: PoseGraph, path: str | os.PathLike, *, keep_edges: np.ndarray | None = None) -> None:
    """Write a graph as g2o text, atomically: the file is complete or untouched.

    Vertices are written in id order, then FIX lines, then `graph.unknown_lines` (landmarks,
    parameters, ... skipped by `read_g2o`, verbatim and in file order), then edges in graph order,
    the priors among them in factor order (`egnc.io.g2o_priors.merged_with_priors`).
    Floats are written with `repr`, so reading the file back gives bit-identical arrays. Only the
    upper triangle of each information matrix is written (the g2o convention).

    Args:
        graph: the graph to write.
        path: the output file; replaced only once the new content is fully written.
        keep_edges: optional `(E,)` bool mask of the edges to write (e.g. to drop outliers); all
            vertices are written regardless.

    Raises:
        OptionTypeError: `graph` is not a `PoseGraph` or `path` not a path (e.g. the two swapped).
        OptionError: `keep_edges` is not an `(E,)` boolean mask (a `ValueError` too).
        GraphError: the graph holds non-finite values, which no reader would accept.
    """
    check_instance("graph", graph, PoseGraph)
    check_instance("path", path, (str, os.PathLike), "a file path (str or os.PathLike)")
    keep = np.ones(graph.num_edges, dtype=bool) if keep_edges is None else np.asarray(keep_edges)
    if keep.dtype != bool or keep.shape != (graph.num_edges,):
        raise OptionError(
            f"keep_edges must be a boolean mask of shape ({graph.num_edges},), "
            f"got dtype {keep.dtype} and shape {keep.shape}"
        )
    _check_writable(graph)
    vertex_tag, edge_tag = _VERTEX_TAGS[graph.dim], _EDGE_TAGS[graph.dim]
    rows_upper, cols_upper = np.triu_indices(graph.tangent_dim)
    with atomic_text_file(Path(path)) as out:
        out.write(_format_records(vertex_tag.name, graph.vertex_ids[:, None], graph.poses))
        out.write("".join(f"{_FIX} {i}\n" for i in graph.vertex_ids[graph.fixed].tolist()))
        out.write("".join(f"{line}\n" for line in graph.unknown_lines))
        edge_values = np.concatenate(
            (graph.measurements[keep], graph.information[keep][:, rows_upper, cols_upper]), axis=1
        )
        edge_text = _format_records(edge_tag.name, graph.vertex_ids[graph.edges[keep]], edge_values)
        out.write(merged_with_priors(graph, keep, edge_text) if graph.num_priors else edge_text)


def _split_records(
    lines: list[str], context: _Context, skip_unknown: bool
) -> tuple[int | None, _Records, _Records, _Records, list[str]]:
    """Group the fields of each line by record type, checking characters, tags and field counts.

    Returns:
        `(dim, vertices, edges, fixes, unknown)`; `dim` is None when the file has no vertex or
        edge line; `unknown` holds the lines with other tags, verbatim (only with `skip_unknown`).
    """
    vertices, edges, fixes = _Records([], []), _Records([], []), _Records([], [])
    unknown: list[str] = []
    dim = None
    first_line = 0
    for line_number, raw_line in enumerate(lines, start=1):
        raw_line = raw_line.removesuffix("\r")  # CRLF files
        line = raw_line.partition("#")[0]
        problem = check_line_characters(line)
        if problem:
            raise context.error(problem, line_number)
        fields = line.split()
        if not fields:
            continue
        name = fields[0]
        tag = _TAGS.get(name)
        if tag is None:
            if name == _FIX:
                if len(fields) < 2:
                    raise context.error("FIX needs at least one vertex id", line_number)
                fixes.rows.append(fields)
                fixes.lines.append(line_number)
            elif not _TAG_NAME.fullmatch(name):
                raise context.error(f"line starts with {shown(name)}, which is not a record tag", line_number)
            elif skip_unknown:
                unknown.append(raw_line)
            else:
                raise context.error(
                    f"unknown tag {shown(name)}; "
                    "pass skip_unknown=True / --skip-unknown to skip such lines (they are written back with -o)",
                    line_number,
                )
            continue
        if len(fields) - 1 != tag.num_fields:
            raise context.error(
                f"{name} needs {tag.num_fields} fields after the tag ({tag.layout}), found {len(fields) - 1}",
                line_number,
            )
        if tag.dim != dim:
            if dim is not None:
                raise context.error(
                    f"{name} is {tag.dim}D but line {first_line} is {dim}D; "
                    "2D and 3D records cannot be mixed in one file",
                    line_number,
                )
            dim, first_line = tag.dim, line_number
        records = vertices if tag.kind == "vertex" else edges
        records.rows.append(fields)
        records.lines.append(line_number)
    return dim, vertices, edges, fixes, unknown


def _plain_tables(text: str, lines: list[str]) -> tuple[int, _Table, _Table, _Records] | None:
    """`_split_records` and `_to_table` at once for a plain file, or None to leave it to them.

    Plain means: lines of printable ASCII, spaces and tabs (no comment, no CR: `_NOT_PLAIN_TEXT`,
    checked by the caller on the whole text), only this module's tags and `FIX`, one dimension,
    every field count right, plain numbers, ids of at most 15 digits. `egnc.io.plain_records`
    reads them all at once, without a string per field. Each of these is checked over all
    records; whatever fails is left to the loop, which finds the first bad line and its message.

    Returns:
        `(dim, vertices, edges, fixes)`.
    """
    names = (*_TAGS, _FIX)
    records = plain_records(text, names)
    if records is None:
        return None
    present = [name for name, count in zip(names, np.bincount(records.tags, minlength=len(names))) if count]
    tags = [_TAGS[name] for name in present if name != _FIX]
    dims = {tag.dim for tag in tags}
    kinds = [tag.kind for tag in tags]
    if len(dims) != 1 or len(kinds) != len(set(kinds)) or "edge" not in kinds:
        return None  # several dimensions, g2o and TORO records of one kind, or no edge: the loop's job
    dim = dims.pop()
    tables = {"vertex": _Table.empty(_VERTEX_TAGS[dim])}  # a file may have no VERTEX line
    for tag in tags:
        rows = np.flatnonzero(records.tags == names.index(tag.name))
        ids = records.integers(rows, tag.num_ids) if np.all(records.counts[rows] == tag.num_fields) else None
        if ids is None:
            return None
        values = records.floats(rows, tag.num_ids, tag.num_values)
        tables[tag.kind] = _Table(ids, values, records.lines[rows], np.full(len(rows), tag.toro))
    fix_lines = records.lines[records.tags == names.index(_FIX)].tolist()
    fixes = _Records([lines[number - 1].split() for number in fix_lines], fix_lines)
    if any(len(row) < 2 for row in fixes.rows):
        return None
    return dim, tables["vertex"], tables["edge"], fixes


def _describe_skipped(path: Path, unknown: list[str]) -> str:
    """One sentence: how many lines of which tags were skipped."""
    counts = collections.Counter(line.split()[0] for line in unknown)
    tags = ", ".join(f"{tag} {count}" for tag, count in counts.most_common())
    return (
        f"{path}: skipped {len(unknown)} lines with tags egnc does not read ({tags}); "
        "write_g2o (egnc-solve -o) writes them back unchanged"
    )


def _to_table(records: _Records, tag: _Tag, context: _Context) -> _Table:
    """Convert the rows of one kind (`tag`'s, g2o or TORO) to a `_Table` (`egnc.io.numbers`)."""
    # Every row has 1 + num_fields tokens (checked by `_split_records`): take the tokens column by
    # column with list slices, which is faster than slicing each row, then transpose the numbers.
    n, k, width = len(records.rows), 1 + tag.num_ids, 1 + tag.num_fields
    tokens = list(itertools.chain.from_iterable(records.rows))
    ids = parse_integers(list(itertools.chain.from_iterable(tokens[c::width] for c in range(1, k))))
    values = parse_floats(list(itertools.chain.from_iterable(tokens[c::width] for c in range(k, width))))
    if ids is None or values is None:
        _raise_first_bad_field(records, tag, context)
    toro = np.fromiter((row[0] != tag.name for row in records.rows), dtype=bool, count=n)
    lines = np.asarray(records.lines, dtype=np.int64)
    return _Table(ids.reshape(tag.num_ids, n).T.copy(), values.reshape(tag.num_values, n).T.copy(), lines, toro)


def _raise_first_bad_field(records: _Records, tag: _Tag, context: _Context) -> NoReturn:
    """Find the first field that is not a valid id or number and raise for its line."""
    for row, line_number in zip(records.rows, records.lines):
        for position, token in enumerate(row[1:], start=1):
            if position <= tag.num_ids:
                _parse_id(token, row[0], position, line_number, context)
            elif not is_float(token):
                raise context.error(f"{row[0]} field {position} is {shown(token)}, expected a number", line_number)
    raise AssertionError("no bad field found")


def _parse_id(token: str, tag_name: str, position: int, line_number: int, context: _Context) -> int:
    """Parse one vertex id, raising for its line unless it is an int64 integer (`parse_id`)."""
    value = parse_id(token)
    if value is None:
        raise context.error(
            f"{tag_name} field {position} is {shown(token)}, expected an integer vertex id in the int64 range",
            line_number,
        )
    return value


def _check_finite(table: _Table, tag: _Tag, context: _Context) -> None:
    """Reject NaN and infinite values, naming the first offending line, tag and field."""
    bad = ~np.isfinite(table.values)
    if bad.any():
        row, column = np.argwhere(bad)[0]
        raise context.error(
            f"{table.tag_name(row, tag)} field {1 + tag.num_ids + column} is {table.values[row, column]}, "
            "expected a finite number",
            int(table.lines[row]),
        )


def _check_quaternions(quaternions: np.ndarray, lines: np.ndarray, context: _Context) -> None:
    """Reject quaternions that cannot be normalized (`egnc.graph.validity`); stored values are kept as read."""
    found = first_bad_quaternion(quaternions)
    if found:
        raise context.error(found[1], int(lines[found[0]]))


def _check_unique_vertices(vertex_ids: np.ndarray, lines: np.ndarray, context: _Context) -> None:
    """Reject a vertex id defined twice, naming both lines."""
    order = np.argsort(vertex_ids, kind="stable")
    repeats = np.flatnonzero(np.diff(vertex_ids[order]) == 0)
    if len(repeats):
        # Report the pair whose second definition comes first in the file.
        first_rows, second_rows = order[repeats], order[repeats + 1]
        k = np.argmin(lines[second_rows])
        raise context.error(
            f"vertex id {vertex_ids[first_rows[k]]} is defined twice, on lines "
            f"{lines[first_rows[k]]} and {lines[second_rows[k]]}",
            int(lines[second_rows[k]]),
        )


def _check_no_self_edges(edge_ids: np.ndarray, lines: np.ndarray, context: _Context) -> None:
    """Reject an edge from a vertex to itself (`egnc.graph.validity`)."""
    found = first_self_edge(edge_ids)
    if found:
        raise context.error(found[1], int(lines[found[0]]))


def _positive_definite(
    information: np.ndarray, lines: np.ndarray, mode: InformationMode, context: _Context
) -> tuple[np.ndarray, str | None]:
    """Check the information matrices, repairing the bad ones unless `mode` is strict.

    Returns:
        `(information, note)`: the matrices (repaired ones replaced) and the warning to emit, or
        None when nothing was repaired.
    """
    bad = not_positive_definite(information)
    if not len(bad):
        return information, None
    if mode == "strict":
        raise context.error(
            f"{not_positive_definite_message(information, bad)}; "
            "--information nearest-pd or diagonal (information= in read_g2o) repairs them",
            int(lines[bad[0]]),
        )
    information, still_bad, repair = repair_information(information, bad, mode)
    if len(still_bad):
        raise context.error(
            f"information matrix is not positive definite and --information {mode} cannot repair it "
            f"(diagonal {np.diagonal(information[still_bad[0]]).tolist()})",
            int(lines[still_bad[0]]),
        )
    note = (
        f"{context.path}: repaired {repair.count} of {len(information)} information matrices that were not "
        f"positive definite ({mode}); largest relative change {repair.largest_change:.3g} "
        f"(line {lines[repair.largest_index]})"
    )
    return information, note


def _fixed_mask(fixes: _Records, vertex_ids: np.ndarray, context: _Context) -> np.ndarray:
    """Return the `(N,)` bool mask of vertices named by FIX lines."""
    listed_ids: list[int] = []
    fixed_lines: list[int] = []
    for row, line_number in zip(fixes.rows, fixes.lines):
        for position, token in enumerate(row[1:], start=1):
            listed_ids.append(_parse_id(token, _FIX, position, line_number, context))
            fixed_lines.append(line_number)
    fixed_ids = np.array(listed_ids, dtype=np.int64)
    rows = np.minimum(np.searchsorted(vertex_ids, fixed_ids), len(vertex_ids) - 1)
    unknown = np.flatnonzero(vertex_ids[rows] != fixed_ids)
    if len(unknown):
        k = unknown[0]
        raise context.error(
            f"FIX names vertex {fixed_ids[k]}, which no VERTEX or EDGE line mentions",
            fixed_lines[k],
        )
    fixed = np.zeros(len(vertex_ids), dtype=bool)
    fixed[rows] = True
    return fixed


def _information_from_upper(upper: np.ndarray, d: int) -> np.ndarray:
    """Build `(E, d, d)` symmetric matrices from `(E, d(d+1)/2)` row-major upper triangles."""
    rows, cols = np.triu_indices(d)
    information = np.zeros((len(upper), d, d))
    information[:, rows, cols] = upper
    information[:, cols, rows] = upper
    return information


def _check_writable(graph: PoseGraph) -> None:
    """Refuse to write values that `read_g2o` would reject."""
    for name in ("poses", "measurements", "information"):
        values = getattr(graph, name)
        if not np.isfinite(values).all():
            row = int(np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))[0])
            what = f"vertex {graph.vertex_ids[row]}" if name == "poses" else f"edge {row}"
            raise GraphError(f"cannot write g2o: {name} of {what} is not finite")


def _format_records(tag: str, ids: np.ndarray, values: np.ndarray) -> str:
    """Format rows as `TAG id... value...` lines; `%r` (`repr`) gives the shortest exact float text.

    One `%` formatting of all rows at once, about twice as fast as formatting row by row.
    """
    n, num_ids = ids.shape
    line = tag + " %d" * num_ids + " %r" * values.shape[1] + "\n"
    fields = np.hstack((ids.astype(object), values.astype(object)))  # Python ints and floats
    return (line * n) % tuple(fields.ravel().tolist())
