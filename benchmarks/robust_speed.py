"""The cost of robustness: default robust solve time over the clean least-squares solve time.

    python benchmarks/robust_speed.py [--datasets manhattanOlson3500,sphere2500]
        [--percent 10,30,50] [--seeds 1] [--backends cholmod,scipy] [--direct] [--before]
        [--large] [--grid 100000,...] [--grid3d 50000,...] [--clean-init auto|file|chordal] [--repeats N]
        [--importtime]

Each row runs in two child processes, so that each solve's peak resident memory is its own: the
first reads the file (or generates the grid), solves its least squares untimed from the file's
guess and from the chordal initialization (the reference is the lower minimum,
`egnc.bench.cases.least_squares_optimum`; also the warm-up), then times the clean least-squares
solve from that start (`egnc.solve(graph, "l2", init=...)`, its start in `clean init`): its
peak is `clean MiB`. The second adds riSAM-protocol false loops drawn against that reference
and times the default robust solve (`egnc.solve(corrupted, "egnc")`): its peak is `peak MiB`.
Iterations are per solved stage (the last one is the least-squares refinement); `CG` is the
conjugate-gradient iterations of all steps; `analyses` counts the linear solvers created for a
new sparsity pattern (each a fill-reducing ordering and a symbolic analysis: GNC problem,
trusted preconditioners, decision rounds, chordal solves); `rounds` the decision rounds of both
starts.

- `--direct`: also solve with `SolverOptions(linear_method="direct")` (one factorization of all
  edges per step) and report whether it rejects the same loops (`same as direct`).
- `--before`: also solve the way the default did before the chordal start (issue 16: every
  other start off, the decision from the guess alone) and report its time and whether it
  rejects the same loops.
- `--large`: add city10000 at 30% and a generated 100k-pose 2D grid at 10% (seed 1);
  `--datasets "" --large` runs only those.
- `--grid`: add generated 2D grids (`egnc.datasets.grid_world`, seed 1) of these pose counts, at
  each `--percent`; `--datasets "" --grid 100000` runs only those.
- `--grid3d`: the same with 3D grids (`grid_world(3, ...)`, seed 1).
- `--clean-init file|chordal`: the clean least squares (reference and timed) starts from there
  instead of the lower of the two minima (`auto`, the default): from the chained odometry of a
  large grid LM stops in a folded map (3D, 50k poses: 100 iterations, cost 180x the optimum),
  which is no reference for the decisions nor for the time.
- `--repeats N`: time each case N times, the clean and robust children in turn (clean first,
  then robust first, ...: the machine's drift falls on both alike). The time and memory columns
  are medians, the ratio the median of the repeats' own ratios with their range; the script
  stops if two repeats differ in anything else (the solves are deterministic).
- `--importtime`: print the slowest imports of `python -X importtime -c "import egnc"`.

Precision and recall count false loops as positives; ATE is against the clean optimum (m).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATASETS = Path(os.environ.get("EGNC_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets"))
GRID_100K = "grid2d-100k"


def _graph(case: dict):
    """The case's clean graph: a shared file, or a generated 2D or 3D grid (`grid2d-<poses>`, `grid3d-<poses>`)."""
    from egnc.datasets import grid_world
    from egnc.io import read_g2o

    if case["dataset"].startswith(("grid2d-", "grid3d-")):
        poses = 100_000 if case["dataset"] == GRID_100K else int(case["dataset"].split("-")[1])
        return grid_world(int(case["dataset"][4]), poses, seed=1).graph
    return read_g2o(DATASETS / f"{case['dataset']}.g2o")


def run_clean(case: dict) -> dict:
    """Solve the clean least squares (the reference, then timed); save the reference poses (the child's side)."""
    import numpy as np

    from egnc.api import solve
    from egnc.bench.cases import least_squares_optimum

    backend = case["backend"]
    graph = _graph(case)
    if case["clean_init"] == "auto":
        reference = least_squares_optimum(graph, backend)
    else:
        reference = solve(graph, "l2", linear_solver=backend, init=case["clean_init"])
    np.save(case["reference"], reference.graph.poses)
    started = time.perf_counter()
    clean = solve(graph, "l2", init=reference.init, linear_solver=backend)
    return {"clean_s": time.perf_counter() - started, "clean_iterations": clean.iterations, "clean_init": clean.init}


def run_robust(case: dict) -> dict:
    """Corrupt the graph against the saved reference and time the robust solve (the child's side)."""
    import numpy as np

    import egnc.linalg.analysis
    import egnc.nonlinear.chordal
    from egnc.api import solve
    from egnc.datasets import add_false_loops
    from egnc.metrics import ate, precision_recall
    from egnc.nonlinear.least_squares import SolverOptions
    from egnc.robust.gnc import GncOptions

    analyses = [0]

    def counted(make):  # every linear solver made for a new pattern is one symbolic analysis
        def make_counted(*args, **kwargs):
            analyses[0] += 1
            return make(*args, **kwargs)

        return make_counted

    egnc.linalg.analysis.make_linear_solver = counted(egnc.linalg.analysis.make_linear_solver)
    egnc.nonlinear.chordal.make_linear_solver = counted(egnc.nonlinear.chordal.make_linear_solver)
    backend = case["backend"]
    graph = _graph(case)
    reference_poses = np.load(case["reference"])
    corrupted = add_false_loops(graph, case["percent"], seed=case["seed"], reference_poses=reference_poses)
    started = time.perf_counter()
    robust = solve(corrupted.graph, "egnc", linear_solver=backend)
    robust_s = time.perf_counter() - started
    precision, recall = precision_recall(~robust.inliers, corrupted.is_outlier)
    out = {
        "robust_s": robust_s,
        "iterations": [stage.iterations for stage in robust.stages],
        "cg": sum(stage.cg_iterations for stage in robust.stages),
        "analyses": analyses[0],
        "rounds": sum(stage.kind == "decision" for stage in robust.stages),
        "false": int(corrupted.is_outlier.sum()),
        "rejected": int((~robust.inliers).sum()),
        "precision": precision,
        "recall": recall,
        "ate": ate(robust.graph.poses[: graph.num_poses], reference_poses, graph.dim),
    }
    direct = SolverOptions(linear_method="direct")
    guess_only = GncOptions(starts=())
    variants = {"direct": (direct, GncOptions()), "before": (SolverOptions(), guess_only)}
    for name in ("direct", "before"):
        if case[name]:
            options, gnc_options = variants[name]
            started = time.perf_counter()
            other = solve(corrupted.graph, "egnc", linear_solver=backend, options=options, gnc_options=gnc_options)
            out[f"{name}_s"] = time.perf_counter() - started
            out[f"{name}_same"] = bool(np.array_equal(other.inliers, robust.inliers))
    return out


def _child(case: dict) -> tuple[dict, float]:
    """Run `case` in a child process; its figures and its peak resident memory (MiB)."""
    command = [sys.executable, __file__, "--case", json.dumps(case)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None
    output = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise SystemExit(f"case {case} failed with exit code {process.returncode}")
    return json.loads(output.strip().splitlines()[-1]), usage.ru_maxrss / 1024  # kilobytes on Linux


def run_child(case: dict, repeats: int = 1) -> dict:
    """Run `case`'s clean and robust solves `repeats` times, each in its own child process, with
    their peak memory; several repeats are merged by `combined`."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        case = case | {"reference": str(Path(folder) / "reference.npy")}
        for repeat in range(repeats):
            phases = ("clean", "robust") if repeat % 2 == 0 else ("robust", "clean")  # the reference exists by then
            done = {phase: _child(case | {"phase": phase}) for phase in phases}
            (clean, clean_mib), (robust, robust_mib) = done["clean"], done["robust"]
            rows.append(clean | robust | {"clean_mib": clean_mib, "peak_mib": robust_mib})
    return combined(rows)


MEASURED = ("clean_s", "robust_s", "clean_mib", "peak_mib", "direct_s", "before_s")
"""Fields that differ from run to run: merged as medians over repeats; every other field must agree."""


def combined(rows: list[dict]) -> dict:
    """One row from the repeats `rows` of a case: medians of `MEASURED`, and `ratio` (the median of
    each repeat's robust / clean time) with `ratio_range` (its lowest and highest).

    Raises:
        SystemExit: two repeats differ in a field outside `MEASURED`.
    """
    import numpy as np

    from egnc.bench.report import merged_repeats

    ratios = [row["robust_s"] / row["clean_s"] for row in rows]
    merged = merged_repeats(rows, MEASURED)
    return {**merged, "ratio": float(np.median(ratios)), "ratio_range": (min(ratios), max(ratios))}


def import_times(top: int = 12) -> list[tuple[int, int, str]]:
    """`(self us, cumulative us, module)` of the slowest imports of `import egnc`, and the total."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", "import egnc"], capture_output=True, text=True, check=True
    )
    rows = []
    for line in done.stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        own, cumulative, name = (part.strip() for part in line[len("import time:") :].split("|"))
        rows.append((int(own), int(cumulative), name))
    egnc_total = next(row for row in rows if row[2] == "egnc")
    return [egnc_total] + sorted((r for r in rows if r[2] != "egnc"), key=lambda r: -r[1])[:top]


def main() -> None:
    """Parse arguments, run every case in a child process, print the markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", help=argparse.SUPPRESS)
    parser.add_argument("--datasets", default="manhattanOlson3500,sphere2500")
    parser.add_argument("--percent", default="10,30,50")
    parser.add_argument("--seeds", default="1")
    parser.add_argument("--backends", default="cholmod,scipy")
    parser.add_argument("--direct", action="store_true")
    parser.add_argument("--before", action="store_true")
    parser.add_argument("--large", action="store_true")
    parser.add_argument("--grid", default="", help="generated 2D grids of these pose counts, at each --percent")
    parser.add_argument("--grid3d", default="", help="generated 3D grids of these pose counts, at each --percent")
    parser.add_argument("--clean-init", choices=("auto", "file", "chordal"), default="auto")
    parser.add_argument("--repeats", type=int, default=1, help="times each case is timed, clean and robust in turn")
    parser.add_argument("--importtime", action="store_true")
    args = parser.parse_args()
    if args.case:
        case = json.loads(args.case)
        print(json.dumps(run_clean(case) if case["phase"] == "clean" else run_robust(case)))
        return

    backends = args.backends.split(",")
    cases = [
        {"dataset": dataset, "percent": float(percent), "seed": int(seed), "backend": backend}
        for dataset in filter(None, args.datasets.split(","))
        for percent in args.percent.split(",")
        for seed in args.seeds.split(",")
        for backend in backends
    ]
    if args.large:
        cases += [{"dataset": "city10000", "percent": 30.0, "seed": 1, "backend": b} for b in backends]
        cases += [{"dataset": GRID_100K, "percent": 10.0, "seed": 1, "backend": b} for b in backends]
    cases += [
        {"dataset": f"grid{dim}d-{poses}", "percent": float(percent), "seed": 1, "backend": backend}
        for dim, counts in ((2, args.grid), (3, args.grid3d))
        for poses in filter(None, counts.split(","))
        for percent in args.percent.split(",")
        for backend in backends
    ]
    from egnc.bench.report import installed_versions

    versions = installed_versions(("numpy", "scipy", "scikit-sparse", "rslab"))
    print(f"{time.strftime('%Y-%m-%d')}; {versions}\n")
    header = (
        "| dataset | false % | seed | backend | clean init | clean l2 (s) | robust (s) | ratio | iterations | CG |"
        " analyses | rounds | rejected / false | P | R | ATE (m) | clean MiB | peak MiB | peak / clean |"
    )
    extra = (" direct (s) | same as direct |" if args.direct else "") + (
        " before (s) | same as before |" if args.before else ""
    )
    print(header + extra)
    print(
        "|---|---:|---:|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        + "---:|---|" * extra.count("same")
    )
    for case in cases:
        options = {"direct": args.direct, "before": args.before, "clean_init": args.clean_init}
        f = run_child(case | options, args.repeats)
        spread = f" ({f['ratio_range'][0]:.1f}-{f['ratio_range'][1]:.1f})" if args.repeats > 1 else ""
        row = (
            f"| {case['dataset']} | {case['percent']:g} | {case['seed']} | {case['backend']} | {f['clean_init']}"
            f" | {f['clean_s']:.3f}"
            f" | {f['robust_s']:.3f} | {f['ratio']:.1f}{spread} | {'+'.join(map(str, f['iterations']))}"
            f" | {f['cg']} | {f['analyses']} | {f['rounds']} | {f['rejected']} / {f['false']} | {f['precision']:.4f}"
            f" | {f['recall']:.4f} | {f['ate']:.2e} | {f['clean_mib']:.0f} | {f['peak_mib']:.0f}"
            f" | {f['peak_mib'] / f['clean_mib']:.2f} |"
        )
        for name in ("direct", "before"):
            if f"{name}_s" in f:
                row += f" {f[f'{name}_s']:.2f} | {'yes' if f[f'{name}_same'] else 'NO'} |"
        print(row, flush=True)
    if args.importtime:
        print('\n`python -X importtime -c "import egnc"`, slowest (microseconds):\n')
        print("| module | self | cumulative |\n|---|---:|---:|")
        for own, cumulative, name in import_times():
            print(f"| {name} | {own} | {cumulative} |")


if __name__ == "__main__":
    main()
