"""g2o's prior records: read before the rest of the file is, written back among the edges.

Layouts (g2o's `read`/`write` of each type, the vertex id first, as g2o's factory reads it):

- `EDGE_SE2_PRIOR id x y theta` + 6 information entries (`x y theta`, egnc's tangent order);
- `EDGE_SE2_XYPRIOR id x y` + 3 information entries;
- `EDGE_SE3_PRIOR id param x y z qx qy qz qw` + 21 information entries (`x y z rx ry rz`);
- `EDGE_SE3_XYZPRIOR id param x y z` + 6 information entries;
- `PARAMS_SE3OFFSET param x y z qx qy qz qw`: the sensor offset a 3D prior names.

A pose prior's residual is `Log(Z^-1 X)` as GTSAM's `PriorFactorPose2/3` (g2o's own error is the
translation and quaternion vector of `Z^-1 X`; egnc reads its information as acting on the tangent,
as it does an edge's and as GTSAM's `readG2o` does). A position prior's is `t - z`, as g2o's.
An `EDGE_SE3_PRIOR` whose offset is not the identity is refused (egnc does not model sensor
offsets); g2o's `EDGE_SE3_XYZPRIOR` ignores its offset in its error, and so does egnc.
`PARAMS_SE3OFFSET` lines are kept verbatim (`PoseGraph.unknown_lines`) and written back.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from egnc.errors import G2oFormatError
from egnc.graph import PoseGraph
from egnc.graph.priors import KIND_NAMES, Priors
from egnc.graph.validity import first_bad_quaternion, not_positive_definite, not_positive_definite_message
from egnc.io.numbers import check_line_characters, format_floats, parse_floats, parse_id, shown

PARAMS = "PARAMS_SE3OFFSET"


@dataclass(frozen=True)
class PriorTag:
    """The layout of one g2o prior record."""

    name: str
    dim: int
    kind: str  # "pose" or "position"
    has_param: bool
    num_measured: int  # measurement fields
    m: int  # residual dimension

    @property
    def num_values(self) -> int:
        """Fields after the ids: measurement and upper-triangle information."""
        return self.num_measured + self.m * (self.m + 1) // 2

    @property
    def num_fields(self) -> int:
        """Fields after the tag."""
        return 1 + self.has_param + self.num_values

    @property
    def layout(self) -> str:
        """The fields, in words, for error messages."""
        ids = "id param" if self.has_param else "id"
        return f"{ids}, {self.num_measured} measurement and {self.num_values - self.num_measured} information entries"


PRIOR_TAGS = {
    tag.name: tag
    for tag in (
        PriorTag("EDGE_SE2_PRIOR", 2, "pose", False, 3, 3),
        PriorTag("EDGE_SE2_XYPRIOR", 2, "position", False, 2, 2),
        PriorTag("EDGE_SE3_PRIOR", 3, "pose", True, 7, 6),
        PriorTag("EDGE_SE3_XYZPRIOR", 3, "position", True, 3, 3),
    )
}
_TAG_OF = {(tag.dim, tag.kind): tag for tag in PRIOR_TAGS.values()}

ErrorFactory = Callable[[str, int], G2oFormatError]


@dataclass
class PriorRecords:
    """The prior and `PARAMS_SE3OFFSET` records of a file, parsed, in file order."""

    tags: list[PriorTag] = field(default_factory=list)
    ids: list[int] = field(default_factory=list)
    param_ids: list[int] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)
    offsets: dict[int, tuple[np.ndarray, int]] = field(default_factory=dict)
    param_lines: list[str] = field(default_factory=list)


def split_prior_lines(text: str, error: ErrorFactory) -> tuple[str, PriorRecords | None]:
    """The text with its prior and `PARAMS_SE3OFFSET` lines blanked (line numbers kept), and those
    records parsed; `(text, None)` unchanged when no prior tag occurs in it (its `PARAMS_SE3OFFSET`
    lines are then unknown tags, as before priors were read).

    Raises:
        G2oFormatError: a prior or parameter line with a wrong field count or a bad number or id.
    """
    if not any(name in text for name in PRIOR_TAGS):  # a file without priors is read as before
        return text, None
    lines = text.split("\n")
    records = PriorRecords()
    for number, raw_line in enumerate(lines, start=1):
        raw_line = raw_line.removesuffix("\r")
        line = raw_line.partition("#")[0]
        fields = line.split()
        if not fields or (fields[0] not in PRIOR_TAGS and fields[0] != PARAMS):
            continue
        problem = check_line_characters(line)
        if problem:
            raise error(problem, number)
        if fields[0] == PARAMS:
            _parse_params(fields, number, records, error)
            records.param_lines.append(raw_line)
        else:
            _parse_prior(PRIOR_TAGS[fields[0]], fields, number, records, error)
        lines[number - 1] = ""
    return "\n".join(lines), records


def _parse_params(fields: list[str], number: int, records: PriorRecords, error: ErrorFactory) -> None:
    """One `PARAMS_SE3OFFSET id x y z qx qy qz qw` record."""
    if len(fields) != 9:
        raise error(f"{PARAMS} needs 8 fields after the tag (id x y z qx qy qz qw), found {len(fields) - 1}", number)
    pid, values = parse_id(fields[1]), parse_floats(fields[2:])
    if pid is None or values is None or not np.all(np.isfinite(values)):
        raise error(f"{PARAMS} has a bad id or number: {' '.join(map(shown, fields[1:]))}", number)
    records.offsets[pid] = (values, number)


def _parse_prior(tag: PriorTag, fields: list[str], number: int, records: PriorRecords, error: ErrorFactory) -> None:
    """One prior record of `tag`'s layout."""
    if len(fields) - 1 != tag.num_fields:
        raise error(
            f"{tag.name} needs {tag.num_fields} fields after the tag ({tag.layout}), found {len(fields) - 1}", number
        )
    ids = [parse_id(token) for token in fields[1 : 2 + tag.has_param]]
    values = parse_floats(fields[2 + tag.has_param :])
    if None in ids:
        raise error(f"{tag.name} has an id that is not an integer: {shown(fields[1 + ids.index(None)])}", number)
    if values is None or not np.all(np.isfinite(values)):
        raise error(f"{tag.name} has a value that is not a finite number", number)
    records.tags.append(tag)
    records.ids.append(int(ids[0]))  # type: ignore[arg-type]
    records.param_ids.append(int(ids[1]) if tag.has_param else 0)  # type: ignore[arg-type]
    records.values.append(values)
    records.lines.append(number)


def priors_of(records: PriorRecords, dim: int, all_ids: np.ndarray, error: ErrorFactory) -> Priors:
    """The `Priors` of a file's records, on the rows of `all_ids` `(N,)`, every value checked.

    Raises:
        G2oFormatError: a prior of the other dimension, on a vertex no VERTEX or EDGE line names,
            with a non-unit quaternion, information that is not positive definite, or naming an
            undeclared or (`EDGE_SE3_PRIOR`) non-identity `PARAMS_SE3OFFSET`; names the line.
    """
    measurements, information = [], []
    for tag, vertex, pid, values, number in zip(
        records.tags, records.ids, records.param_ids, records.values, records.lines
    ):
        if tag.dim != dim:
            raise error(f"{tag.name} is {tag.dim}D but the file's vertices and edges are {dim}D", number)
        row = int(np.searchsorted(all_ids, vertex))
        if row == len(all_ids) or all_ids[row] != vertex:
            raise error(f"{tag.name} names vertex {vertex}, which no VERTEX or EDGE line mentions", number)
        if tag.has_param:
            _check_offset(tag, pid, records, number, error)
        z = values[: tag.num_measured]
        if tag.name == "EDGE_SE3_PRIOR":
            bad = first_bad_quaternion(z[None, 3:7])
            if bad:
                raise error(f"{tag.name} measurement {bad[1]}", number)
        info = np.zeros((tag.m, tag.m))
        rows, cols = np.triu_indices(tag.m)
        info[rows, cols] = info[cols, rows] = values[tag.num_measured :]
        if len(not_positive_definite(info[None])):
            raise error(f"{tag.name}: {not_positive_definite_message(info[None], np.array([0]))}", number)
        measurements.append(z)
        information.append(info)
    rows = np.searchsorted(all_ids, np.asarray(records.ids, dtype=np.int64))
    kinds = [tag.kind for tag in records.tags]
    built = Priors.from_lists(dim, rows.tolist(), kinds, measurements, information)  # type: ignore[arg-type]
    lines, param_ids = np.array(records.lines, dtype=np.int64), np.array(records.param_ids, dtype=np.int64)
    return Priors(dim, built.rows, built.kinds, built.measurements, built.information, lines, param_ids)


def _check_offset(tag: PriorTag, pid: int, records: PriorRecords, number: int, error: ErrorFactory) -> None:
    """A 3D prior's `PARAMS_SE3OFFSET` must be declared, and the identity for a pose prior."""
    if pid not in records.offsets:
        raise error(f"{tag.name} names {PARAMS} {pid}, which no {PARAMS} line declares", number)
    offset, declared = records.offsets[pid]
    identity = np.allclose(offset[:3], 0.0, rtol=0.0, atol=1e-12) and np.allclose(
        np.abs(offset[3:]) / max(float(np.linalg.norm(offset[3:])), 1e-300), (0, 0, 0, 1), rtol=0.0, atol=1e-12
    )
    if tag.kind == "pose" and not identity:
        raise error(
            f"{tag.name} names {PARAMS} {pid} (line {declared}), which is not the identity: "
            "egnc does not model sensor offsets; express the prior in the vertex's own frame",
            number,
        )


def prior_records_text(graph: PoseGraph) -> list[str]:
    """`(K,)` g2o lines of the graph's priors, in prior order, ending in a newline."""
    priors, out = graph.priors, []
    dims = priors.factor_dims
    for k in range(len(priors)):
        tag = _TAG_OF[(graph.dim, KIND_NAMES[priors.kinds[k]])]
        m = int(dims[k])
        rows, cols = np.triu_indices(m)
        ids = f"{graph.vertex_ids[priors.rows[k]]}" + (f" {priors.param_ids[k]}" if tag.has_param else "")
        values = np.concatenate((priors.measurements[k, : tag.num_measured], priors.information[k][rows, cols]))
        out.append(f"{tag.name} {ids} {format_floats(values)}\n")
    return out


def merged_with_priors(graph: PoseGraph, keep: np.ndarray, edge_text: str) -> str:
    """The kept edges' lines `edge_text` and the priors' lines, in the graph's factor order."""
    lines = edge_text.splitlines(keepends=True) + prior_records_text(graph)
    keys = np.concatenate((graph.edge_factor_index[keep], graph.prior_factor_index))
    return _missing_offsets(graph) + "".join(lines[k] for k in np.argsort(keys, kind="stable").tolist())


def _missing_offsets(graph: PoseGraph) -> str:
    """Identity `PARAMS_SE3OFFSET` lines for the ids the 3D priors name and `unknown_lines` do not
    declare (a graph built in Python), so that g2o and egnc read the file back."""
    if graph.dim == 2:
        return ""
    declared = {line.split()[1] for line in graph.unknown_lines if line.split()[:1] == [PARAMS]}
    missing = sorted(set(graph.priors.param_ids.tolist()) - {int(k) for k in declared if k.lstrip("-").isdigit()})
    return "".join(f"{PARAMS} {pid} 0 0 0 0 0 0 1\n" for pid in missing)


def counts_text(graph: PoseGraph) -> str:
    """`"K priors (p pose, q position)"`, or the empty string without priors."""
    if not graph.num_priors:
        return ""
    counts = graph.priors.counts()
    return f"{graph.num_priors} priors ({counts['pose']} pose, {counts['position']} position)"
