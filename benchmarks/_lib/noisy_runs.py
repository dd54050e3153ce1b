"""Table 2 of the paper: noisy-Manhattan datasets solved in batch and replayed online, one JSON line per run.

Every run records, beside precision and recall (outliers the positive class), what a failure
needs explained: the outliers kept (`missed`) and the true loops rejected (`rejected_true`),
each with its squared whitened error at the ground truth, at the outlier-free optimum and at the
run's final map, and the truncated cost (`egnc.robust.costs.truncated_cost`, the criterion egnc's
default decision is judged by) of the final map and of the outlier-free optimum.

A regime is an `outlier_min_r2` of `make_noisy_manhattan`: `None` keeps outliers above the
paper's rule `r^2 > chi2.ppf(0.95, 3)`, `90` only gross ones (the shipped case's regime).
Lines already in the output file are not run again, so an interrupted run resumes.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

BATCH_METHODS = ("egnc", "risam", "gnc-tls")
ONLINE_METHODS = ("egnc", "risam")
DECISION_QUANTILE = 0.99
"""`GncOptions.outlier_quantile`'s default: the quantile of the truncated cost egnc judges decisions by."""


def regime_name(bound: float | None) -> str:
    """`None` -> `"chi2"` (the paper's rule), `90.0` -> `"r2>90"`."""
    return "chi2" if bound is None else f"r2>{bound:g}"


def squared_errors(graph, poses: np.ndarray) -> np.ndarray:
    """`(E,)` squared whitened errors `r^2` of `graph`'s edges at `poses` `(N, P)`."""
    from egnc.nonlinear.factors import BetweenFactors, to_matrices

    factors = BetweenFactors.from_graph(graph)
    return factors.whitened_norms(factors.residuals(to_matrices(graph.dim, poses))) ** 2


def score(noisy, rejected: np.ndarray, poses: np.ndarray) -> dict:
    """Precision, recall and the edges behind a failure, of a decision `rejected` `(E,)` with its map `poses`."""
    from egnc.metrics import ate, precision_recall, rpe
    from egnc.robust.costs import truncated_cost

    graph, outlier = noisy.graph, noisy.is_outlier
    loops = ~graph.is_odometry
    precision, recall = precision_recall(rejected, outlier)
    r2 = {
        "truth": squared_errors(graph, noisy.ground_truth),
        "ref": squared_errors(graph, noisy.reference),
        "final": squared_errors(graph, poses),
    }
    missed = np.flatnonzero(outlier & ~rejected)
    rejected_true = np.flatnonzero(loops & ~outlier & rejected)

    def edges(index: np.ndarray) -> dict:
        return {"index": index.tolist(), **{f"r2_{k}": np.round(v[index], 3).tolist() for k, v in r2.items()}}

    return {
        "P": precision,
        "R": recall,
        "ok": bool(precision == 1.0 and recall == 1.0),
        "missed": edges(missed),
        "rejected_true": edges(rejected_true),
        "tc": truncated_cost(np.sqrt(r2["final"]), loops, graph.dim, DECISION_QUANTILE),
        "tc_ref": truncated_cost(np.sqrt(r2["ref"]), loops, graph.dim, DECISION_QUANTILE),
        "ate": ate(poses, noisy.reference, graph.dim),
        "rpe_percent": rpe(poses, noisy.reference, graph.dim).percent,
        "ate_truth": ate(poses, noisy.ground_truth, graph.dim),
        "rpe_truth_percent": rpe(poses, noisy.ground_truth, graph.dim).percent,
    }


def batch_run(noisy, method: str) -> dict:
    """One batch solve (`egnc.solve`, this process) of a dataset, scored."""
    from egnc import solve

    started = time.perf_counter()
    result = solve(noisy.graph, method, known_inliers=noisy.graph.is_odometry)
    seconds = time.perf_counter() - started
    extra = {"iterations": int(result.iterations), "time_s": seconds, "start": getattr(result, "start", "")}
    return {**score(noisy, ~result.inliers, result.graph.poses), **extra}


def online_run(noisy, method: str) -> dict:
    """One pose-by-pose replay (`egnc.online.replay`, default options) of a dataset, scored.

    Besides the final decision (`result()`: a batch decision from the online estimate), the
    running one (`OnlineSolver.inliers`: the chi-square test at the robust estimate, which the
    schedule alone shapes): `P_now`, `R_now`, `missed_now` (outliers it keeps).
    """
    from egnc.metrics import precision_recall
    from egnc.online.replay import replay, replay_steps

    graph = noisy.graph
    outcome = replay(graph, method, known_inliers=graph.is_odometry)
    rejected_now = np.zeros(graph.num_edges, dtype=bool)
    rejected_now[np.concatenate(replay_steps(graph, graph.is_odometry))] = ~outcome.solver.inliers
    precision_now, recall_now = precision_recall(rejected_now, noisy.is_outlier)
    extra = {
        "iterations": int(outcome.update_iterations.sum()),
        "time_s": float(outcome.total_s),
        "start": outcome.result.start,
        "P_now": precision_now,
        "R_now": recall_now,
        "missed_now": np.flatnonzero(noisy.is_outlier & ~rejected_now).tolist(),
    }
    return {**score(noisy, ~outcome.result.inliers, outcome.result.graph.poses), **extra}


def datasets(data_dir: Path, count: int, bounds: list[float | None], first_seed: int = 1) -> Iterator:
    """`(regime, seed, NoisyGraph)` for seeds `first_seed..first_seed+count-1` of every regime, lazily."""
    return selected(data_dir, [(bound, seed) for bound in bounds for seed in range(first_seed, first_seed + count)])


def selected(data_dir: Path, wanted: list[tuple[float | None, int]]) -> Iterator:
    """`(regime, seed, NoisyGraph)` of the `(outlier_min_r2, seed)` pairs `wanted`, lazily."""
    from egnc import solve
    from egnc.datasets import make_noisy_manhattan
    from egnc.io import read_g2o

    source = read_g2o(Path(data_dir) / "manhattanOlson3500.g2o")
    truth = solve(source, "l2", linear_solver="scipy").graph.poses
    for bound, seed in wanted:
        yield regime_name(bound), seed, make_noisy_manhattan(source, truth, seed=seed, outlier_min_r2=bound)


def done_runs(path: Path) -> set[tuple]:
    """`(regime, seed, mode, method)` of the lines already in `path`."""
    if not path.exists():
        return set()
    lines = (json.loads(line) for line in path.read_text().splitlines() if line.strip())
    return {(row["regime"], row["seed"], row["mode"], row["method"]) for row in lines}


def run_all(
    data_dir: Path,
    out: Path,
    *,
    count: int,
    bounds: list[float | None],
    modes: tuple[str, ...] = ("batch", "online"),
    batch_methods: tuple[str, ...] = BATCH_METHODS,
    first_seed: int = 1,
) -> Path:
    """Run every mode's methods on every dataset, appending one JSON line per run to `out`; returns `out`."""
    return run_cases(out, datasets(data_dir, count, bounds, first_seed), modes, batch_methods)


def run_cases(
    out: Path, cases: Iterator, modes: tuple[str, ...], batch_methods: tuple[str, ...] = BATCH_METHODS
) -> Path:
    """Run every mode's methods on `(regime, seed, NoisyGraph)` `cases`, one JSON line per run appended to `out`."""
    out.parent.mkdir(parents=True, exist_ok=True)
    done = done_runs(out)
    wanted = [(mode, method) for mode in modes for method in (batch_methods if mode == "batch" else ONLINE_METHODS)]
    runner = {"batch": batch_run, "online": online_run}
    for regime, seed, noisy in cases:
        for mode, method in wanted:
            if (regime, seed, mode, method) in done:
                continue
            row = {"regime": regime, "seed": seed, "mode": mode, "method": method, **runner[mode](noisy, method)}
            with open(out, "a", encoding="utf-8") as stream:
                stream.write(json.dumps(row) + "\n")
            status = "ok" if row["ok"] else f"missed {len(row['missed']['index'])}"
            print(
                f"{regime} seed {seed} {mode} {method}: P {row['P']:.4f} R {row['R']:.4f} {status}, "
                f"{row['time_s']:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    return out


def read_rows(path: Path) -> list[dict]:
    """The JSON lines of a `run_all` output file."""
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def bound_of(regime: str) -> float | None:
    """The inverse of `regime_name`: `"chi2"` -> `None`, `"r2>90"` -> `90.0`."""
    return None if regime == "chi2" else float(regime.removeprefix("r2>"))


def risam_failures(rows: list[dict], regimes: tuple[str, ...] = ("r2>90",)) -> list[tuple[float | None, int]]:
    """`(outlier_min_r2, seed)` of the `regimes` datasets where risam failed, online or in batch (Table 3)."""
    failed = {(row["regime"], row["seed"]) for row in rows if row["method"] == "risam" and not row["ok"]}
    return [(bound_of(regime), seed) for regime, seed in sorted(failed) if regime in regimes]
