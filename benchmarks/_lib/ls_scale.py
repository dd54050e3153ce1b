"""Least squares at scale: `egnc-solve --method l2` against GTSAM's LM on generated grids.

    python benchmarks/least_squares.py scale [--poses 100000,250000,500000,1000000] [--dim 2]
        [--backends cholmod,rslab,scipy] [--no-gtsam] [--runs 1] [--timeout 600] [--init file|chordal]

For each pose count a child process generates the clean grid (`egnc.datasets.grid_world`, seed
1, no false loops) and writes it to a temporary .g2o file. Then, `--runs` times and alternated
(every solver once, then again), each solver solves that file in a process of its own:

- `egnc-solve FILE --method l2 --linear-solver B --init I -o OUT -q --report R.json`, one row per
  backend B: `solve (s)` is the report's `time_s` (the `egnc.solve` call alone: pattern,
  ordering, the LM steps);
- `python benchmarks/least_squares.py gtsam-solve FILE OUT --init I --json` (`gtsam_process`:
  `readG2o`, a prior on the first pose, LM with tolerances 1e-10 and 100 iterations at most, as
  egnc's defaults, `writeG2o`): `solve (s)` is `optimize()` alone (with `--init chordal`, GTSAM's LAGO or chordal
  initialization first, as egnc's time includes its own).

GTSAM's `converged` means fewer than 100 iterations (it reports no reason).

`wall (s)` is the whole process (start-up, imports, reading, solving, writing), `peak MiB` its
peak resident memory (the kernel's `ru_maxrss`), `cost` the final `0.5 sum r^2` over the edges
(GTSAM's includes its prior, which is 0 unless the first pose moves). A process still running
after `--timeout` seconds is killed and reported as such. Times are medians over the runs; the
ratios divide egnc's medians by GTSAM's on the same file in the same run.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from .paths import ENTRIES
from .processes import ChildRun, run_child

ENTRY = ENTRIES / "least_squares.py"


def generate(poses: int, dim: int, path: Path) -> int:
    """Write the clean seed-1 grid of `poses` poses to `path`; its number of edges (the child's side)."""
    from egnc.datasets import grid_world
    from egnc.io import write_g2o

    graph = grid_world(dim, poses, seed=1).graph
    write_g2o(graph, path)
    return graph.num_edges


def egnc_run(path: Path, backend: str, init: str, folder: Path, timeout: float) -> dict:
    """One `egnc-solve` process on `path` with `backend`; its figures."""
    report = folder / "report.json"
    report.unlink(missing_ok=True)
    command = [
        str(Path(sys.executable).with_name("egnc-solve")),
        str(path),
        "--method",
        "l2",
        "--linear-solver",
        backend,
        "--init",
        init,
        "-o",
        str(folder / "egnc.g2o"),
        "-q",
        "--report",
        str(report),
    ]
    run = run_child(command, timeout)
    if not run.ok:
        return _failed(run)
    figures = json.loads(report.read_text())
    return {
        "wall_s": run.wall_s,
        "mib": run.peak_mib,
        "solve_s": figures["time_s"],
        "cost": figures["final_cost_all_edges"],
        "iterations": figures["iterations"],
        "converged": figures["converged"],
    }


def gtsam_run(path: Path, init: str, folder: Path, timeout: float) -> dict:
    """One `least_squares.py gtsam-solve` process on `path`; its figures."""
    out = folder / "gtsam.g2o"
    command = [sys.executable, str(ENTRY), "gtsam-solve", str(path), str(out), "--init", init, "--json"]
    run = run_child(command, timeout)
    if not run.ok:
        return _failed(run)
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    converged = figures["iterations"] < 100
    return {"wall_s": run.wall_s, "mib": run.peak_mib, "solve_s": figures["solve_s"], "cost": figures["cost"]} | {
        "iterations": figures["iterations"],
        "converged": converged,
    }


def _failed(run: ChildRun) -> dict:
    """The figures of a process killed at its time limit or failed."""
    return {"wall_s": run.wall_s, "mib": run.peak_mib, "failed": True}


def summary(runs: list[dict]) -> dict:
    """Medians of the runs' times and memory, and the last run's cost and iterations; `failed` if any run failed."""
    if any(run.get("failed") for run in runs):
        return {"failed": True, "wall_s": max(run["wall_s"] for run in runs)}
    keys = ("wall_s", "solve_s", "mib")
    return {key: statistics.median(run[key] for run in runs) for key in keys} | {
        key: runs[-1][key] for key in ("cost", "iterations", "converged")
    }


def run(poses: str, dim: int, backends: str, gtsam: bool, runs: int, timeout: float, init: str) -> None:
    """Generate each grid of `poses` (comma-separated counts), time every solver on it, print the markdown table."""
    solvers = [f"egnc {backend}" for backend in filter(None, backends.split(","))]
    solvers += ["gtsam"] if gtsam else []
    from egnc.bench.report import installed_versions

    versions = installed_versions(("numpy", "scipy", "scikit-sparse", "rslab", "gtsam"))
    print(f"{time.strftime('%Y-%m-%d %H:%M')}; {versions}; --init {init}\n")
    print(
        "| poses | edges | solver | wall (s) | solve (s) | peak MiB | cost | iterations | converged"
        " | wall / GTSAM | solve / GTSAM |"
    )
    print("|---:|---:|---|---:|---:|---:|---:|---:|---|---:|---:|")
    for count in (int(text) for text in filter(None, poses.split(","))):
        with tempfile.TemporaryDirectory(prefix="egnc-ls-scale-") as name:
            folder = Path(name)
            path = folder / f"grid{dim}d-{count}.g2o"
            done = run_child([sys.executable, str(ENTRY), "scale", "--generate", str(count), str(dim), str(path)])
            if not done.ok:
                raise SystemExit(f"generating {path.name} failed: {done.stderr.strip()[-300:]}")
            edges = int(done.stdout.strip().splitlines()[-1])
            timed: dict[str, list[dict]] = {solver: [] for solver in solvers}
            for _ in range(runs):
                for solver in solvers:
                    if solver == "gtsam":
                        timed[solver].append(gtsam_run(path, init, folder, timeout))
                    else:
                        timed[solver].append(egnc_run(path, solver.split()[1], init, folder, timeout))
            figures = {solver: summary(solver_runs) for solver, solver_runs in timed.items()}
        reference = figures.get("gtsam", {"failed": True})
        for solver, f in figures.items():
            if f.get("failed"):
                print(f"| {count} | {edges} | {solver} | not finished after {f['wall_s']:.0f} s | | | | | | | |")
                continue
            ratios = " | |"
            if solver != "gtsam" and not reference.get("failed"):
                ratios = f" {f['wall_s'] / reference['wall_s']:.2f} | {f['solve_s'] / reference['solve_s']:.2f} |"
            print(
                f"| {count} | {edges} | {solver} | {f['wall_s']:.2f} | {f['solve_s']:.2f} | {f['mib']:.0f}"
                f" | {f['cost']:.6g} | {f['iterations']} | {'yes' if f['converged'] else 'no'} |{ratios}",
                flush=True,
            )
