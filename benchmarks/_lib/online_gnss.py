"""GNSS fixes with multipath outliers and false loops, replayed online: P and R apart, ATE, latency.

    python benchmarks/online.py gnss [--files manhattanOlson3500,sphere2500,city10000] [--loops 0,10,30]
        [--priors 0,10,20] [--every 10] [--sigma 2] [--seed 1] [--baseline] [--json rows.jsonl]

The cases are `benchmarks/robust.py gnss`'s (`_lib/robust_gnss.cases`: a position prior every
`--every` poses around the clean file's least-squares optimum, false loops, multipath jumps of
10-50 m single and in bursts of 5-20 fixes). Each is replayed pose by pose by `egnc.online.replay`
with the defaults (egnc schedule; loops and priors both candidates, each fix added when its pose
arrives), then solved in one batch by `egnc.solve` for comparison, in this process, one at a time.

Columns: precision and recall (outliers positive) of the final decision (`result()`) for the
loops and for the priors apart; ATE without alignment against the least-squares optimum of the
outlier-free factors (the fixes set the frame); updates, their summed time and the median and
99th percentile of the update latency; the batch solve's time. With `--baseline`, the same graph
without its fixes is replayed right after (same false loops, the first pose held as in any
replay without priors), and `vs no fixes` gives the update total over that replay's.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from .robust_gnss import cases, scores


def row(case, json_path, baseline: bool = False) -> str:  # noqa: ANN001 (robust_gnss.Case)
    """The table row of one case (module docstring), also appended to `json_path` as JSON if given;
    with `baseline`, the update total over that of a replay of the same graph without its fixes."""
    from dataclasses import replace

    import egnc
    from egnc.graph.priors import Priors
    from egnc.metrics import ate
    from egnc.online.replay import latency_summary, replay

    graph = case.graph
    outcome = replay(graph)
    result = outcome.result
    rejected_priors = np.isin(graph.prior_factor_index, result.rejected_priors)
    loops, priors = scores(~result.inliers, rejected_priors, case)
    error = ate(result.graph.poses, case.reference, graph.dim, align=False)
    latency = latency_summary(outcome.update_ms)
    started = time.perf_counter()
    egnc.solve(graph)
    batch_s = time.perf_counter() - started
    without = replay(replace(graph, priors=Priors.empty(graph.dim))) if baseline else None
    bursts = " bursts" if case.bursts else ""
    figures = {
        "file": case.name,
        "loops": case.loops,
        "priors": f"{case.priors:g}{bursts}",
        "loops_PR": loops,
        "priors_PR": priors,
        "ate_m": error,
        "updates": int(outcome.steps),
        "total_s": outcome.total_s,
        "p50_ms": latency["p50"],
        "p99_ms": latency["p99"],
        "batch_s": batch_s,
        "vs_no_fixes": None if without is None else outcome.total_s / without.total_s,
    }
    if json_path is not None:
        with open(json_path, "a") as stream:
            stream.write(json.dumps(figures) + "\n")
    cells = [case.name, f"{case.loops:g}", figures["priors"], loops, priors, f"{error:.3f}", str(outcome.steps)]
    cells += [f"{outcome.total_s:.1f}", f"{latency['p50']:.1f}", f"{latency['p99']:.1f}", f"{batch_s:.2f}"]
    if without is not None:
        no_fixes = latency_summary(without.update_ms)
        cells += [f"{figures['vs_no_fixes']:.2f}x (p50 {no_fixes['p50']:.1f}, p99 {no_fixes['p99']:.1f})"]
    return "| " + " | ".join(cells) + " |"


def report(args: argparse.Namespace) -> int:
    """Print the table of every file's grid (module docstring)."""
    loops = [float(v) for v in args.loops.split(",")]
    priors = [float(v) for v in args.priors.split(",")]
    head = "| file | false loops % | prior outliers % | loops P/R | priors P/R | ATE m | updates | total s"
    head += " | p50 ms | p99 ms | batch s |" + (" vs no fixes |" if args.baseline else "")
    print(head)
    print("|---|---:|---|---|---|---:|---:|---:|---:|---:|---:|" + ("---|" if args.baseline else ""), flush=True)
    for name in args.files.split(","):
        for case in cases(name, loops, priors, args.every, args.sigma, args.seed):
            print(row(case, args.json, args.baseline), flush=True)
    return 0
