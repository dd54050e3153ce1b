"""Fuzz target `kill-resume`: SIGKILL an online replay at random moments, resume it, compare.

    python benchmarks/fuzz.py --target kill-resume [--file datasets/grid2d_outliers.g2o] [--kills 20]
        [--seed 0] [--checkpoint-every 5] [--method egnc] [--decide-at-arrival]

One uninterrupted `egnc-solve FILE --online` run gives the reference poses and rejected edges.
Then one replay with `--checkpoint` is killed with SIGKILL at `--kills` moments drawn uniformly
over the reference run's wall time and resumed each time (the next attempt starts from the
checkpoint the killed one left), until a run completes; a kill that lands after the run
completed is drawn again. Prints one row per kill (the checkpointed step it resumed from) and the
largest pose difference and whether the rejected edges are the same as the reference's.
"""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .paths import SHIPPED_DATASETS

DEFAULT_FILE = SHIPPED_DATASETS / "grid2d_outliers.g2o"


def egnc_solve(*args: object) -> list[str]:
    """The command line of `egnc-solve` with `args`, in this interpreter."""
    return [sys.executable, "-m", "egnc.cli.solve", *map(str, args)]


def run(file: Path, kills: int, seed: int, checkpoint_every: int, method: str, decide_at_arrival: bool) -> int:
    """Kill and resume as the module docstring says, printing one row per kill; 0 if the runs agree, else 1."""
    options = ["--online", "--method", method, *(["--decide-at-arrival"] if decide_at_arrival else [])]
    from egnc.io import read_g2o

    rng = random.Random(seed)
    work = Path(tempfile.mkdtemp(prefix="egnc-kill-"))
    whole_out, whole_report = work / "whole.g2o", work / "whole.json"
    started = time.perf_counter()
    subprocess.run(
        egnc_solve(file, *options, "-o", whole_out, "--report", whole_report, "-q"),
        check=True,
    )
    whole_s = time.perf_counter() - started
    checkpoint, out, report = work / "run.ckpt", work / "out.g2o", work / "report.json"
    command = egnc_solve(
        file, *options, "-o", out, "--report", report, "-q",
        "--checkpoint", checkpoint, "--checkpoint-every", checkpoint_every,
    )  # fmt: skip
    print(f"reference run: {whole_s:.1f} s; {kills} kills drawn in (0, {whole_s:.1f}) s after each start")
    print("| kill | after s | resumed from step |")
    print("|---|---|---|")
    done = 0
    while True:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if done < kills:
            delay = rng.uniform(0.0, whole_s)
            try:
                process.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                process.send_signal(signal.SIGKILL)
                process.wait()
                done += 1
                step = "none yet"
                if checkpoint.exists():
                    from egnc.online import OnlineSolver

                    step = str(OnlineSolver.load(checkpoint)[0].steps)
                print(f"| {done} | {delay:.2f} | {step} |", flush=True)
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
    print(f"\nkills: {done}; final run resumed from step {resumed}; largest pose difference {difference:.3g};"
          f" same rejected edges: {same}")  # fmt: skip
    return 0 if same and difference <= 1e-9 else 1
