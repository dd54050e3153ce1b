"""Read and write Incremental Robot Logs (IRL), riSAM's text format for robust-SLAM datasets.

An IRL file is a 5-line header (name, date `YYYY-MM-DD`, pose dimension 2 or 3, linearity,
free-form notes) followed by one entry per line, in time order:

    TAG NUM_MODES CORRECT_MODE TAG_SPECIFIC MEASUREMENT_1 ... MEASUREMENT_NUM_MODES

- `PRIOR 1 0 id POSE COV`: a prior on one pose.
- `ODOMETRY 1 0 i j POSE COV`: the relative pose `X_i^-1 X_j` (j is the new pose).
- `LOOP NUM_MODES CORRECT_MODE a (b POSE COV | NULL)...`: a loop closure measuring `X_a^-1 X_b`.
  riSAM's generator writes every loop closure as `LOOP 2 c a b POSE COV NULL`: mode 0 is the
  measurement, mode 1 the null hypothesis "this measurement is wrong", so `c = 1` marks a
  ground-truth outlier.

POSE is `x y theta` in 2D and `x y z rx ry rz` in 3D, with the rotation
`Rz(rz) Ry(ry) Rx(rx)` (GTSAM's `Rot3::RzRyRx`). COV is the full covariance matrix, row-major,
d x d (d = 3 or 6): `(x, y, theta)` in 2D. In 3D the format leaves its order to the programs, and
riSAM's two disagree (`egnc.io.irl_covariance`): its C++ reader takes GTSAM's tangent order
`(rx, ry, rz, x, y, z)`, rotation first (`covariance_order="gtsam"`, the default), while its
`g2o-2-irl` converter writes the inverse g2o information in g2o's order `(x, y, z, rx, ry, rz)`
(`covariance_order="g2o"`). For isotropic covariances the two readings agree; for logs converted
from anisotropic g2o files (sphere2500) only "g2o" keeps the g2o file's noise model, and
`read_irl` warns once when the blocks differ and neither the caller nor the notes line chose the
order.
egnc orders its tangent translation first, so the "gtsam" reading block-permutes the information
matrix `COV^-1` (no rescaling), as GTSAM's `readG2o` does the other way round.

egnc reads the entries riSAM's data sets use: every PRIOR and ODOMETRY with one mode, every
LOOP with its measurement as mode 0 and at most a NULL hypothesis as mode 1. Multi-hypothesis
entries are rejected with a one-line error naming the file and line.

The prior: riSAM and GTSAM add a Gaussian prior on the first pose. It is the graph's only
absolute factor, so at the optimum it is satisfied exactly (any solution can be moved rigidly
onto it without changing the relative residuals), and fixing that pose at the prior's value gives
the same optimum whatever the prior's covariance. egnc does exactly that: the initial guess
places the prior's pose at the prior's value (the solver then keeps row 0 fixed; when the prior
is on another pose, that pose is marked `fixed`). The initial guess of every other pose composes
the odometry from there, as riSAM does when the log is replayed; loop closures never initialize.

`IrlLog` keeps the file's own numbers (measurements in the IRL parametrization, covariances as
written) and derives the `PoseGraph` from them, so `write_irl(read_irl(f))` reproduces every
value bit for bit (floats are written with `repr`).

References:
    M. McGann, F. Dellaert, M. Kaess, "Robust Incremental Smoothing and Mapping (riSAM)",
    ICRA 2023; file format in the riSAM repository, `experiments/irl/README.md`.
"""

from __future__ import annotations

import datetime
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from egnc.errors import EgncError, EgncWarning, G2oFormatError, GraphError
from egnc.graph import POSE_SIZE, TANGENT_SIZE, PoseGraph
from egnc.graph.checks import check_instance
from egnc.graph.connectivity import connected_components, describe_components, require_connected
from egnc.graph.index_sets import sorted_unique
from egnc.io.atomic import atomic_text_file
from egnc.io.irl_covariance import (
    CovarianceOrder,
    bad_covariances,
    check_order,
    information,
    information_in_egnc_order,
    order_mark,
    reading_warning,
    to_file_order,
)
from egnc.io.numbers import check_line_characters, format_floats, is_float, parse_id, shown
from egnc.io.text import read_text
from egnc.lie import so3
from egnc.nonlinear.initialize import initialize_poses

__all__ = ["IrlLog", "IrlPrior", "read_irl", "write_irl"]

HEADER_LINES = 5
"""Name, date, pose dimension, linearity, notes."""

IRL_POSE_SIZE = {2: 3, 3: 6}
"""Numbers per pose in an IRL file: `x y theta` or `x y z rx ry rz`."""

_NULL = "NULL"
_ENTRY_TAGS = ("PRIOR", "ODOMETRY", "LOOP")


@dataclass(frozen=True, eq=False)
class IrlPrior:
    """The log's PRIOR entry.

    Attributes:
        vertex_id: the pose it applies to.
        pose: `(M,)` prior mean in the IRL parametrization (`x y theta` or `x y z rx ry rz`).
        covariance: `(d, d)` covariance as written in the file (in the log's `covariance_order`).
    """

    vertex_id: int
    pose: np.ndarray
    covariance: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertex_id", int(self.vertex_id))
        for name in ("pose", "covariance"):
            array = np.array(getattr(self, name), dtype=np.float64)
            array.setflags(write=False)
            object.__setattr__(self, name, array)


@dataclass(frozen=True, eq=False)
class IrlLog:
    """An Incremental Robot Log: the file's entries as arrays, and the pose graph they define.

    Edges are the ODOMETRY and LOOP entries in file order; edge k of `graph` is entry k.

    Attributes:
        name, date, notes: header lines 1, 2 and 5 (stripped).
        dim: pose dimension, 2 or 3 (header line 3).
        edge_ids: `(E, 2)` int64 vertex ids `(i, j)` (ODOMETRY start/end, LOOP pose a/pose b).
        measurements: `(E, M)` relative poses in the IRL parametrization (`M` = 3 or 6).
        covariances: `(E, d, d)` covariances as written (in `covariance_order`).
        is_odometry: `(E,)` bool, ODOMETRY entries (the rest are LOOP entries).
        is_outlier: `(E,)` bool, ground truth: LOOP entries whose correct mode is NULL.
        has_null: `(E,)` bool, LOOP entries that list a NULL hypothesis (mode 1).
        prior: the PRIOR entry, or None when the log has none (egnc then fixes the lowest id).
        entry_lines: `(E,)` 1-based line of each entry in the file (0 when built in memory).
        covariance_order: how the 3D covariances are read, `"gtsam"` (rotation first, riSAM's
            reader, the default) or `"g2o"` (translation first, riSAM's g2o-2-irl output);
            irrelevant in 2D (`egnc.io.irl_covariance`).
        graph: the `PoseGraph` (derived, not a constructor argument): information =
            covariance^-1 in egnc's tangent order, initial guess = odometry composed from the
            prior (see the module docstring).
    """

    name: str
    date: str
    dim: int
    notes: str
    edge_ids: np.ndarray
    measurements: np.ndarray
    covariances: np.ndarray
    is_odometry: np.ndarray
    is_outlier: np.ndarray
    has_null: np.ndarray
    prior: IrlPrior | None = None
    entry_lines: np.ndarray = field(default=None)  # type: ignore[arg-type]
    covariance_order: CovarianceOrder = "gtsam"
    graph: PoseGraph = field(init=False)

    def __post_init__(self) -> None:
        check_order(self.covariance_order)
        if self.dim not in POSE_SIZE:
            raise GraphError(f"IRL pose dimension must be 2 or 3, got {self.dim}")
        for name in ("name", "date", "notes"):
            if "\n" in getattr(self, name) or "\r" in getattr(self, name):
                raise EgncError(f"IRL header field {name} must be a single line")
        num_edges = len(self.edge_ids)
        if self.entry_lines is None:
            object.__setattr__(self, "entry_lines", np.zeros(num_edges, dtype=np.int64))
        m, d = IRL_POSE_SIZE[self.dim], TANGENT_SIZE[self.dim]
        expected = {
            "edge_ids": ((num_edges, 2), np.int64),
            "measurements": ((num_edges, m), np.float64),
            "covariances": ((num_edges, d, d), np.float64),
            "is_odometry": ((num_edges,), bool),
            "is_outlier": ((num_edges,), bool),
            "has_null": ((num_edges,), bool),
            "entry_lines": ((num_edges,), np.int64),
        }
        for name, (shape, dtype) in expected.items():
            array = np.array(getattr(self, name), dtype=dtype)
            if array.shape != shape:
                raise GraphError(f"IrlLog.{name} has shape {array.shape}, expected {shape}")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        if np.any(self.has_null & self.is_odometry):
            raise GraphError("IrlLog: ODOMETRY entries cannot have a NULL hypothesis")
        if np.any(self.is_outlier & ~self.has_null):
            raise GraphError("IrlLog: an outlier entry must list the NULL hypothesis it marks as correct")
        if self.prior is not None and (self.prior.pose.shape != (m,) or self.prior.covariance.shape != (d, d)):
            raise GraphError(f"IrlLog.prior needs a ({m},) pose and a ({d}, {d}) covariance")
        values = [self.measurements.reshape(num_edges, -1), self.covariances.reshape(num_edges, -1)]
        if self.prior is not None:
            values += [self.prior.pose, self.prior.covariance]
        if not all(np.isfinite(v).all() for v in values):
            raise GraphError("IrlLog holds NaN or infinite values")
        if np.any(self.edge_ids < 0):
            raise GraphError("IrlLog: pose ids must be non-negative")
        object.__setattr__(self, "graph", _build_graph(self))

    @property
    def num_edges(self) -> int:
        """Number of ODOMETRY and LOOP entries E."""
        return len(self.edge_ids)

    @classmethod
    def from_graph(
        cls,
        graph: PoseGraph,
        is_outlier: np.ndarray | None = None,
        *,
        name: str = "egnc",
        date: str | None = None,
        notes: str = "",
        prior_covariance: np.ndarray | None = None,
        covariance_order: CovarianceOrder = "gtsam",
    ) -> IrlLog:
        """Describe a pose graph as an IRL log, the way riSAM's g2o converter does.

        Odometry edges (consecutive ids) become ODOMETRY entries, every other edge a LOOP with a
        NULL hypothesis; the prior sits on the lowest id at its pose in `graph`. Covariances are
        the inverse information matrices, in 3D in `covariance_order` (rotation first by default,
        for riSAM's reader), and a 3D log's notes line declares that order (`order_mark`), so
        reading it back with the same order stays silent.

        Args:
            graph: the pose graph; its edge order is kept.
            is_outlier: `(E,)` bool ground-truth outliers (loop closures only); default none.
            name, notes: header lines 1 and 5.
            date: header line 2, `YYYY-MM-DD`; default today.
            prior_covariance: `(d, d)` prior covariance; default `0.1 I`, riSAM's converter default.
            covariance_order: `"gtsam"` or `"g2o"`, the order of the 3D covariances written.
        """
        check_order(covariance_order)
        d = graph.tangent_dim
        is_odometry = graph.is_odometry
        outliers = np.zeros(graph.num_edges, bool) if is_outlier is None else np.asarray(is_outlier, dtype=bool)
        if outliers.shape != (graph.num_edges,) or np.any(outliers & is_odometry):
            raise EgncError(f"is_outlier must be an ({graph.num_edges},) bool mask of loop closures")
        covariances = np.linalg.inv(graph.information)
        covariances = to_file_order(0.5 * (covariances + covariances.swapaxes(1, 2)), graph.dim, covariance_order)
        if graph.dim == 3:
            notes = f"{notes} {order_mark(covariance_order)}" if notes else order_mark(covariance_order)
        prior_pose = _to_irl_poses(graph.dim, graph.poses[:1])[0]
        return cls(
            name=name,
            date=datetime.date.today().isoformat() if date is None else date,
            dim=graph.dim,
            notes=notes,
            edge_ids=graph.vertex_ids[graph.edges],
            measurements=_to_irl_poses(graph.dim, graph.measurements),
            covariances=covariances,
            is_odometry=is_odometry,
            is_outlier=outliers,
            has_null=~is_odometry,
            prior=IrlPrior(
                int(graph.vertex_ids[0]),
                prior_pose,
                0.1 * np.eye(d) if prior_covariance is None else prior_covariance,
            ),
            covariance_order=covariance_order,
        )


def read_irl(path: str | os.PathLike, covariance_order: CovarianceOrder | None = None) -> IrlLog:
    """Read an IRL file (2D or 3D, "nonlinear") into an `IrlLog`.

    Args:
        path: the log.
        covariance_order: the order of a 3D log's covariances: `"gtsam"` (rotation first, as
            riSAM's C++ reader takes them; None, the default, reads so too) or `"g2o"` (translation
            first, as riSAM's g2o-2-irl converter writes them). Ignored in 2D. With the default, when
            the two readings differ on this file and its notes do not declare the order, one
            `EgncWarning` says so; a reading other than the one the notes declare is said too.

    Raises:
        G2oFormatError: the file cannot be read or is malformed; names the file and 1-based line.
        GraphError: the entries are well formed but do not make a solvable graph (a pose not
            reached by odometry, a covariance that is not positive definite).
    """
    check_instance("path", path, (str, os.PathLike), "an IRL file path (str or os.PathLike)")
    if covariance_order is not None:
        check_order(covariance_order)
    path = Path(path)
    text = read_text(path)
    lines = text.split("\n")
    if text.endswith("\n"):
        lines.pop()
    if len(lines) < HEADER_LINES:
        raise G2oFormatError(
            f"IRL header needs {HEADER_LINES} lines (name, date, pose dimension, linearity, notes), found {len(lines)}",
            path,
        )
    name, date, dim_text, linearity, notes = (line.strip() for line in lines[:HEADER_LINES])
    _check_header(path, dim_text, linearity, notes)
    dim = int(dim_text)
    parser = _EntryParser(path, dim, cut_line=len(lines) if not text.endswith("\n") else None)
    for number, line in enumerate(lines[HEADER_LINES:], start=HEADER_LINES + 1):
        parser.parse(line, number)
    if not parser.edge_ids:
        raise G2oFormatError("no ODOMETRY or LOOP entries: a pose graph needs edges", path)
    m, d = IRL_POSE_SIZE[dim], TANGENT_SIZE[dim]
    values = np.array(parser.values, dtype=np.float64)
    lines_array = np.array(parser.lines, dtype=np.int64)
    covariances = values[:, m:].reshape(-1, d, d)
    _check_covariances(covariances, lines_array, path)
    if parser.prior is not None:
        _check_covariances(parser.prior.covariance[None], np.array([parser.prior_line]), path)
    warning = reading_warning(covariances, dim, notes, covariance_order)
    if warning is not None:
        warnings.warn(f"{path}: {warning}", EgncWarning, stacklevel=2)
    try:
        return IrlLog(
            name=name,
            date=date,
            dim=dim,
            notes=notes,
            edge_ids=np.array(parser.edge_ids, dtype=np.int64),
            measurements=values[:, :m],
            covariances=covariances,
            is_odometry=np.array(parser.is_odometry, dtype=bool),
            is_outlier=np.array(parser.is_outlier, dtype=bool),
            has_null=np.array(parser.has_null, dtype=bool),
            prior=parser.prior,
            entry_lines=lines_array,
            covariance_order=covariance_order or "gtsam",
        )
    except GraphError as error:
        raise GraphError(f"{path}: {error}") from None


def _check_header(path: Path, dim_text: str, linearity: str, notes: str) -> None:
    """Refuse a header that is not exactly the five lines, e.g. one without its notes line.

    Without the check, a file whose notes line is missing reads its PRIOR entry as the notes and
    loses the prior without a word.
    """
    if dim_text not in ("2", "3"):
        raise G2oFormatError(f"pose dimension (header line 3) must be 2 or 3, got {shown(dim_text)}", path, 3)
    if linearity != "nonlinear":
        raise G2oFormatError(
            f"linearity (header line 4) is {shown(linearity)}: egnc reads 'nonlinear' logs (poses, not points)",
            path,
            4,
        )
    first_word = notes.split(maxsplit=1)[0] if notes else ""
    if first_word in _ENTRY_TAGS:
        raise G2oFormatError(
            f"header line 5 (notes) is a {first_word} entry: the IRL header has {HEADER_LINES} lines "
            "(name, date, pose dimension, linearity, notes); add the notes line, even empty",
            path,
            5,
        )


def write_irl(log: IrlLog, path: str | os.PathLike) -> None:
    """Write an `IrlLog` as IRL text, atomically: the file is complete or untouched.

    The header, then the PRIOR (if any), then one ODOMETRY or LOOP line per edge in order. Floats
    are written with `repr`, so `read_irl` gives back bit-identical arrays.
    """
    check_instance("log", log, IrlLog)
    check_instance("path", path, (str, os.PathLike), "a file path (str or os.PathLike)")
    lines = [log.name, log.date, str(log.dim), "nonlinear", log.notes]
    if log.prior is not None:
        prior = log.prior
        values = f"{format_floats(prior.pose)} {format_floats(prior.covariance.ravel())}"
        lines.append(f"PRIOR 1 0 {prior.vertex_id} {values}")
    covariances = log.covariances.reshape(log.num_edges, -1)
    for k, ((i, j), odometry, outlier, null) in enumerate(
        zip(log.edge_ids.tolist(), log.is_odometry.tolist(), log.is_outlier.tolist(), log.has_null.tolist())
    ):
        measurement = f"{format_floats(log.measurements[k])} {format_floats(covariances[k])}"
        if odometry:
            lines.append(f"ODOMETRY 1 0 {i} {j} {measurement}")
        elif null:
            lines.append(f"LOOP 2 {int(outlier)} {i} {j} {measurement} {_NULL}")
        else:
            lines.append(f"LOOP 1 0 {i} {j} {measurement}")
    with atomic_text_file(Path(path)) as out:
        out.write("\n".join(lines) + "\n")


class _EntryParser:
    """Accumulates the entries of an IRL file line by line, raising on the first bad line."""

    def __init__(self, path: Path, dim: int, cut_line: int | None):
        self.path = path
        self.dim = dim
        self.cut_line = cut_line
        self.measure_size = IRL_POSE_SIZE[dim] + TANGENT_SIZE[dim] ** 2
        self.edge_ids: list[tuple[int, int]] = []
        self.values: list[list[float]] = []
        self.is_odometry: list[bool] = []
        self.is_outlier: list[bool] = []
        self.has_null: list[bool] = []
        self.lines: list[int] = []
        self.prior: IrlPrior | None = None
        self.prior_line = 0

    def error(self, message: str, line: int) -> G2oFormatError:
        if line == self.cut_line:
            message = f"file looks truncated (last line has no newline): {message}"
        return G2oFormatError(message, self.path, line)

    def parse(self, line: str, number: int) -> None:
        line = line.removesuffix("\r")  # CRLF files
        problem = check_line_characters(line)
        if problem:
            raise self.error(problem, number)
        fields = line.split()
        if not fields:
            return
        tag = fields[0]
        if tag not in _ENTRY_TAGS:
            raise self.error(f"unknown entry tag {shown(tag)}: expected PRIOR, ODOMETRY or LOOP", number)
        if len(fields) < 3:
            raise self.error(f"{tag} needs NUM_MODES and CORRECT_MODE after the tag", number)
        modes = self.integer(fields, 1, "NUM_MODES", number)
        correct = self.integer(fields, 2, "CORRECT_MODE", number)
        if modes < 1 or correct >= modes:
            message = f"{tag} has NUM_MODES {modes} and CORRECT_MODE {correct}: need 0 <= CORRECT_MODE < NUM_MODES"
            raise self.error(message, number)
        k = self.measure_size
        pose = "x y theta" if self.dim == 2 else "x y z rx ry rz"
        d = TANGENT_SIZE[self.dim]
        if tag == "PRIOR":
            self.single_mode(tag, modes, number)
            self.count(fields, 3 + k, f"id, {pose} and the {d}x{d} covariance", tag, number)
            if self.prior is not None:
                message = f"a second PRIOR (the first is on line {self.prior_line}): egnc uses one prior as the gauge"
                raise self.error(message, number)
            vertex_id = self.integer(fields, 3, "pose id", number)
            values = self.floats(fields, 4, number)
            m = IRL_POSE_SIZE[self.dim]
            self.prior = IrlPrior(vertex_id, np.array(values[:m]), np.reshape(values[m:], (d, d)))
            self.prior_line = number
            return
        if tag == "ODOMETRY":
            self.single_mode(tag, modes, number)
            self.count(fields, 4 + k, f"i, j, {pose} and the {d}x{d} covariance", tag, number)
            self.add(fields, number, odometry=True, null=False, outlier=False)
            return
        if modes > 2 or (len(fields) > 4 and fields[4] == _NULL):
            raise self.error(
                f"LOOP with {modes} modes: egnc reads one measurement as mode 0, optionally followed by "
                "NULL as mode 1 (multi-hypothesis loop closures are not supported)",
                number,
            )
        null = modes == 2
        layout = f"a, b, {pose}, the {d}x{d} covariance" + (" and NULL" if null else "")
        self.count(fields, 4 + k + null, layout, f"LOOP with {modes} modes", number)
        if null and fields[-1] != _NULL:
            raise self.error(f"LOOP mode 1 is {shown(fields[-1])}: egnc reads NULL as the second mode", number)
        self.add(fields[: len(fields) - null], number, odometry=False, null=null, outlier=correct == 1)

    def single_mode(self, tag: str, modes: int, number: int) -> None:
        if modes != 1:
            raise self.error(f"{tag} with {modes} modes: egnc reads single-mode {tag} entries", number)

    def count(self, fields: list[str], expected: int, layout: str, what: str, number: int) -> None:
        if len(fields) - 1 != expected:
            raise self.error(
                f"{what} needs {expected} fields after the tag (NUM_MODES, CORRECT_MODE, {layout}), "
                f"found {len(fields) - 1}",
                number,
            )

    def add(self, fields: list[str], number: int, *, odometry: bool, null: bool, outlier: bool) -> None:
        i = self.integer(fields, 3, "pose id", number)
        j = self.integer(fields, 4, "pose id", number)
        if i == j:
            raise self.error(f"entry joins pose {i} to itself", number)
        self.edge_ids.append((i, j))
        self.values.append(self.floats(fields, 5, number))
        self.is_odometry.append(odometry)
        self.has_null.append(null)
        self.is_outlier.append(outlier)
        self.lines.append(number)

    def integer(self, fields: list[str], position: int, what: str, number: int) -> int:
        value = parse_id(fields[position])
        if value is None or value < 0:
            raise self.error(
                f"{fields[0]} field {position} ({what}) is {shown(fields[position])}, "
                "expected a non-negative integer in the int64 range",
                number,
            )
        return value

    def floats(self, fields: list[str], start: int, number: int) -> list[float]:
        for position, token in enumerate(fields[start:], start=start):
            if not is_float(token):
                raise self.error(f"{fields[0]} field {position} is {shown(token)}, expected a number", number)
        values = [float(token) for token in fields[start:]]
        for position, value in enumerate(values, start=start):
            if not np.isfinite(value):
                message = f"{fields[0]} field {position} is {fields[position]}, expected a finite number"
                raise self.error(message, number)
        return values


def _check_covariances(covariances: np.ndarray, lines: np.ndarray, path: Path) -> None:
    """Reject covariances that are not symmetric positive definite, or whose inverse is not."""
    bad, problem = bad_covariances(covariances)
    if len(bad):
        raise G2oFormatError(
            f"{problem}; {len(bad)} of the file's {len(covariances)} such matrices are affected",
            path,
            int(lines[bad[0]]),
        )


def _build_graph(log: IrlLog) -> PoseGraph:
    """The `PoseGraph` of a log: ids, egnc measurements/information, odometry-composed guess."""
    bad, problem = bad_covariances(log.covariances)
    if len(bad):
        where = f"line {log.entry_lines[bad[0]]}" if log.entry_lines[bad[0]] else f"edge {bad[0]}"
        raise GraphError(f"{where}: {problem}")
    ids = log.edge_ids.ravel()
    if log.prior is not None:
        ids = np.append(ids, log.prior.vertex_id)
    vertex_ids = sorted_unique(ids)
    rows = np.searchsorted(vertex_ids, log.edge_ids)
    measurements = _from_irl_poses(log.dim, log.measurements)
    information_matrices = information_in_egnc_order(information(log.covariances), log.dim, log.covariance_order)

    require_connected(vertex_ids, rows)
    root = 0 if log.prior is None else int(np.searchsorted(vertex_ids, log.prior.vertex_id))
    odometry_rows = rows[log.is_odometry]
    count, labels = connected_components(len(vertex_ids), odometry_rows)
    if count > 1:
        raise GraphError(
            f"the odometry does not reach every pose from pose {vertex_ids[root]} "
            f"({count} odometry-connected groups: {describe_components(vertex_ids, labels)}); "
            "IRL poses are initialized by composing odometry"
        )
    poses = np.zeros((len(vertex_ids), POSE_SIZE[log.dim]))
    known = np.zeros(len(vertex_ids), dtype=bool)
    if log.prior is not None:
        poses[root] = _from_irl_poses(log.dim, log.prior.pose[None])[0]
        known[root] = True
    poses = initialize_poses(log.dim, odometry_rows, measurements[log.is_odometry], poses=poses, known=known)
    fixed = np.zeros(len(vertex_ids), dtype=bool)
    # egnc fixes row 0 when nothing is fixed; a prior elsewhere must hold the gauge itself.
    fixed[root] = root != 0
    return PoseGraph(
        dim=log.dim,
        vertex_ids=vertex_ids,
        poses=poses,
        edges=rows,
        measurements=measurements,
        information=information_matrices,
        fixed=fixed,
        edge_lines=log.entry_lines,
    )


def _from_irl_poses(dim: int, poses: np.ndarray) -> np.ndarray:
    """IRL poses `(K, M)` to egnc's stored parametrization `(K, P)`."""
    if dim == 2:
        return np.array(poses, dtype=np.float64)
    return np.concatenate((poses[:, :3], _quaternion_from_rzryrx(poses[:, 3:])), axis=1)


def _to_irl_poses(dim: int, poses: np.ndarray) -> np.ndarray:
    """egnc poses `(K, P)` to the IRL parametrization `(K, M)`."""
    if dim == 2:
        return np.array(poses, dtype=np.float64)
    return np.concatenate((poses[:, :3], _rzryrx_from_rotation(so3.from_quaternion(poses[:, 3:]))), axis=1)


def _quaternion_from_rzryrx(angles: np.ndarray) -> np.ndarray:
    """`(K, 3)` angles `(rx, ry, rz)` of `R = Rz(rz) Ry(ry) Rx(rx)` to `(K, 4)` `[qx, qy, qz, qw]`, `qw >= 0`.

    The product of the half-angle quaternions `q_z(rz) q_y(ry) q_x(rx)`.
    """
    c = np.cos(0.5 * angles)
    s = np.sin(0.5 * angles)
    (cx, cy, cz), (sx, sy, sz) = c.T, s.T
    q = np.stack(
        (
            sx * cy * cz - cx * sy * sz,
            cx * sy * cz + sx * cy * sz,
            cx * cy * sz - sx * sy * cz,
            cx * cy * cz + sx * sy * sz,
        ),
        axis=1,
    )
    return np.where(q[:, 3:] < 0.0, -q, q)


def _rzryrx_from_rotation(R: np.ndarray) -> np.ndarray:
    """`(K, 3, 3)` rotations to `(K, 3)` angles `(rx, ry, rz)` with `R = Rz(rz) Ry(ry) Rx(rx)`.

    `ry` in `[-pi/2, pi/2]`. At gimbal lock (`cos ry = 0`) only `rz -/+ rx` is defined; `rx = 0`
    is chosen there.
    """
    cos_y = np.hypot(R[:, 0, 0], R[:, 1, 0])
    ry = np.arctan2(-R[:, 2, 0], cos_y)
    locked = cos_y < 1e-12
    rx = np.where(locked, 0.0, np.arctan2(R[:, 2, 1], R[:, 2, 2]))
    rz = np.where(locked, np.arctan2(-R[:, 0, 1], R[:, 1, 1]), np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    return np.stack((rx, ry, rz), axis=1)
