"""Table 1 of the paper: false loop closures replayed online (egnc, risam), with batch columns beside.

The cases are `benchmarks/online.py replay`'s (`online_replay.cases`: riSAM's generator rule,
`add_false_loops` against the clean least-squares optimum, seed 0), so the online rows are that
bench's and the batch columns solve the very same corrupted graphs:

- `egnc` batch: `egnc.solve` (through `egnc.bench.run_case`, a child process with a time limit);
- `gtsam-gnc-tls`: GTSAM's `GncLMOptimizer` with truncated least squares, its defaults
  (`egnc.bench`'s method of that name);

g2o's DCS is not a column: the `g2opy` wheel's `RobustKernelDCS` (phi = 1) takes clean CSAIL from
g2o's least-squares chi2 of 39 to 1.3e6 under Levenberg-Marquardt (Gauss-Newton makes no step),
where `RobustKernelCauchy` in the same harness ends at 41.5: the wheel's DCS kernel is unusable.

One JSON line per (dataset, percent, mode, method); lines already in the file are not run again.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .online_replay import cases, run

ONLINE_METHODS = ("egnc", "risam")
BATCH_METHODS = ("egnc", "gtsam-gnc-tls")


def replay_args(datasets: str, percents: str, seed: int = 0) -> argparse.Namespace:
    """`online.py replay`'s arguments with its defaults, for `online_replay.cases` and `online_replay.run`."""
    return argparse.Namespace(
        datasets=datasets,
        percents=percents,
        seed=seed,
        irl="",
        linear_solver="auto",
        regraduate="reference",
        stage_iterations=1,
        strong_at_arrival=False,
        decide_at_arrival=False,
        region_hops=None,
        boundary_share=None,
        rel_cost_tol=None,
    )


def batch_row(name, percent, graph, is_outlier, known, reference, method: str, time_limit_s: float) -> dict:
    """One batch method on one case, in a child process killed after `time_limit_s`."""
    from egnc.bench import BenchCase, parse_method, run_case

    case = BenchCase(name, percent, 0, graph, is_outlier, known, reference)
    record = run_case(case, parse_method(method), time_limit_s=time_limit_s)
    if not record.ok:
        return {"status": record.status}
    return {"status": "ok", "P": record.precision, "R": record.recall, "ate": record.ate,
            "iterations": record.iterations, "total_s": record.time_s}  # fmt: skip


def run_all(
    out: Path,
    *,
    datasets: str,
    percents: str,
    modes: tuple[str, ...] = ("online", "batch"),
    batch_methods: tuple[str, ...] = BATCH_METHODS,
    time_limit_s: float = 300.0,
) -> Path:
    """Every case of `datasets` x `percents` online and in batch; one JSON line per run appended to `out`."""
    out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if out.exists():
        rows = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
        done = {(row["dataset"], row["percent"], row["mode"], row["method"]) for row in rows}
    args = replay_args(datasets, percents)
    for name, percent, graph, is_outlier, known, reference in cases(args):
        wanted = [("online", m) for m in ONLINE_METHODS if "online" in modes]
        wanted += [("batch", m) for m in batch_methods if "batch" in modes]
        for mode, method in wanted:
            if (name, percent, mode, method) in done:
                continue
            if mode == "online":
                row = run(graph, is_outlier, known, reference, method, args)
                row = {key: row[key] for key in ("P", "R", "ate", "iterations", "total_s")} | {"status": "ok"}
            else:
                row = batch_row(name, percent, graph, is_outlier, known, reference, method, time_limit_s)
            row = {"dataset": name, "percent": percent, "mode": mode, "method": method, **row}
            with open(out, "a", encoding="utf-8") as stream:
                stream.write(json.dumps(row) + "\n")
            figures = f"P {row['P']:.4f} R {row['R']:.4f}, {row['total_s']:.1f} s" if row["status"] == "ok" else ""
            print(f"{name} {percent:g}% {mode} {method}: {row['status']} {figures}", file=sys.stderr, flush=True)
    return out
