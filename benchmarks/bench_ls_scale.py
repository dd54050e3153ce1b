"""Least squares at scale: `egnc-solve --method l2` against GTSAM's LM on generated grids.

    python benchmarks/bench_ls_scale.py [--poses 100000,250000,500000,1000000] [--dim 2]
        [--backends cholmod,rslab,scipy] [--no-gtsam] [--runs 1] [--timeout 600] [--init file|chordal]

For each pose count a child process generates the clean grid (`egnc.datasets.grid_world`, seed
1, no false loops) and writes it to a temporary .g2o file. Then, `--runs` times and alternated
(every solver once, then again), each solver solves that file in a process of its own:

- `egnc-solve FILE --method l2 --linear-solver B --init I -o OUT -q --report R.json`, one row per
  backend B: `solve (s)` is the report's `time_s` (the `egnc.solve` call alone: pattern,
  ordering, the LM steps);
- `python benchmarks/gtsam_solve.py FILE OUT --init I --json` (`readG2o`, a prior on the first
  pose, LM with tolerances 1e-10 and 100 iterations at most, as egnc's defaults, `writeG2o`):
  `solve (s)` is `optimize()` alone (with `--init chordal`, GTSAM's LAGO or chordal
  initialization first, as egnc's time includes its own).

GTSAM's `converged` means fewer than 100 iterations (it reports no reason).

`wall (s)` is the whole process (start-up, imports, reading, solving, writing), `peak MiB` its
peak resident memory (the kernel's `ru_maxrss`), `cost` the final `0.5 sum r^2` over the edges
(GTSAM's includes its prior, which is 0 unless the first pose moves). A process still running
after `--timeout` seconds is killed and reported as such. Times are medians over the runs; the
ratios divide egnc's medians by GTSAM's on the same file in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GTSAM_SCRIPT = Path(__file__).resolve().parent / "gtsam_solve.py"


def generate(poses: int, dim: int, path: Path) -> int:
    """Write the clean seed-1 grid of `poses` poses to `path`; its number of edges (the child's side)."""
    from egnc.datasets import grid_world
    from egnc.io import write_g2o

    graph = grid_world(dim, poses, seed=1).graph
    write_g2o(graph, path)
    return graph.num_edges


def run_process(command: list[str], timeout: float) -> tuple[str | None, float, float]:
    """Run `command`; `(stdout or None if killed at timeout or failed, wall seconds, peak MiB)`."""
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert process.stdout is not None
    killed = False
    while True:
        pid, status, usage = os.wait4(process.pid, os.WNOHANG)
        if pid:
            break
        if not killed and time.perf_counter() - started > timeout:
            process.kill()
            killed = True
        time.sleep(0.05)
    wall = time.perf_counter() - started
    output = process.stdout.read()
    process.returncode = os.waitstatus_to_exitcode(status)
    ok = not killed and process.returncode == 0
    return (output if ok else None), wall, usage.ru_maxrss / 1024  # kilobytes on Linux


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
    output, wall, mib = run_process(command, timeout)
    if output is None:
        return {"wall_s": wall, "mib": mib, "failed": True}
    figures = json.loads(report.read_text())
    return {
        "wall_s": wall,
        "mib": mib,
        "solve_s": figures["time_s"],
        "cost": figures["final_cost_all_edges"],
        "iterations": figures["iterations"],
        "converged": figures["converged"],
    }


def gtsam_run(path: Path, init: str, folder: Path, timeout: float) -> dict:
    """One `benchmarks/gtsam_solve.py` process on `path`; its figures."""
    command = [sys.executable, str(GTSAM_SCRIPT), str(path), str(folder / "gtsam.g2o"), "--init", init, "--json"]
    output, wall, mib = run_process(command, timeout)
    if output is None:
        return {"wall_s": wall, "mib": mib, "failed": True}
    figures = json.loads(output.strip().splitlines()[-1])
    converged = figures["iterations"] < 100
    return {"wall_s": wall, "mib": mib, "solve_s": figures["solve_s"], "cost": figures["cost"]} | {
        "iterations": figures["iterations"],
        "converged": converged,
    }


def summary(runs: list[dict]) -> dict:
    """Medians of the runs' times and memory, and the last run's cost and iterations; `failed` if any run failed."""
    if any(run.get("failed") for run in runs):
        return {"failed": True, "wall_s": max(run["wall_s"] for run in runs)}
    keys = ("wall_s", "solve_s", "mib")
    return {key: statistics.median(run[key] for run in runs) for key in keys} | {
        key: runs[-1][key] for key in ("cost", "iterations", "converged")
    }




def main() -> None:
    """Parse arguments, generate each grid, time every solver on it, print the markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generate", nargs=3, help=argparse.SUPPRESS)  # POSES DIM PATH, in the child
    parser.add_argument("--poses", default="100000,250000,500000,1000000")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--backends", default="cholmod,rslab,scipy")
    parser.add_argument("--no-gtsam", action="store_true", help="time egnc only")
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds after which a process is killed")
    parser.add_argument("--init", choices=("file", "chordal"), default="file", help="the initial guess of both")
    args = parser.parse_args()
    if args.generate:
        poses, dim, path = args.generate
        print(generate(int(poses), int(dim), Path(path)))
        return

    solvers = [f"egnc {backend}" for backend in filter(None, args.backends.split(","))]
    solvers += [] if args.no_gtsam else ["gtsam"]
    from egnc.bench.report import installed_versions

    versions = installed_versions(("numpy", "scipy", "scikit-sparse", "rslab", "gtsam"))
    print(f"{time.strftime('%Y-%m-%d %H:%M')}; {versions}; --init {args.init}\n")
    print(
        "| poses | edges | solver | wall (s) | solve (s) | peak MiB | cost | iterations | converged"
        " | wall / GTSAM | solve / GTSAM |"
    )
    print("|---:|---:|---|---:|---:|---:|---:|---:|---|---:|---:|")
    for poses in (int(text) for text in filter(None, args.poses.split(","))):
        with tempfile.TemporaryDirectory(prefix="egnc-ls-scale-") as name:
            folder = Path(name)
            path = folder / f"grid{args.dim}d-{poses}.g2o"
            done = subprocess.run(
                [sys.executable, __file__, "--generate", str(poses), str(args.dim), str(path)],
                capture_output=True,
                text=True,
                check=True,
            )
            edges = int(done.stdout.strip().splitlines()[-1])
            runs: dict[str, list[dict]] = {solver: [] for solver in solvers}
            for _ in range(args.runs):
                for solver in solvers:
                    if solver == "gtsam":
                        runs[solver].append(gtsam_run(path, args.init, folder, args.timeout))
                    else:
                        runs[solver].append(egnc_run(path, solver.split()[1], args.init, folder, args.timeout))
            figures = {solver: summary(solver_runs) for solver, solver_runs in runs.items()}
        reference = figures.get("gtsam", {"failed": True})
        for solver, f in figures.items():
            if f.get("failed"):
                print(f"| {poses} | {edges} | {solver} | not finished after {f['wall_s']:.0f} s | | | | | | | |")
                continue
            ratios = " | |"
            if solver != "gtsam" and not reference.get("failed"):
                ratios = f" {f['wall_s'] / reference['wall_s']:.2f} | {f['solve_s'] / reference['solve_s']:.2f} |"
            print(
                f"| {poses} | {edges} | {solver} | {f['wall_s']:.2f} | {f['solve_s']:.2f} | {f['mib']:.0f}"
                f" | {f['cost']:.6g} | {f['iterations']} | {'yes' if f['converged'] else 'no'} |{ratios}",
                flush=True,
            )


if __name__ == "__main__":
    main()
