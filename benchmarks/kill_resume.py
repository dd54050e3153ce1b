"""SIGKILL an online replay at random moments, resume it from its checkpoint, compare with an uninterrupted run.

    python benchmarks/kill_resume.py [--file datasets/grid2d_outliers.g2o] [--kills 20] [--seed 0]
        [--checkpoint-every 5] [--method egnc] [--decide-at-arrival]

One uninterrupted `egnc-solve FILE --online` run gives the reference poses and rejected edges.
Then one replay with `--checkpoint` is killed with SIGKILL at `--kills` moments drawn uniformly
over the reference run's wall time and resumed each time (the next attempt starts from the
checkpoint the killed one left), until a run completes; a kill that lands after the run
completed is drawn again. Prints one row per kill (the checkpointed step it resumed from) and the
largest pose difference and whether the rejected edges are the same as the reference's.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def egnc_solve(*args: object) -> list[str]:
    return [sys.executable, "-m", "egnc.cli.solve", *map(str, args)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--file", type=Path, default=Path(__file__).parents[1] / "datasets" / "grid2d_outliers.g2o")
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--checkpoint-every", type=int, default=5)
    parser.add_argument("--method", default="egnc")
    parser.add_argument("--decide-at-arrival", action="store_true", help="egnc-solve --decide-at-arrival")
    args = parser.parse_args()
    options = ["--online", "--method", args.method, *(["--decide-at-arrival"] if args.decide_at_arrival else [])]
    from egnc.io import read_g2o

    rng = random.Random(args.seed)
    work = Path(tempfile.mkdtemp(prefix="egnc-kill-"))
    whole_out, whole_report = work / "whole.g2o", work / "whole.json"
    started = time.perf_counter()
    subprocess.run(
        egnc_solve(args.file, *options, "-o", whole_out, "--report", whole_report, "-q"),
        check=True,
    )
    whole_s = time.perf_counter() - started
    checkpoint, out, report = work / "run.ckpt", work / "out.g2o", work / "report.json"
    command = egnc_solve(
        args.file, *options, "-o", out, "--report", report, "-q",
        "--checkpoint", checkpoint, "--checkpoint-every", args.checkpoint_every,
    )  # fmt: skip
    print(f"reference run: {whole_s:.1f} s; {args.kills} kills drawn in (0, {whole_s:.1f}) s after each start")
    print("| kill | after s | resumed from step |")
    print("|---|---|---|")
    kills = 0
    while True:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if kills < args.kills:
            delay = rng.uniform(0.0, whole_s)
            try:
                process.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                process.send_signal(signal.SIGKILL)
                process.wait()
                kills += 1
                step = "none yet"
                if checkpoint.exists():
                    from egnc.online import OnlineSolver

                    step = str(OnlineSolver.load(checkpoint)[0].steps)
                print(f"| {kills} | {delay:.2f} | {step} |", flush=True)
                continue
            if process.returncode != 0:
                raise SystemExit(f"run failed with status {process.returncode}")
            if not out.exists():
                continue
            checkpoint.unlink(missing_ok=True)  # completed before the kill: start over
            out.unlink()
            continue
        if process.wait() != 0:
            raise SystemExit(f"final run failed with status {process.returncode}")
        break
    difference = float(np.abs(read_g2o(out).poses - read_g2o(whole_out).poses).max())
    same = json.loads(report.read_text())["rejected_edges"] == json.loads(whole_report.read_text())["rejected_edges"]
    resumed = json.loads(report.read_text())["online"].get("resumed_from")
    print(f"\nkills: {kills}; final run resumed from step {resumed}; largest pose difference {difference:.3g};"
          f" same rejected edges: {same}")  # fmt: skip
    return 0 if same and difference <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
