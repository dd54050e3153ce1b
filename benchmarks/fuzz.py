"""Fuzz the g2o reader and the solver with seeded mutants of real and generated pose graphs.

Each mutant is a small g2o text changed by one random operator (byte flips, truncation, deleted,
repeated or swapped lines, swapped fields, huge, tiny and non-numeric numbers, Unicode separators,
CRLF, foreign tags). For each one:

- reading must give a `PoseGraph` or an `EgncError`;
- an accepted graph is solved with `l2` and `egnc` (a few iterations per stage): the result must be
  finite or an `EgncError`; its JSON report must be strict JSON;
- nothing may be printed on stdout (file descriptor 1, so BLAS messages count too).

`python benchmarks/fuzz.py [--cases N] [--seed S]` prints the outcomes by class as a markdown table
(recorded in RELIABILITY.md) and exits 1 if any mutant ended in another exception, a non-finite
result, stdout output or invalid JSON. `tests/test_fuzz.py` runs the same kind of cases, fewer.
"""

from __future__ import annotations

import argparse
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
from egnc.io import read_g2o, write_g2o

DATASETS = Path(__file__).parents[1] / "datasets"
METHODS = ("l2", "egnc")
SOLVER_OPTIONS = egnc.SolverOptions(max_iterations=5)
GNC_OPTIONS = egnc.GncOptions(max_stages=8)
"""Few iterations and stages: the fuzzer looks for crashes and non-finite numbers, not optima."""
BAD_OUTCOMES = ("crash", "non-finite result", "stdout output", "invalid JSON")
"""Outcome classes that are bugs."""

SPECIAL_NUMBERS = (
    "1e300", "-1e300", "1e20", "1e-320", "5e-324", "0", "-0", "nan", "-inf", "1e400", "1e+05",
    "1_0", "+3", "\u0663", "0x10", "1.2.3", "--1", "", "99999999999999999999",
)  # fmt: skip
SEPARATORS = ("\x1c", "\u2028", "\xa0", "\r", "\x0b", "\t", "\x00")
OPERATORS = (
    "byte", "truncate", "delete line", "repeat line", "swap lines", "number", "swap fields", "separator", "crlf",
    "foreign line", "scale",
)  # fmt: skip
FOREIGN_LINES = ("VERTEX_XY 9999 1 2", "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1", "FIX 0", "FIX 123456")


def source_texts(poses: int = 30) -> dict[str, str]:
    """Small g2o texts to mutate: the first `poses` poses of each shipped file, and two generated graphs."""
    texts = {}
    with tempfile.TemporaryDirectory() as folder:
        for path in sorted(DATASETS.glob("*.g2o")):
            graph = read_g2o(path)
            keep = (graph.edges < poses).all(axis=1)
            small = egnc.PoseGraph(
                graph.dim, graph.vertex_ids[:poses], graph.poses[:poses], graph.edges[keep],
                graph.measurements[keep], graph.information[keep],
            )  # fmt: skip
            out = Path(folder) / path.name
            write_g2o(small, out)
            texts[path.name] = out.read_text()
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


def mutate(text: str, rng: random.Random) -> tuple[str, str]:
    """One random mutation of a g2o text: `(operator name, mutated text)`."""
    lines = text.split("\n")
    k = rng.randrange(len(lines))
    fields = lines[k].split(" ")
    operator = rng.choice(OPERATORS)
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


def run_case(text: str, operator: str, folder: Path) -> Outcome:
    """Read the mutant and solve it when accepted, classifying each step."""
    path = folder / "mutant.g2o"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    solves = []
    with stdout_captured() as output:
        try:
            graph = read_g2o(path, skip_unknown=True)
            read = "graph"
        except EgncError:
            read = "clean error"
        except Exception:  # noqa: BLE001 - the class of failure is the finding
            read = "crash"
        if read == "graph":
            solves = [_solve(graph, method) for method in METHODS]
    return Outcome(operator, read, solves, stdout=bool(output[0]))


def _solve(graph: egnc.PoseGraph, method: str) -> str:
    try:
        result = egnc.solve(graph, method, linear_solver="scipy", options=SOLVER_OPTIONS, gnc_options=GNC_OPTIONS)
    except EgncError:
        return "solver error"
    except Exception:  # noqa: BLE001
        return "crash"
    if not (np.isfinite(result.graph.poses).all() and np.isfinite(result.residual_norms).all()):
        return "solver failure reported" if result.status == 5 else "non-finite result"
    try:
        json.dumps(report_dict(result, []), allow_nan=False)
    except ValueError:
        return "invalid JSON"
    return "finite"


def fuzz(cases: int, seed: int) -> list[Outcome]:
    """Run `cases` mutants, cycling over the source texts, from one seed."""
    rng = random.Random(seed)
    texts = list(source_texts().values())
    outcomes = []
    with tempfile.TemporaryDirectory() as folder:
        for case in range(cases):
            operator, mutant = mutate(texts[case % len(texts)], rng)
            outcomes.append(run_case(mutant, operator, Path(folder)))
    return outcomes


def bad(outcome: Outcome) -> list[str]:
    """The bug classes of one outcome (empty when it behaved)."""
    found = [outcome.read] if outcome.read == "crash" else []
    found += [solve for solve in outcome.solves if solve in BAD_OUTCOMES]
    return found + (["stdout output"] if outcome.stdout else [])


READ_CLASSES = ("graph", "clean error", "crash")
SOLVE_CLASSES = ("finite", "solver error", "solver failure reported", "non-finite result", "invalid JSON", "crash")


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
    lines = ["| operator | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for operator in [*sorted(set(rows) - {"**all**"}), "**all**"]:
        lines.append(f"| {operator} | " + " | ".join(str(rows[operator][c]) for c in columns) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=2000, help="number of mutants (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    args = parser.parse_args(argv)
    outcomes = fuzz(args.cases, args.seed)
    print(table(outcomes))
    return 1 if any(bad(outcome) for outcome in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
