"""Benchmark grid: datasets x outlier percentages x seeds x methods, each run isolated and timed.

The evaluation protocol is described in `docs/evaluation.md`. The package's modules, one job each:

- `methods`: method specs, `egnc[threshold=distance]`, and the GTSAM baselines' names;
- `cases`: datasets, their outlier-free references and seeded corruptions (`BenchCase`);
- `runs`: one method on one case: solve, score, `RunRecord`;
- `child`: a call in a forked child process, killed at its time limit;
- `parallel`: many calls at once, on this machine or on a Dask cluster;
- `runner`: the grid (`run_grid`) and the IRL mode (`run_irl`);
- `gtsam`: the GTSAM baselines (the optional `bench` extra);
- `report`: summaries over seeds, the markdown table, `results.csv` and plots.
"""

from egnc.bench.cases import BenchCase, resolve_dataset
from egnc.bench.gtsam import GTSAM_PRIOR_SIGMA, add_gtsam_reference_prior, gtsam_available
from egnc.bench.methods import GTSAM_METHODS, MethodSpec, parse_method, parse_methods
from egnc.bench.report import SUCCESS_DEFINITION, SummaryRow, format_markdown, summarize, write_outputs
from egnc.bench.runner import run_case, run_grid, run_irl
from egnc.bench.runs import CSV_COLUMNS, RunRecord, describe_run

__all__ = [
    "CSV_COLUMNS",
    "GTSAM_METHODS",
    "GTSAM_PRIOR_SIGMA",
    "SUCCESS_DEFINITION",
    "BenchCase",
    "MethodSpec",
    "RunRecord",
    "SummaryRow",
    "add_gtsam_reference_prior",
    "describe_run",
    "format_markdown",
    "gtsam_available",
    "parse_method",
    "parse_methods",
    "resolve_dataset",
    "run_case",
    "run_grid",
    "run_irl",
    "summarize",
    "write_outputs",
]
