"""Least-squares benchmark (issue 2): `egnc-solve --method l2` against GTSAM's LM and g2o's GN on the same files.

For each file, in one run and interleaved repeat by repeat (so that load from other processes
hits all alike): egnc with CHOLMOD, egnc with SciPy's SuperLU, GTSAM 4.3's
`LevenbergMarquardtOptimizer` and, when the `g2opy` wheel is installed, g2o's Gauss-Newton with
Eigen's sparse Cholesky (`g2o_solve`). Reported times are medians over the repeats.

- "solve": egnc's `solve(graph, "l2")` on an already-read graph (problem set-up, symbolic
  analysis and the GN/LM loop) vs GTSAM's `optimize()` alone (the graph already read).
- "CLI": the whole command, reading included: `egnc.cli.solve.main([file, "--method", "l2", ...])`
  in-process vs `gtsam.readG2o` + the reference prior + `optimize()`. Interpreter start-up and
  imports are excluded for both.
- Per iteration: the solver's phase clocks (`SolverResult.timings`) divided by the accepted
  iterations, next to the "floor": one bare CHOLMOD `cholesky_inplace` of the same normal
  equations matrix with the solver's own symbolic analysis.

- g2o: `initialize_optimization()` plus `optimize()` on a file g2o has read (reading excluded),
  against egnc-cholmod's solve; its optimum is checked by egnc's cost at g2o's poses, which
  equals egnc's optimal cost when both reach the same point (`SAME_OPTIMUM_RTOL`).

GTSAM runs the reference protocol of `gtsam_lm` (prior sigma 1e-3 on the first pose)
with `lm_params(1e-10, 1e-10, 1000)`; egnc fixes the first pose and uses its defaults
(`SolverOptions()`: LM, stop when `(F_prev - F) / F_prev <= 1e-10`, `max |g| <= 1e-10` or
`||delta|| <= 1e-12`).

Run: `python benchmarks/least_squares.py [compare] [--files NAME ...] [--repeat N]`.
"""

from __future__ import annotations

import datetime
import functools
import os
import platform
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

import gtsam
import numpy as np
import scipy.sparse as sp

from egnc import solve
from egnc.bench import add_gtsam_reference_prior
from egnc.cli import solve as cli
from egnc.graph import PoseGraph
from egnc.io import read_g2o
from egnc.linalg.linear_solvers import CholmodSolver, serial_native_threads
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares

from .g2o_solve import g2o_available, solve_g2o
from .gtsam_lm import g2o_is_3d, lm_params
from .paths import dataset_path

DEFAULT_FILES = ("manhattanOlson3500", "city10000", "sphere2500")
GTSAM_TOL = 1e-10
BACKENDS = ("cholmod", "scipy")
PHASES = ("linearize", "assemble", "factorize", "update")
SAME_OPTIMUM_RTOL = 1e-6
"""g2o reaches egnc's optimum when egnc's cost at g2o's poses is within this of egnc's optimal cost."""


@dataclass(frozen=True)
class FileResult:
    """Medians over the repeats for one file."""

    name: str
    egnc_iterations: int
    gtsam_iterations: int
    egnc_cost: float  # 0.5 sum r^2, first pose fixed
    gtsam_cost: float  # graph.error(), reference prior included (zero at the fixed first pose)
    solve_s: dict[str, float]  # "cholmod", "scipy", "gtsam" and, with g2opy, "g2o"
    cli_s: dict[str, float]
    g2o_iterations: int | None = None  # None: g2opy is not installed
    g2o_cost: float | None = None  # egnc's 0.5 sum r^2 at g2o's poses


@dataclass(frozen=True)
class IterationProfile:
    """Per-iteration phase times of one backend on one file, milliseconds."""

    name: str
    backend: str
    iterations: int
    linear_solves: int
    phase_ms: dict[str, float]  # phase total / accepted iterations
    floor_ms: float  # one bare CHOLMOD cholesky_inplace of the same matrix

    @property
    def python_ms(self) -> float:
        """Linearize + assemble + update per iteration: the work done in NumPy, not in the factorization."""
        return self.phase_ms["linearize"] + self.phase_ms["assemble"] + self.phase_ms["update"]


def _timed(fn) -> tuple[float, object]:
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def gtsam_problem(path: Path) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """`readG2o` plus the reference prior on the lowest id (as `gtsam_lm.load_g2o`, minus its bookkeeping)."""
    is_3d = g2o_is_3d(path)
    graph, initial = gtsam.readG2o(str(path), is_3d)
    add_gtsam_reference_prior(graph, initial, min(initial.keys()), is_3d)
    return graph, initial


def gtsam_cli(path: Path) -> tuple[float, int]:
    """GTSAM read + optimize, as one command would; returns `(final error, iterations)`."""
    graph, initial = gtsam_problem(path)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, lm_params(GTSAM_TOL, GTSAM_TOL, 1000))
    result = optimizer.optimize()
    return graph.error(result), optimizer.iterations()


def egnc_cli(path: Path, backend: str) -> None:
    """`egnc-solve FILE --method l2 --linear-solver BACKEND -q`, in-process."""
    code = cli.main([str(path), "--method", "l2", "--linear-solver", backend, "-q"])
    if code != 0:
        raise RuntimeError(f"egnc-solve failed on {path} with exit code {code}")


def egnc_cost(graph: PoseGraph, matrices: np.ndarray) -> float:
    """egnc's least-squares cost `0.5 sum r^2` over every edge of `graph` at poses `(N, d+1, d+1)`."""
    factors = BetweenFactors.from_graph(graph)
    return float(0.5 * np.sum(factors.whitened_norms(factors.residuals(matrices)) ** 2))


def compare_file(name: str, repeat: int = 3) -> FileResult:
    """Time egnc (CHOLMOD, SciPy), GTSAM and g2o (when installed) on one file, interleaved, `repeat` times each."""
    path = dataset_path(name)
    graph = read_g2o(path)
    g_graph, g_initial = gtsam_problem(path)
    params = lm_params(GTSAM_TOL, GTSAM_TOL, 1000)
    with_g2o = g2o_available()
    solvers = (*BACKENDS, "gtsam", *(["g2o"] if with_g2o else []))
    solve_times: dict[str, list[float]] = {key: [] for key in solvers}
    cli_times: dict[str, list[float]] = {key: [] for key in (*BACKENDS, "gtsam")}
    costs: dict[str, float] = {}
    gauge = int(graph.vertex_ids[np.flatnonzero(graph.fixed)[0] if graph.fixed.any() else 0])
    g2o_iterations = None
    for _ in range(max(1, repeat)):
        optimizer = gtsam.LevenbergMarquardtOptimizer(g_graph, g_initial, params)
        seconds, values = _timed(optimizer.optimize)
        solve_times["gtsam"].append(seconds)
        gtsam_iterations = optimizer.iterations()
        costs["gtsam"] = g_graph.error(values)
        for backend in BACKENDS:
            result = solve(graph, "l2", linear_solver=backend)
            solve_times[backend].append(result.time_s)
            costs[backend] = result.cost
            egnc_iterations = result.iterations
        if with_g2o:
            run = solve_g2o(path, graph.dim, graph.vertex_ids, gauge)
            solve_times["g2o"].append(run.time_s)
            costs["g2o"] = egnc_cost(graph, run.poses)
            g2o_iterations = run.iterations
        cli_times["gtsam"].append(_timed(lambda: gtsam_cli(path))[0])
        for backend in BACKENDS:
            cli_times[backend].append(_timed(functools.partial(egnc_cli, path, backend))[0])
    return FileResult(
        name=path.stem,
        egnc_iterations=egnc_iterations,
        gtsam_iterations=gtsam_iterations,
        egnc_cost=costs["cholmod"],
        gtsam_cost=costs["gtsam"],
        solve_s={key: statistics.median(v) for key, v in solve_times.items()},
        cli_s={key: statistics.median(v) for key, v in cli_times.items()},
        g2o_iterations=g2o_iterations,
        g2o_cost=costs.get("g2o"),
    )


def bare_factorization_ms(graph, poses: np.ndarray, repeat: int) -> float:
    """Median ms of one CHOLMOD `cholesky_inplace` of `H + 1e-8 diag(H)` at `poses`.

    With the solver's analysis and threads.
    """
    problem = Problem.from_graph(graph, "cholmod")
    pattern = problem.pattern
    linearization = problem.factors.linearize(poses)
    data, _ = pattern.assemble(linearization, problem.factors.information, np.ones(graph.num_edges))
    data[pattern.diagonal_slots] *= 1.0 + 1e-8
    # The analysis the solver makes at its first factorization (`make_linear_solver` on the ordered pattern).
    solver = CholmodSolver(pattern.indptr, pattern.indices, ordered=True)
    matrix = sp.csc_matrix(
        (data, pattern.indices.astype(np.int32), pattern.indptr.astype(np.int32)), shape=(pattern.size, pattern.size)
    )
    times = []
    with serial_native_threads():  # as the solver calls it
        for _ in range(max(3, repeat)):
            start = time.perf_counter()
            solver.factor.cholesky_inplace(matrix)
            times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def profile_iterations(name: str, repeat: int = 3) -> list[IterationProfile]:
    """Per-iteration phase times of the LM loop for each backend, and the bare factorization floor."""
    graph = read_g2o(dataset_path(name))
    initial = to_matrices(graph.dim, graph.poses)
    profiles = []
    final = initial
    runs: dict[str, list] = {backend: [] for backend in BACKENDS}
    problems = {backend: Problem.from_graph(graph, backend) for backend in BACKENDS}
    for _ in range(max(1, repeat)):
        for backend in BACKENDS:
            runs[backend].append(solve_least_squares(problems[backend], initial, None, SolverOptions()))
    final = runs["cholmod"][-1].poses
    floor = bare_factorization_ms(graph, final, 2 * repeat + 1)
    for backend in BACKENDS:
        last = runs[backend][-1]
        per_iteration = {
            phase: 1e3 * statistics.median(run.timings[phase] for run in runs[backend]) / max(last.iterations, 1)
            for phase in PHASES
        }
        profiles.append(
            IterationProfile(Path(name).stem, backend, last.iterations, last.linear_solves, per_iteration, floor)
        )
    return profiles


def format_comparison(results: Sequence[FileResult]) -> str:
    """Markdown table: iterations, costs, solve and CLI times, ratios to GTSAM."""
    lines = [
        "| file | iterations egnc / gtsam | final cost egnc | final cost gtsam "
        "| solve egnc-cholmod (s) | solve egnc-scipy (s) | optimize gtsam (s) | cholmod / gtsam | scipy / gtsam "
        "| CLI egnc-cholmod (s) | CLI egnc-scipy (s) | CLI gtsam (s) | CLI cholmod / gtsam | CLI scipy / gtsam |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        s, c = r.solve_s, r.cli_s
        lines.append(
            f"| {r.name} | {r.egnc_iterations} / {r.gtsam_iterations} | {r.egnc_cost:.10g} | {r.gtsam_cost:.10g} "
            f"| {s['cholmod']:.3f} | {s['scipy']:.3f} | {s['gtsam']:.3f} "
            f"| {s['cholmod'] / s['gtsam']:.2f}x | {s['scipy'] / s['gtsam']:.2f}x "
            f"| {c['cholmod']:.3f} | {c['scipy']:.3f} | {c['gtsam']:.3f} "
            f"| {c['cholmod'] / c['gtsam']:.2f}x | {c['scipy'] / c['gtsam']:.2f}x |"
        )
    return "\n".join(lines)


def format_g2o(results: Sequence[FileResult]) -> str:
    """Markdown table: g2o's Gauss-Newton against egnc-cholmod, time ratio and optimum check."""
    lines = [
        "| file | iterations g2o / egnc | solve g2o (s) | solve egnc-cholmod (s) | g2o / egnc "
        "| egnc's cost at g2o's poses | egnc's optimum | same optimum |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in results:
        if r.g2o_cost is None:
            continue
        same = abs(r.g2o_cost - r.egnc_cost) <= SAME_OPTIMUM_RTOL * r.egnc_cost
        lines.append(
            f"| {r.name} | {r.g2o_iterations} / {r.egnc_iterations} | {r.solve_s['g2o']:.3f} "
            f"| {r.solve_s['cholmod']:.3f} | {r.solve_s['g2o'] / r.solve_s['cholmod']:.2f}x "
            f"| {r.g2o_cost:.10g} | {r.egnc_cost:.10g} | {'yes' if same else 'no'} |"
        )
    return "\n".join(lines)


def format_iterations(profiles: Sequence[IterationProfile]) -> str:
    """Markdown table: ms per accepted iteration by phase, the bare factorization floor and the ratios."""
    lines = [
        "| file | backend | iterations / solves | linearize | assemble | factorize (+solve) | update "
        "| python (lin+asm+upd) | floor: bare CHOLMOD factorization | python / floor |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for p in profiles:
        ms = p.phase_ms
        lines.append(
            f"| {p.name} | {p.backend} | {p.iterations} / {p.linear_solves} | {ms['linearize']:.1f} "
            f"| {ms['assemble']:.1f} | {ms['factorize']:.1f} | {ms['update']:.1f} | {p.python_ms:.1f} "
            f"| {p.floor_ms:.1f} | {p.python_ms / p.floor_ms:.2f} |"
        )
    return "\n".join(lines)


def environment() -> str:
    """One line: date, machine and library versions."""
    stamp = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    versions = ", ".join(f"{pkg} {version(pkg)}" for pkg in ("egnc", "numpy", "scipy", "scikit-sparse", "gtsam")) + (
        f", g2opy {version('g2opy')}" if g2o_available() else ""
    )
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    return (
        f"{stamp}; {_cpu_model()}, {os.cpu_count()} cpus; Python {platform.python_version()}; {versions}; "
        f"OPENBLAS_NUM_THREADS={threads}"
    )


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown cpu"


def run(files: Sequence[str], repeat: int, command: str) -> int:
    """Print the comparison, g2o and per-iteration tables for `files`."""
    print(f"`{command}`")
    print(environment() + "\n")
    results = []
    profiles: list[IterationProfile] = []
    for name in files:
        results.append(compare_file(name, repeat))
        profiles.extend(profile_iterations(name, repeat))
    print(format_comparison(results))
    print(
        f"\nMedian of {repeat} interleaved runs. GTSAM: LM, relativeErrorTol = absoluteErrorTol = {GTSAM_TOL:g}, "
        "maxIterations 1000, prior sigma 1e-3 on the first pose. egnc: LM, rel_cost_tol 1e-10, "
        "gradient_tol 1e-10, step_tol 1e-12, first pose fixed.\n"
    )
    if g2o_available():
        print(format_g2o(results))
        print(
            "\ng2o: Gauss-Newton, LinearSolverEigen (Eigen's sparse Cholesky), stop when the relative chi2 "
            f"decrease < 1e-10 or after 100 iterations, first pose fixed; same optimum: within {SAME_OPTIMUM_RTOL:g} "
            "of egnc's cost (g2o's 3D error takes half the rotation angle, so its optimum differs there).\n"
        )
    else:
        print("g2o: not compared (`import g2opy` failed; `pip install g2opy`).\n")
    print(format_iterations(profiles))
    print("\nms per accepted iteration (phase total / iterations); floor: median bare `cholesky_inplace`.")
    return 0
