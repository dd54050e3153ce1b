"""Fuzz egnc with seeded cases and print the outcomes by class (the tables of RELIABILITY.md).

    python benchmarks/fuzz.py [--target files|options|api|checkpoints|all] [--cases N] [--seed S]
    python benchmarks/fuzz.py --target kill-resume [--file F.g2o] [--kills 20] [--seed S]
        [--checkpoint-every 5] [--method egnc] [--decide-at-arrival]

Targets (each a module of `benchmarks/_lib` over the shared `fuzz_core`):

- `files` (`fuzz_files`): mutated g2o and IRL texts must read to a graph or an `EgncError`, and solve
  to finite numbers or an `EgncError`, printing nothing;
- `options` (`fuzz_options`): invalid option values are refused naming the field, valid ones solve;
- `api` (`fuzz_api`): every misuse of the public API ends in a one-line `EgncError`;
- `checkpoints` (`fuzz_checkpoints`): a damaged checkpoint is refused in one line naming the file,
  or resumes;
- `all`: the four above;
- `kill-resume` (`kill_resume`): an `egnc-solve --online --checkpoint` replay killed `--kills` times
  and resumed ends where an uninterrupted run does.

Exit status 1 when any case is a bug. `tests/test_fuzz.py` runs the same targets with fewer cases.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

TARGETS = ("files", "options", "api", "checkpoints")


def main(argv: list[str] | None = None) -> int:
    """Run the chosen target(s) and print each table; 1 if a case is a bug."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", choices=[*TARGETS, "all", "kill-resume"], default="files")
    parser.add_argument("--cases", type=int, default=2000, help="number of cases per target (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    kill = parser.add_argument_group("kill-resume")
    kill.add_argument("--file", type=Path, help="the replayed graph (default datasets/grid2d_outliers.g2o)")
    kill.add_argument("--kills", type=int, default=20)
    kill.add_argument("--checkpoint-every", type=int, default=5)
    kill.add_argument("--method", default="egnc")
    kill.add_argument("--decide-at-arrival", action="store_true", help="egnc-solve --decide-at-arrival")
    args = parser.parse_args(argv)
    if args.target == "kill-resume":
        from _lib import kill_resume

        file = args.file or kill_resume.DEFAULT_FILE
        return kill_resume.run(file, args.kills, args.seed, args.checkpoint_every, args.method, args.decide_at_arrival)

    import importlib

    failed = False
    for name in TARGETS if args.target == "all" else [args.target]:
        target = importlib.import_module(f"_lib.fuzz_{name}")
        started = time.perf_counter()
        text, bugs = target.run_target(args.cases, args.seed)
        print(f"### {name}: {args.cases} cases, seed {args.seed}, {time.perf_counter() - started:.0f} s, {bugs} bugs")
        print(f"\n{text}\n", flush=True)
        failed |= bugs > 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
