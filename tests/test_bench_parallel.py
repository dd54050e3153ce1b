"""Runs in parallel: child processes and their time limits, `--workers`, and a Dask cluster on the
loopback address giving the same table as a serial run."""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from egnc.bench import RunRecord, run_grid
from egnc.bench.child import Call, run_in_child
from egnc.bench.parallel import DaskPool, LocalPool

DATASETS = Path(__file__).parents[1] / "datasets"
GRID = dict(datasets=["grid2d", "grid3d"], percents=[10, 30], seeds=[1, 2], methods=["egnc", "l2"])
"""8 cases x 2 methods on the shipped grids: 16 runs of well under a second each."""

TIMES = ("time_s", "wall_s")


def without_times(records: list[RunRecord]) -> list[dict]:
    """Everything a record holds but its times."""
    return [{k: v for k, v in dataclasses.asdict(r).items() if k not in TIMES} for r in records]


@pytest.fixture(scope="module")
def serial() -> list[RunRecord]:
    return run_grid(**GRID, data_dir=DATASETS, time_limit_s=120)


# --- child processes ----------------------------------------------------------------------------


def test_a_child_answers_times_out_or_dies():
    assert run_in_child(math.sqrt, (4.0,), 10).value == 2.0
    slow = run_in_child(time.sleep, (5,), 0.3)
    assert (slow.status, slow.value) == ("timeout", None) and 0.3 <= slow.wall_s < 3
    assert run_in_child(math.sqrt, (-1.0,), 10).status == "error: ValueError: math domain error"
    assert run_in_child(os._exit, (3,), 10).status == "error: child process died (exit code 3)"


def test_local_pool_runs_calls_at_once_each_with_its_own_limit():
    calls = [("slow", Call(time.sleep, (30,), 1.0))] + [(k, Call(time.sleep, (0.5,), 10)) for k in range(3)]
    started = time.perf_counter()
    outcomes = dict(LocalPool(workers=2).run(calls))
    elapsed = time.perf_counter() - started
    assert outcomes["slow"].status == "timeout"
    assert [outcomes[k].status for k in range(3)] == ["ok"] * 3
    # Serially this takes 1 + 3 * 0.5 s; with two children at once the sleeps overlap the slow one.
    assert elapsed < 2.3


def write_pid_and_sleep(path: Path, seconds: float) -> None:
    path.write_text(str(os.getpid()))
    time.sleep(seconds)


def test_local_pool_kills_its_children_when_the_caller_stops(tmp_path):
    calls = [(0, Call(time.sleep, (0.05,), 120)), (1, Call(write_pid_and_sleep, (tmp_path / "pid", 60), 120))]
    results = LocalPool(workers=2).run(calls)
    assert next(results)[0] == 0
    while not (tmp_path / "pid").exists() or not (tmp_path / "pid").read_text():
        time.sleep(0.01)
    pid = int((tmp_path / "pid").read_text())
    os.kill(pid, 0)  # the slow child runs
    results.close()  # the caller stops: the pool's cleanup kills and reaps it
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


# --- the grid in parallel -----------------------------------------------------------------------


def test_workers_give_the_serial_table(serial):
    lines: list[str] = []
    parallel = run_grid(**GRID, data_dir=DATASETS, time_limit_s=120, workers=2, progress=lines.append)
    assert without_times(parallel) == without_times(serial)
    assert all(r.ok for r in parallel) and any(r.success for r in parallel)
    assert sorted(int(line[1 : line.index("/")]) for line in lines) == list(range(1, 17))


def test_cli_workers_and_dask_exclude_each_other():
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.bench", "--datasets", "grid2d", "--workers", "2",
         "--dask-scheduler", "tcp://127.0.0.1:1"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert run.returncode == 2 and "exclude each other" in run.stderr


# --- Dask ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes on the loopback address.

    LocalCluster leaves `OPENBLAS_NUM_THREADS=1` (and OMP, MKL) in this process's environment for
    its workers; it is restored afterwards, so that nothing after it runs in another environment
    (egnc itself reads that variable only at import: `USER_CHOSE_OPENBLAS_THREADS`).
    """
    distributed = pytest.importorskip("distributed")
    saved = dict(os.environ)
    try:
        with distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        ) as local:
            yield local
    finally:
        os.environ.clear()
        os.environ.update(saved)


def test_dask_cluster_gives_the_serial_table(serial, cluster):
    lines: list[str] = []
    on_dask = run_grid(
        **GRID, data_dir=DATASETS, time_limit_s=120, dask_scheduler=cluster.scheduler_address, progress=lines.append
    )
    assert without_times(on_dask) == without_times(serial)
    assert len(lines) == 16 and lines[-1].startswith("[16/16] ")


def test_dask_workers_enforce_the_time_limit(cluster):
    pool = DaskPool(cluster.scheduler_address)
    try:
        outcomes = dict(pool.run([("slow", Call(time.sleep, (30,), 0.5)), ("quick", Call(math.sqrt, (9.0,), 10))]))
    finally:
        pool.close()
    assert outcomes["slow"].status == "timeout" and outcomes["slow"].wall_s < 5
    assert (outcomes["quick"].status, outcomes["quick"].value) == ("ok", 3.0)


def test_dask_cli_writes_the_serial_table(cluster, tmp_path):
    common = ["--datasets", "grid2d", "--data-dir", DATASETS, "--percent", "30", "--seeds", "1,2", "--methods", "egnc"]
    for name, extra in (("serial", []), ("dask", ["--dask-scheduler", cluster.scheduler_address])):
        run = subprocess.run(
            [sys.executable, "-m", "egnc.cli.bench", *common, *extra, "--out", tmp_path / name, "-q"],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr
    tables = [(tmp_path / name / "results.md").read_text().split("\n\n", 2)[2] for name in ("serial", "dask")]
    strip_times = [[row.split("|")[:9] for row in table.splitlines()] for table in tables]
    assert strip_times[0] == strip_times[1]


def test_an_unreachable_scheduler_is_a_one_line_error(tmp_path):
    pytest.importorskip("distributed")
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.bench", "--datasets", "grid2d", "--data-dir", DATASETS,
         "--dask-scheduler", "tcp://127.0.0.1:1", "--out", tmp_path / "out"],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"},  # not Dask's 30 s
    )  # fmt: skip
    assert run.returncode == 1
    assert run.stderr.startswith("egnc-bench: error: cannot connect to the Dask scheduler at tcp://127.0.0.1:1")
    assert run.stderr.count("\n") == 1
