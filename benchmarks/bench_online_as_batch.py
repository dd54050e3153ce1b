"""Should the batch default graduate online? Today's `egnc.solve` against the file replayed online.

    python benchmarks/bench_online_as_batch.py [--data DIR_OR_FILE] [--files csail,intel]
        [--percent 30] [--seed 0] [--timeout 600] [--information nearest-pd]
        [--linear-solver auto] [--json results.jsonl]

Every `.g2o` and `.irl` file of `--data` (default: the shared datasets; a single file also works),
smallest first, or the names given by `--files` in that order, is solved two ways:

- `batch`: today's default, `egnc.solve(graph)` (method egnc, restarted stages);
- `online`: `egnc.online.replay.replay(graph, "egnc")`, the file replayed pose by pose through the
  online solver (EGNC's per-loop `mu*` graduation from the running estimate), ending with
  `OnlineSolver.result()`, the batch decision (`egnc.robust.decision`) on the online estimate.

Both on the clean graph and on each corruption: riSAM-protocol false loops
(`egnc.datasets.add_false_loops(graph, percent, seed=seed, reference_poses=<clean LS optimum>)`,
as `benchmarks/bench_online.py` builds them), the odometry as known inliers. An IRL log is solved
without its labelled outliers (`clean`) and as shipped, scored against its labels (`--percent`
does not apply to it). The reference of a graph is the least-squares optimum of its clean version
(`egnc.solve(graph, "l2")`).

Every run, and every reference solve, is its own forked child process (`egnc.bench.child`),
killed after `--timeout` seconds ("> N s"): its time and memory are its own, one at a time. A
graph the online solver cannot take in order (a loop closure to a pose no earlier edge reached,
`egnc.errors.GraphError`) is reported as "not replayable" with the message.

Columns, for each of `batch` and `online`:
- `s`: seconds of the call alone (`egnc.solve` or the whole `replay`, final decision included;
  reading, corrupting and the reference excluded).
- `rej`: loop closures rejected; `true rej`: true loops among them; `false kept`: false loops
  accepted (0 on clean graphs).
- `P / R or cost`: with false loops, precision / recall of the rejection, outliers positive; on a
  clean graph, the least-squares cost of the result over all edges divided by that of the
  least-squares optimum (1.0000: as good as least squares; below 1: a better minimum).
- `ATE`: metres, against the clean least-squares optimum, after rigid alignment.
- `MiB`: the child's peak resident memory (it includes the parent's pages at the fork).
Then `same rej`: whether both reject exactly the same edges, and `online / batch`: the ratio of
times measured in the same run of this script.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.graph import PoseGraph

DATASETS = Path(os.environ.get("EGNC_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets"))
METHODS = ("batch", "online")


@dataclass(frozen=True, eq=False)
class Variant:
    """One graph to solve both ways.

    Attributes:
        name: "clean", or the false-loop percentage ("30 %", "31 % (labels)").
        graph: the graph.
        is_outlier: `(E,)` bool ground truth (all false on a clean graph).
        known_inliers: `(E,)` bool, the odometry.
        reference: `(N, P)` the clean least-squares optimum.
        least_squares_cost: the least-squares cost of `graph` at its own least-squares optimum
            (clean variants only, else nan).
    """

    name: str
    graph: PoseGraph
    is_outlier: np.ndarray
    known_inliers: np.ndarray
    reference: np.ndarray
    least_squares_cost: float


def least_squares(graph: PoseGraph, known_inliers: np.ndarray, linear_solver: str) -> tuple[np.ndarray, float]:
    """The least-squares optimum `(N, P)` of `graph` and its cost (the child's side)."""
    from egnc.api import solve

    result = solve(graph, "l2", known_inliers=known_inliers, linear_solver=linear_solver)
    return result.graph.poses, result.cost


def solve_and_score(variant: Variant, method: str, linear_solver: str) -> dict:
    """Solve `variant` with `method` ("batch" or "online") and score it (the child's side)."""
    from egnc.api import solve
    from egnc.errors import GraphError
    from egnc.metrics import ate, precision_recall
    from egnc.online.replay import replay

    graph, known = variant.graph, variant.known_inliers
    started = time.perf_counter()
    if method == "batch":
        result = solve(graph, known_inliers=known, linear_solver=linear_solver)
    else:
        try:
            result = replay(graph, "egnc", known_inliers=known, linear_solver=linear_solver).result
        except GraphError as error:
            return {"not_replayable": " ".join(str(error).split())}
    seconds = time.perf_counter() - started
    rejected = ~result.inliers
    least_squares_cost = variant.least_squares_cost  # nan with false loops
    precision, recall = precision_recall(rejected, variant.is_outlier)
    return {
        "s": seconds,
        "rejected_edges": np.flatnonzero(rejected).tolist(),
        "rej": int(rejected.sum()),
        "true_rej": int((rejected & ~variant.is_outlier).sum()),
        "false_kept": int((~rejected & variant.is_outlier).sum()),
        "P": precision,
        "R": recall,
        "cost_ratio": result.cost / least_squares_cost if least_squares_cost > 0 else float("nan"),
        "ate": ate(result.graph.poses, variant.reference, graph.dim),
        "mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,  # kilobytes on Linux
        "warnings": list(result.warnings),
    }


def run(target, args: tuple, timeout_s: float) -> dict:
    """`target(*args)` in a forked child killed after `timeout_s`; its dict, or `{"status": ...}`."""
    from egnc.bench.child import run_in_child

    outcome = run_in_child(target, args, timeout_s)
    if outcome.status == "ok":
        return {"status": "ok", "value": outcome.value}
    return {"status": outcome.status}


def files(data: Path, names: str) -> list[Path]:
    """The `.g2o` and `.irl` files of `data` (or `data` itself), smallest first, or `names` in order."""
    if data.is_file():
        found = [data]
    else:
        found = sorted((p for p in data.iterdir() if p.suffix in (".g2o", ".irl")), key=lambda p: p.stat().st_size)
    if not names:
        return found
    by_stem = {path.stem: path for path in found}
    missing = [name for name in names.split(",") if name not in by_stem]
    if missing:
        raise SystemExit(f"not found in {data}: {', '.join(missing)}")
    return [by_stem[name] for name in names.split(",")]


def variants(path: Path, args: argparse.Namespace):
    """Every `Variant` of one file, lazily; a string (the row's message) where one cannot be built."""
    from egnc.datasets import add_false_loops
    from egnc.errors import EgncError
    from egnc.io import read_g2o, read_irl

    try:
        if path.suffix == ".irl":
            log = read_irl(path)
            graph, known, labels = log.graph.subgraph_edges(~log.is_outlier), log.is_odometry[~log.is_outlier], log
        else:
            graph = read_g2o(path, information=args.information)
            known, labels = graph.is_odometry, None
    except EgncError as error:
        yield f"cannot read: {' '.join(str(error).split())}"
        return
    solved = run(least_squares, (graph, known, args.linear_solver), args.timeout)
    if solved["status"] != "ok":
        yield f"reference (least squares): {solved['status']}"
        return
    reference, cost = solved["value"]
    yield Variant("clean", graph, np.zeros(graph.num_edges, dtype=bool), known, reference, cost)
    if labels is not None:
        share = 100.0 * labels.is_outlier.sum() / max(1, (~labels.is_odometry).sum())
        yield Variant(f"{share:.0f} % (labels)", labels.graph, labels.is_outlier, labels.is_odometry, reference, np.nan)
        return
    for percent in (float(p) for p in filter(None, args.percent.split(","))):
        try:
            corrupted = add_false_loops(graph, percent, seed=args.seed, reference_poses=reference)
        except EgncError as error:
            yield f"{percent:g} %: {error}"
            continue
        g = corrupted.graph
        yield Variant(f"{percent:g} %", g, corrupted.is_outlier, g.is_odometry, reference, np.nan)


HEADER = (
    "| file | variant | batch s | rej | true rej | false kept | P / R or cost | ATE (m) | MiB"
    " | online s | rej | true rej | false kept | P / R or cost | ATE (m) | MiB | same rej | online / batch |"
)


def cells(outcome: dict, clean: bool, timeout_s: float) -> list[str]:
    """The seven cells of one method's outcome."""
    if outcome["status"] == "timeout":
        return [f"> {timeout_s:g}"] + ["-"] * 6
    if outcome["status"] != "ok":
        return [outcome["status"]] + ["-"] * 6
    value = outcome["value"]
    if "not_replayable" in value:
        return [f"not replayable: {value['not_replayable']}"] + ["-"] * 6
    quality = f"cost {value['cost_ratio']:.4f}" if clean else f"{value['P']:.4f} / {value['R']:.4f}"
    return [
        f"{value['s']:.2f}",
        str(value["rej"]),
        str(value["true_rej"]),
        str(value["false_kept"]),
        quality,
        f"{value['ate']:.3g}",
        f"{value['mib']:.0f}",
    ]


def comparison(batch: dict, online: dict, timeout_s: float) -> list[str]:
    """`same rej` and `online / batch` of one row."""
    if batch["status"] != "ok":
        return ["-", "-"]
    batch_s = batch["value"]["s"]
    if online["status"] == "timeout":
        return ["-", f"> {timeout_s / batch_s:.0f}x"]
    if online["status"] != "ok" or "not_replayable" in online["value"]:
        return ["-", "-"]
    same = online["value"]["rejected_edges"] == batch["value"]["rejected_edges"]
    return ["yes" if same else "**no**", f"{online['value']['s'] / batch_s:.1f}x"]


def environment() -> str:
    """Versions, cores, commit and time, for the record."""
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for package in ("egnc", "numpy", "scipy", "scikit-sparse"):
        try:
            found.append(f"{package} {version(package)}")
        except PackageNotFoundError:
            found.append(f"{package} absent")
    commit = subprocess.run(
        ["git", "-C", str(Path(__file__).parent), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    return (
        f"{', '.join(found)}, Python {platform.python_version()}, {os.cpu_count()} CPUs,"
        f" commit {commit or 'unknown'}, {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}"
    )


def main(argv: list[str] | None = None) -> int:
    """Solve every file both ways, one child process per run, and print the markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATASETS, help="a folder of .g2o/.irl files, or one file")
    parser.add_argument("--files", default="", help="comma-separated file stems (default: every file, smallest first)")
    parser.add_argument("--percent", default="30", help="false-loop percentages, comma-separated ('': clean only)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per run (and per reference solve)")
    parser.add_argument("--information", default="nearest-pd", help="read_g2o's repair of non-PD information")
    parser.add_argument("--linear-solver", default="auto")
    parser.add_argument("--json", type=Path, help="append one JSON line per row here")
    args = parser.parse_args(argv)

    print(environment(), file=sys.stderr)
    print(HEADER)
    print("|---|---|" + "---:|" * (HEADER.count("|") - 3))
    for path in files(args.data, args.files):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # repaired information and the like: the rows say what matters
            built = list(variants(path, args))
        for variant in built:
            if isinstance(variant, str):
                print(f"| {path.stem} | {variant} |" + " |" * (HEADER.count("|") - 3), flush=True)
                continue
            outcomes = {}
            for method in METHODS:
                print(f"{path.stem} {variant.name} {method} ...", file=sys.stderr, flush=True)
                outcomes[method] = run(solve_and_score, (variant, method, args.linear_solver), args.timeout)
            clean = variant.name == "clean"
            row = [path.stem, variant.name]
            for method in METHODS:
                row += cells(outcomes[method], clean, args.timeout)
            row += comparison(outcomes["batch"], outcomes["online"], args.timeout)
            print("| " + " | ".join(row) + " |", flush=True)
            if args.json is not None:
                with open(args.json, "a", encoding="utf-8") as out:
                    record = {"file": path.stem, "variant": variant.name, **outcomes}
                    out.write(json.dumps(record) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
