"""The online solver on replayed logs: accuracy, total cost, and latency per update, egnc vs risam.

    python benchmarks/online.py [replay] [--datasets csail,intel] [--percents 10,30,50] [--seed 0]
        [--methods egnc,risam] [--irl manhattan_noisy] [--stage-iterations N]
        [--regraduate reference|new] [--region-hops N] [--boundary-share S] [--strong-at-arrival] [--decide-at-arrival]
        [--rel-cost-tol TOL] [--linear-solver auto] [--repeats N]
        [--json results.jsonl]

For every dataset and percentage, the clean graph's least-squares optimum is the reference; the
graph is corrupted with riSAM-protocol false loops (`egnc.datasets.add_false_loops`, seeded) and
replayed pose by pose through `egnc.online.replay` with each method in turn, in this process, one run at
a time. An IRL log (`--irl`, default manhattan_noisy) is replayed as it is and scored against its
own labels; its reference is the least-squares optimum without the labelled outliers.

Columns:
- `P`, `R`: precision and recall of the final decision (`OnlineSolver.result()`), outliers the
  positive class; `P now`, `R now`: the same for the solver's running decision before it
  (`OnlineSolver.inliers`, the chi-square test at the robust estimate).
- `ATE`: of the final result against the reference, metres, after rigid alignment; `ATE now`:
  of the online estimate before it (`OnlineSolver.poses`).
- `updates`: updates (one per new pose); `loop updates`: those that added a loop closure;
  `decided`: those decided at arrival (`UpdateReport.decided_at_arrival`: nothing solved);
  `restarted`: those whose last stage started from the map before the update
  (`UpdateReport.restarted`).
- `iterations`: accepted solver steps summed over all updates (the final decision excluded).
- `total s`: sum of the update times (reading, reference, final decision excluded);
  `decide s`: the final decision (`result()`: from the online estimate and from the batch solve);
  `kept`: the start whose decision `result()` kept (`online`, or the batch solve's `guess` /
  `chordal`).
- `p50`, `p99`, `max`: update latency in milliseconds over all updates; `loop p50`: over the
  updates that added a loop closure.
- `ratio`: egnc's total time and iterations over risam's on the same replay.

With `--repeats N` every case replays each method N times, the methods' order reversed on every
other repeat (egnc, risam, then risam, egnc, ...), so that a drift of the machine's speed weighs on
both alike. The time columns (`total s`, `decide s`, the latencies) are then medians over the
repeats, and `ratio` gives the median of the repeats' own time ratios with their range. The
replays are deterministic: every other column must agree between repeats, or the bench stops.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from .paths import SHARED_DATASETS


def run(graph, is_outlier, known, reference, method: str, args: argparse.Namespace) -> dict:
    """Replay one graph with one method; the row's figures."""
    from egnc.metrics import ate, precision_recall
    from egnc.online import OnlineOptions
    from egnc.online.replay import latency_summary, replay, replay_steps

    options = OnlineOptions(
        regraduate=args.regraduate,
        stage_iterations=args.stage_iterations or None,
        # Rules of the egnc schedule: the risam rows run without them.
        strong_at_arrival=args.strong_at_arrival and method == "egnc",
        decide_at_arrival=args.decide_at_arrival and method == "egnc",
        **({} if args.region_hops is None else {"region_hops": args.region_hops or None}),
        **({} if args.boundary_share is None else {"boundary_share": args.boundary_share}),
        **({} if args.rel_cost_tol is None else {"rel_cost_tol": args.rel_cost_tol}),
    )
    decided, restarted = [], []

    def on_step(step: int, total: int, report) -> None:
        decided.append(report.decided_at_arrival)
        restarted.append(report.restarted)

    outcome = replay(
        graph,
        method,
        known_inliers=known,
        linear_solver=args.linear_solver,
        online_options=options,
        on_step=on_step,
    )
    steps = replay_steps(graph, known)
    # The running decision, in file order (the result already is): edge k of the solver is inserted[k].
    inserted = np.concatenate(steps)
    now_rejected = np.zeros(graph.num_edges, dtype=bool)
    now_rejected[inserted] = ~outcome.solver.inliers
    now_poses = np.empty_like(graph.poses)
    now_poses[np.searchsorted(graph.vertex_ids, outcome.solver.vertex_ids)] = outcome.solver.poses
    started = time.perf_counter()
    outcome.solver.result()  # replay() made it already; this times the final decision alone
    decide_s = time.perf_counter() - started
    precision, recall = precision_recall(~outcome.result.inliers, is_outlier)
    now_precision, now_recall = precision_recall(now_rejected, is_outlier)
    ms, iterations = outcome.update_ms, outcome.update_iterations
    has_loop = np.array([bool((~known[step]).any()) for step in steps])
    latency = latency_summary(ms)
    return {
        "method": method,
        "P": precision,
        "R": recall,
        "P_now": now_precision,
        "R_now": now_recall,
        "ate": ate(outcome.result.graph.poses, reference, graph.dim),
        "ate_now": ate(now_poses, reference, graph.dim),
        "updates": int(outcome.steps),
        "loop_updates": int(has_loop.sum()),
        "decided": int(np.sum(decided)),
        "restarted": int(np.sum(restarted)),
        "iterations": int(iterations.sum()),
        "total_s": float(outcome.total_s),
        "decide_s": decide_s,
        "kept": outcome.result.start,
        **latency,
        "loop_p50": float(np.percentile(ms[has_loop], 50)) if has_loop.any() else 0.0,
    }


def cases(args: argparse.Namespace):
    """`(name, percent, graph, is_outlier, known, reference)` of every case, lazily."""
    from egnc.api import solve
    from egnc.datasets import add_false_loops
    from egnc.io import read_g2o, read_irl

    for name in filter(None, args.datasets.split(",")):
        graph = read_g2o(SHARED_DATASETS / f"{name}.g2o")
        reference = solve(graph, "l2", linear_solver=args.linear_solver).graph.poses
        for percent in (float(p) for p in args.percents.split(",")):
            corrupted = add_false_loops(graph, percent, seed=args.seed, reference_poses=reference)
            g = corrupted.graph
            yield name, percent, g, corrupted.is_outlier, g.is_odometry, reference
    for name in filter(None, args.irl.split(",")):
        log = read_irl(SHARED_DATASETS / f"{name}.irl")
        clean = log.graph.subgraph_edges(~log.is_outlier)
        reference = solve(clean, "l2", linear_solver=args.linear_solver).graph.poses
        percent = 100.0 * log.is_outlier.sum() / max(1, (~log.is_odometry).sum())
        yield name, percent, log.graph, log.is_outlier, log.is_odometry, reference


TIMES = ("total_s", "decide_s", "p50", "p99", "max", "loop_p50")
"""Row fields that are timings: a median over repeats. Every other field must repeat exactly."""


def combined(rows: list[dict]) -> dict:
    """One row from the repeats `rows` of a method on a case: the timings' medians (`TIMES`).

    Raises:
        SystemExit: a field other than a timing differs between repeats.
    """
    from egnc.bench.report import merged_repeats

    return merged_repeats(rows, TIMES, rows[0]["method"])


HEADER = (
    "| dataset | % | method | P | R | P now | R now | ATE (m) | ATE now (m) | updates | loop updates | decided"
    " | restarted | iterations"
    " | total s | decide s | kept | p50 ms | p99 ms | max ms | loop p50 ms | ratio time / iterations |"
)


def report(args: argparse.Namespace) -> int:
    """Replay every case with every method, print a markdown row per case and method (`args`: `online.py replay`)."""
    import egnc

    print(
        f"egnc {egnc.__version__}, Python {platform.python_version()}, numpy {np.__version__},"
        f" {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}",
        file=sys.stderr,
    )
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    methods = args.methods.split(",")
    for name, percent, graph, is_outlier, known, reference in cases(args):
        repeats: dict[str, list[dict]] = {method: [] for method in methods}
        for repeat in range(args.repeats):
            for method in methods if repeat % 2 == 0 else methods[::-1]:
                repeats[method].append(run(graph, is_outlier, known, reference, method, args))
        rows = [combined(repeats[method]) for method in methods]
        for row in rows:
            ratio = ""
            if row["method"] == "egnc" and "risam" in repeats:
                times = [e["total_s"] / r["total_s"] for e, r in zip(repeats["egnc"], repeats["risam"])]
                spread = f" ({min(times):.2f}-{max(times):.2f})" if len(times) > 1 else ""
                iterations = row["iterations"] / repeats["risam"][0]["iterations"]
                ratio = f"{np.median(times):.2f}x{spread} / {iterations:.2f}x"
                row = {**row, "time_ratios": times}
            print(
                f"| {name} | {percent:.0f} | {row['method']} | {row['P']:.4f} | {row['R']:.4f} | {row['P_now']:.4f}"
                f" | {row['R_now']:.4f} | {row['ate']:.4f} | {row['ate_now']:.4f} | {row['updates']}"
                f" | {row['loop_updates']} | {row['decided']} | {row['restarted']}"
                f" | {row['iterations']} | {row['total_s']:.1f} | {row['decide_s']:.2f} | {row['kept']}"
                f" | {row['p50']:.1f} | {row['p99']:.1f} | {row['max']:.1f} | {row['loop_p50']:.1f} | {ratio} |",
                flush=True,
            )
            if args.json is not None:
                with open(args.json, "a", encoding="utf-8") as out:
                    out.write(json.dumps({"dataset": name, "percent": percent, "repeats": args.repeats, **row}) + "\n")
    return 0
