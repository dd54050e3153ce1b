"""Fuzz target `files`: mutated g2o and IRL texts, read and solved.

Each mutant is a small g2o or IRL text changed by one random operator (byte flips,
truncation, deleted, repeated or swapped lines, swapped fields, huge, tiny and non-numeric numbers,
Unicode separators, CRLF, foreign tags; since issue 19 also integers of 5000 digits, a byte-order
mark, TORO records, a 2 MiB line, FIX on every vertex and a deleted IRL header line; since issue 56
the ids moved, in order, to int64's limits, a pose first reached by a loop closure and a prior on a
later pose, `ONLINE_OPERATORS`). For each one:

- reading must give a `PoseGraph` or an `EgncError`, within `TIME_LIMIT_S` (else a hang); the
  mutants that are invalid by construction (`INVALID_OPERATORS`) must give the error, those
  valid by construction (`VALID_OPERATORS`) the graph;
- an accepted graph is solved with `l2` and `egnc` (a few iterations per stage): the result must be
  finite or an `EgncError`; its JSON report must be strict JSON; a graph with every vertex fixed
  must come back with the "nothing to optimize" status, not "converged";
- the mutants of `ONLINE_OPERATORS` are also replayed online, as `egnc-solve --online` does
  (`egnc.online.replay`): where the batch `egnc` solve is finite, the replay must be too, not an
  `EgncError` ("online refused");
- nothing may be printed on stdout (file descriptor 1, so BLAS messages count too).

Run from `benchmarks/fuzz.py --target files`; `tests/test_fuzz.py` runs fewer cases.
"""

from __future__ import annotations

import collections
import contextlib
import json
import os
import random
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import egnc
from egnc.cli.report import report_dict
from egnc.errors import EgncError
from egnc.io import IrlLog, read_g2o, read_irl, write_g2o, write_irl
from egnc.nonlinear.least_squares import NOTHING_TO_OPTIMIZE
from egnc.online.replay import replay

from .fuzz_core import TIME_LIMIT_S, Hang, counts_table, time_limit
from .paths import SHIPPED_DATASETS

METHODS = ("l2", "egnc")
SOLVER_OPTIONS = egnc.SolverOptions(max_iterations=5)
GNC_OPTIONS = egnc.GncOptions(max_stages=8)
"""Few iterations and stages: the fuzzer looks for crashes and non-finite numbers, not optima."""
BAD_OUTCOMES = ("crash", "hang", "accepted invalid", "refused valid", "non-finite result",
                "converged with nothing to solve", "stdout output", "invalid JSON", "online refused")  # fmt: skip
"""Outcome classes that are bugs."""

SPECIAL_NUMBERS = (
    "1e300", "-1e300", "1e20", "1e-320", "5e-324", "0", "-0", "nan", "-inf", "1e400", "1e+05",
    "1_0", "+3", "\u0663", "0x10", "1.2.3", "--1", "", "99999999999999999999",
)  # fmt: skip
SEPARATORS = ("\x1c", "\u2028", "\xa0", "\r", "\x0b", "\t", "\x00")
OPERATORS = (
    "byte", "truncate", "delete line", "repeat line", "swap lines", "number", "swap fields", "separator", "crlf",
    "foreign line", "scale", "huge integer", "bom", "toro", "long line", "fix all", "drop header line",
    "int64 ids", "loop first", "prior later",
)  # fmt: skip
INVALID_OPERATORS = ("huge integer", "long line", "drop header line")
"""Operators whose every mutant is invalid: reading it must fail with an `EgncError`. An integer field
of 5000 digits is out of range wherever it stands; a 2 MiB line is over the readers' bound; an IRL
header without one of its five lines shifts the others (without its notes line the PRIOR used to be
read as the notes)."""
VALID_OPERATORS = ("int64 ids",)
"""Operators whose every mutant is valid: reading it must give a graph. Ids moved in order to the
ends of int64 (issue 56: `[int64 min, 1]` was refused as unsorted, `np.diff` wrapping around)."""
INT64_MIN, INT64_MAX = int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max)
ONLINE_OPERATORS = ("loop first", "prior later")
"""Operators of valid graphs the online replay used to refuse (issue 56): ids `k` and `k + 2` swapped
(in a g2o file pose `k + 2` is then first reached by a loop closure; in an IRL log, whose odometry
must reach every pose, by odometry that reaches poses out of order); a g2o `FIX` or the IRL PRIOR
on a later pose."""
G2O_ONLY = ("toro", "fix all", "int64 ids")
IRL_ONLY = ("drop header line",)
TORO_ORDER = (0, 1, 3, 5, 2, 4)
"""g2o's upper triangle `I11 I12 I13 I22 I23 I33` to TORO's `I11 I12 I22 I33 I13 I23`."""
FOREIGN_LINES = ("VERTEX_XY 9999 1 2", "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1", "FIX 0", "FIX 123456")


def source_texts(poses: int = 30) -> dict[str, str]:
    """Small g2o texts to mutate: the first `poses` poses of each shipped file, and two generated graphs."""
    texts = {}
    with tempfile.TemporaryDirectory() as folder:
        for path in sorted(SHIPPED_DATASETS.glob("*.g2o")):
            small = read_g2o(path).first_poses(poses)
            out = Path(folder) / path.name
            write_g2o(small, out)
            texts[path.name] = out.read_text()
            log = IrlLog.from_graph(small, date="2026-11-25", notes="fuzz source")
            write_irl(log, out.with_suffix(".irl"))
            texts[f"{path.stem}.irl"] = out.with_suffix(".irl").read_text()
    texts["generated_2d"] = _generated(2)
    texts["generated_3d"] = _generated(3)
    return texts


def _generated(dim: int) -> str:
    """A square loop of 8 poses with two loop closures, written by hand as g2o text."""
    vertex, edge = ("VERTEX_SE2", "EDGE_SE2") if dim == 2 else ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT")
    d = 3 if dim == 2 else 6
    information = " ".join("1.0" if r == c else "0.0" for r in range(d) for c in range(r, d))
    step = "1 0 0.7853981633974483" if dim == 2 else "1 0 0 0 0 0.3826834323650898 0.9238795325112867"
    rest = "0 0 0" if dim == 2 else "0 0 0 0 0 0 1"
    lines = [f"{vertex} {k} {k * 0.9} {rest[2:]}" for k in range(8)]
    lines += [f"{edge} {k} {k + 1} {step} {information}" for k in range(7)]
    lines += [f"{edge} 7 0 {step} {information}", f"{edge} 2 6 {rest} {information}"]
    return "\n".join(lines) + "\n"


def mutate(text: str, rng: random.Random, irl: bool = False) -> tuple[str, str]:
    """One random mutation of a g2o (or IRL) text: `(operator name, mutated text)`."""
    lines = text.split("\n")
    k = rng.randrange(len(lines))
    fields = lines[k].split(" ")
    excluded = G2O_ONLY if irl else IRL_ONLY
    operator = rng.choice([name for name in OPERATORS if name not in excluded])
    if operator in ("huge integer", "bom", "toro", "long line", "fix all", "drop header line"):
        return operator, _mutate_issue19(operator, lines, rng)
    if operator == "int64 ids":
        return operator, _ids_at_int64_limits(lines, rng)
    if operator in ONLINE_OPERATORS:
        return operator, _mutate_online(operator, lines, rng, irl)
    if operator == "byte":  # any byte, so invalid UTF-8 too (kept as a surrogate escape until written)
        data = bytearray(text.encode("utf-8", "surrogateescape"))
        data[rng.randrange(len(data))] = rng.randrange(256)
        return operator, data.decode("utf-8", "surrogateescape")
    if operator == "truncate":
        return operator, text[: rng.randrange(len(text))]
    if operator == "delete line":
        del lines[k]
    elif operator == "repeat line":
        lines.insert(k, lines[k])
    elif operator == "swap lines":
        j = rng.randrange(len(lines))
        lines[k], lines[j] = lines[j], lines[k]
    elif operator == "number":
        fields[rng.randrange(len(fields))] = rng.choice(SPECIAL_NUMBERS)
    elif operator == "swap fields":
        i, j = rng.randrange(len(fields)), rng.randrange(len(fields))
        fields[i], fields[j] = fields[j], fields[i]
    elif operator == "separator":
        fields.insert(rng.randrange(len(fields) + 1), rng.choice(SEPARATORS))
    elif operator == "crlf":
        return operator, text.replace("\n", "\r\n")
    elif operator == "foreign line":
        lines.insert(k, rng.choice(FOREIGN_LINES))
    else:  # scale: every number of the line times a huge or tiny factor
        factor = rng.choice((1e8, 1e20, 1e150, 1e-200))
        fields = [fields[0]] + [_scaled(field, factor) for field in fields[1:]]
    if operator in ("number", "swap fields", "separator", "scale"):
        lines[k] = " ".join(fields)
    return operator, "\n".join(lines)


def _mutate_issue19(operator: str, lines: list[str], rng: random.Random) -> str:
    """The operators added with issue 19 (see the module docstring)."""
    if operator == "huge integer":  # an integer field anywhere: an id, a count, a number written as "0"
        spots = [(k, j) for k, line in enumerate(lines) for j, token in enumerate(line.split(" ")) if token.isdigit()]
        k, j = rng.choice(spots)
        fields = lines[k].split(" ")
        fields[j] = rng.choice(("-", "", "0" * 4400)) + "9" * rng.choice((4301, 5000))  # past the digit limit
        lines[k] = " ".join(fields)
    elif operator == "bom":
        return "\ufeff" + "\n".join(lines)
    elif operator == "toro":  # some 2D records as TORO's VERTEX2 / EDGE2: the same graph
        lines = [_toro(line) if rng.random() < 0.5 else line for line in lines]
    elif operator == "long line":
        lines.insert(rng.randrange(len(lines) + 1), "# " + "x" * (2 << 20))
    elif operator == "fix all":
        ids = {token for line in lines if line.startswith(("VERTEX", "EDGE")) for token in line.split(" ")[1:3]}
        ids = {token for token in ids if token.lstrip("-").isdigit()}
        lines.append("FIX " + " ".join(sorted(ids)))
    else:  # drop header line (IRL)
        del lines[rng.randrange(5)]
    return "\n".join(lines)


def _ids_at_int64_limits(lines: list[str], rng: random.Random) -> str:
    """Every vertex id moved, keeping their order, to int64's minimum end, its maximum end, or the
    lower half to the one and the upper half to the other (a graph as valid as the source)."""
    ids = sorted({int(field) for line in lines for field in _id_fields(line)[1]})
    if not ids:
        return "\n".join(lines)
    low, high, middle = ids[0], ids[-1], ids[len(ids) // 2]
    mode = rng.choice(("min", "max", "both"))

    def moved(vertex: int) -> int:
        if mode == "min" or (mode == "both" and vertex < middle):
            return INT64_MIN + (vertex - low)
        return INT64_MAX - (high - vertex)

    out = []
    for line in lines:
        fields, positions = line.split(" "), _id_fields(line)[0]
        for k in positions:
            fields[k] = str(moved(int(fields[k])))
        out.append(" ".join(fields))
    return "\n".join(out)


def _id_fields(line: str) -> tuple[list[int], list[str]]:
    """The positions and texts of the vertex ids of a g2o line (VERTEX*, EDGE*, FIX); none for others."""
    fields = line.split(" ")
    if fields[0].startswith("VERTEX"):
        positions = [1]
    elif fields[0].startswith("EDGE"):
        positions = [1, 2]
    elif fields[0] == "FIX":
        positions = list(range(1, len(fields)))
    else:
        positions = []
    positions = [k for k in positions if k < len(fields) and fields[k].lstrip("-").isdigit()]
    return positions, [fields[k] for k in positions]


def _mutate_online(operator: str, lines: list[str], rng: random.Random, irl: bool) -> str:
    """The operators of issue 56 (`ONLINE_OPERATORS`): valid graphs whose poses a replay meets out of order."""
    ids = sorted({int(line.split(" ")[1]) for line in lines if line.startswith("VERTEX")})
    if irl:
        ids = sorted({int(token) for line in lines if line.startswith("ODOMETRY") for token in line.split(" ")[3:5]})
    k = rng.choice(ids[1:-2]) if len(ids) > 3 else ids[-1]
    if operator == "prior later" and irl:
        return "\n".join(_with_fields(line, {3: str(k)}) if line.startswith("PRIOR") else line for line in lines)
    if operator == "prior later":
        return "\n".join([*lines, f"FIX {k}"])
    swap = {str(k): str(k + 2), str(k + 2): str(k)}  # pose k + 2 then sits where k was
    positions = {"ODOMETRY": (3, 4), "LOOP": (3, 4)} if irl else {"VERTEX": (1,), "EDGE": (1, 2)}
    for n, line in enumerate(lines):
        places = next((spots for tag, spots in positions.items() if line.startswith(tag)), ())
        fields = line.split(" ")
        lines[n] = _with_fields(line, {p: swap[fields[p]] for p in places if fields[p] in swap})
    return "\n".join(lines)


def _with_fields(line: str, values: dict[int, str]) -> str:
    """`line` with its space-separated fields at the positions of `values` replaced."""
    fields = line.split(" ")
    for position, value in values.items():
        fields[position] = value
    return " ".join(fields)


def _toro(line: str) -> str:
    """A `VERTEX_SE2` or `EDGE_SE2` line in TORO's form (other lines unchanged)."""
    fields = line.split(" ")
    if fields[0] == "VERTEX_SE2":
        return " ".join(["VERTEX2", *fields[1:]])
    if fields[0] == "EDGE_SE2" and len(fields) == 12:
        upper = fields[6:]
        return " ".join(["EDGE2", *fields[1:6], *(upper[k] for k in TORO_ORDER)])
    return line


def _scaled(field: str, factor: float) -> str:
    try:
        return repr(float(field) * factor) if "." in field or "e" in field else field
    except ValueError:
        return field


@dataclass
class Outcome:
    """What happened to one mutant."""

    operator: str
    read: str  # one of READ_CLASSES
    solves: list[str]  # per method, one of SOLVE_CLASSES
    stdout: bool


@contextlib.contextmanager
def stdout_captured() -> Iterator[list[bytes]]:
    """Capture file descriptor 1 (Python and C output alike) into the yielded list's one element."""
    sys.stdout.flush()
    saved = os.dup(1)
    captured: list[bytes] = []
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 1)
        try:
            yield captured
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
            sink.seek(0)
            captured.append(sink.read())


def run_case(text: str, operator: str, folder: Path, irl: bool = False) -> Outcome:
    """Read the mutant and solve it when accepted, classifying each step."""
    path = folder / ("mutant.irl" if irl else "mutant.g2o")
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    solves: list[str] = []
    with stdout_captured() as output:
        try:
            with time_limit(TIME_LIMIT_S):
                log = read_irl(path) if irl else None
                graph = log.graph if log is not None else read_g2o(path, skip_unknown=True)
                read = "accepted invalid" if operator in INVALID_OPERATORS else "graph"
                solves = [_solve(graph, method) for method in METHODS]
                if operator in ONLINE_OPERATORS:
                    known = log.is_odometry if log is not None else graph.is_odometry
                    solves.append(_replay(graph, known, batch_finite=solves[-1] == "finite"))
        except Hang:
            read, solves = ("hang", []) if not solves else (read, [*solves, "hang"])
        except EgncError:
            read = "refused valid" if operator in VALID_OPERATORS else "clean error"
        except Exception:  # noqa: BLE001 - the class of failure is the finding
            read = "crash"
    return Outcome(operator, read, solves, stdout=bool(output[0]))


def _solve(graph: egnc.PoseGraph, method: str) -> str:
    try:
        result = egnc.solve(graph, method, linear_solver="scipy", options=SOLVER_OPTIONS, gnc_options=GNC_OPTIONS)
    except EgncError:
        return "solver error"
    except Exception:  # noqa: BLE001
        return "crash"
    if graph.fixed.all():
        return "nothing to optimize" if result.status == NOTHING_TO_OPTIMIZE else "converged with nothing to solve"
    if not (np.isfinite(result.graph.poses).all() and np.isfinite(result.residual_norms).all()):
        return "solver failure reported" if result.status == 5 else "non-finite result"
    try:
        json.dumps(report_dict(result, []), allow_nan=False)
    except ValueError:
        return "invalid JSON"
    return "finite"


def _replay(graph: egnc.PoseGraph, known: np.ndarray, batch_finite: bool) -> str:
    """Replay `graph` online (`known`: `(E,)` odometry) as `egnc-solve --online` does; classify it."""
    try:
        outcome = replay(graph, "egnc", known_inliers=known, linear_solver="scipy", options=SOLVER_OPTIONS)
    except EgncError:
        return "online refused" if batch_finite else "online error"
    except Exception:  # noqa: BLE001
        return "crash"
    return "online finite" if np.isfinite(outcome.result.graph.poses).all() else "non-finite result"


def fuzz(cases: int, seed: int) -> list[Outcome]:
    """Run `cases` mutants, cycling over the source texts, from one seed."""
    rng = random.Random(seed)
    sources = list(source_texts().items())
    outcomes = []
    with tempfile.TemporaryDirectory() as folder:
        for case in range(cases):
            name, text = sources[case % len(sources)]
            irl = name.endswith(".irl")
            operator, mutant = mutate(text, rng, irl=irl)
            outcomes.append(run_case(mutant, operator, Path(folder), irl=irl))
    return outcomes


def bad(outcome: Outcome) -> list[str]:
    """The bug classes of one outcome (empty when it behaved)."""
    found = [outcome.read] if outcome.read in BAD_OUTCOMES else []
    found += [solve for solve in outcome.solves if solve in BAD_OUTCOMES]
    return found + (["stdout output"] if outcome.stdout else [])


READ_CLASSES = ("graph", "clean error", "accepted invalid", "refused valid", "crash", "hang")
SOLVE_CLASSES = (
    "finite", "nothing to optimize", "solver error", "solver failure reported", "non-finite result",
    "converged with nothing to solve", "invalid JSON", "online finite", "online error", "online refused", "crash",
    "hang",
)  # fmt: skip


def table(outcomes: list[Outcome]) -> str:
    """Markdown: per operator, mutants, read outcomes, solve outcomes (both methods) and stdout output."""
    columns = ["mutants", *(f"read: {c}" for c in READ_CLASSES), *(f"solve: {c}" for c in SOLVE_CLASSES), "stdout"]
    rows: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for outcome in outcomes:
        for counts in (rows[outcome.operator], rows["**all**"]):
            counts["mutants"] += 1
            counts[f"read: {outcome.read}"] += 1
            counts.update(f"solve: {solve}" for solve in outcome.solves)
            counts["stdout"] += outcome.stdout
    return counts_table(rows, columns, "operator")


def run_target(cases: int, seed: int) -> tuple[str, int]:
    """The files target for `fuzz.py`: its table and the number of cases that are bugs."""
    outcomes = fuzz(cases, seed)
    return table(outcomes), sum(bool(bad(outcome)) for outcome in outcomes)
