"""Reports of the benchmark grid: means over seeds, the markdown table, `results.csv`, plots."""

from __future__ import annotations

import csv
import importlib.util
import io
import math
import os
import platform
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egnc.bench.runs import CSV_COLUMNS, RunRecord
from egnc.errors import EgncError
from egnc.io.atomic import atomic_text_file
from egnc.plot import save_figure

__all__ = [
    "SUCCESS_DEFINITION",
    "SummaryRow",
    "format_markdown",
    "installed_versions",
    "merged_repeats",
    "summarize",
    "write_outputs",
]

SUCCESS_DEFINITION = (
    "Precision and recall count the false loop closures as the positive class: precision = rejected "
    "false loops / rejected loops (1 when nothing is rejected), recall = rejected false loops / false "
    "loops (1 when there are none). A run is a success when both are exactly 1: it rejected every "
    "false loop closure and no true one. success = successes / runs over the seeds; a run that timed "
    "out or failed is not a success. precision, recall, ATE, RPE and time are means over the runs "
    "that finished."
)
"""What `success` and the other columns mean; `egnc-bench --help` and `results.md` quote it."""

PLOT_DPI = 120
"""Resolution of the grid's plots (`runtime.png`, `precision_recall.png`)."""


@dataclass(frozen=True)
class SummaryRow:
    """Runs of one method on one (dataset, percent), aggregated over seeds.

    Attributes:
        dataset, percent, method: the group.
        runs: number of runs (seeds); `ok` of them finished.
        failures: e.g. `"1 timeout"`, empty when every run finished.
        precision, recall, ate, rpe_percent, time_s: means over the finished runs (nan if none).
        successes: runs with precision = recall = 1.
        kept_precision, kept_recall: riSAM's convention (accepted loops positive), means over
            the finished runs (`RunRecord.kept_precision_recall`).
        time_ratio: `time_s` / the baseline method's `time_s` on the same group (nan without it).
    """

    dataset: str
    percent: float
    method: str
    runs: int
    ok: int
    failures: str
    precision: float
    recall: float
    successes: int
    ate: float
    rpe_percent: float
    time_s: float
    time_ratio: float
    kept_precision: float
    kept_recall: float


def summarize(records: Sequence[RunRecord], baseline_method: str | None = "risam") -> list[SummaryRow]:
    """Aggregate runs over seeds, per (dataset, percent, method), in first-seen order."""
    groups: dict[tuple[str, float, str], list[RunRecord]] = {}
    for record in records:
        groups.setdefault((record.dataset, record.percent, record.method), []).append(record)

    def mean(values: list[float]) -> float:
        return float(np.mean(values)) if values else math.nan

    means: dict[tuple[str, float, str], float] = {
        key: mean([r.time_s for r in runs if r.ok]) for key, runs in groups.items()
    }
    rows = []
    for (dataset, percent, method), runs in groups.items():
        finished = [r for r in runs if r.ok]
        failed: dict[str, int] = {}
        for r in runs:
            if not r.ok:
                kind = "timeout" if r.status == "timeout" else "error"
                failed[kind] = failed.get(kind, 0) + 1
        baseline = means.get((dataset, percent, baseline_method or ""), math.nan)
        time_s = means[(dataset, percent, method)]
        rows.append(
            SummaryRow(
                dataset=dataset,
                percent=percent,
                method=method,
                runs=len(runs),
                ok=len(finished),
                failures=", ".join(f"{count} {kind}" for kind, count in failed.items()),
                precision=mean([r.precision for r in finished]),
                recall=mean([r.recall for r in finished]),
                successes=sum(r.success for r in finished),
                ate=mean([r.ate for r in finished]),
                rpe_percent=mean([r.rpe_percent for r in finished]),
                time_s=time_s,
                time_ratio=time_s / baseline if baseline > 0 else math.nan,
                kept_precision=mean([r.kept_precision_recall[0] for r in finished]),
                kept_recall=mean([r.kept_precision_recall[1] for r in finished]),
            )
        )
    return rows


def format_markdown(rows: Sequence[SummaryRow], baseline_method: str | None = "risam") -> str:
    """A markdown table of `summarize`'s rows, followed by what its columns mean (`SUCCESS_DEFINITION`)."""
    ratio = f"time / {baseline_method}" if baseline_method else "time ratio"
    lines = [
        "| dataset | outliers % | method | precision | recall | success | P kept | R kept | ATE (m) | RPE (%) "
        f"| time (s) | {ratio} | failed |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.dataset} | {row.percent:g} | {row.method} | {_fixed(row.precision, 4)} "
            f"| {_fixed(row.recall, 4)} | {row.successes}/{row.runs} | {_fixed(row.kept_precision, 4)} "
            f"| {_fixed(row.kept_recall, 4)} | {_general(row.ate)} "
            f"| {_fixed(row.rpe_percent, 2)} | {_fixed(row.time_s, 3)} | {_fixed(row.time_ratio, 2)} "
            f"| {row.failures} |"
        )
    return "\n".join(lines) + "\n\n" + SUCCESS_DEFINITION


def _fixed(value: float, digits: int) -> str:
    return "-" if math.isnan(value) else f"{value:.{digits}f}"


def _general(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.4g}"


def _csv_value(value: object) -> str:
    """CSV text: exact floats (`repr`), empty for nan/None, `true`/`false` for flags."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def write_outputs(
    records: Sequence[RunRecord],
    out_dir: str | os.PathLike,
    *,
    baseline_method: str | None = "risam",
    header: str = "",
) -> dict[str, Path]:
    """Write `results.csv`, `results.md` and, when matplotlib is importable, the plots.

    Args:
        records: the runs.
        out_dir: folder to write into (created if needed); each file is replaced atomically.
        baseline_method: label of the method the time ratios are relative to.
        header: text put above the table in `results.md` (e.g. the command and the machine).

    Returns:
        The written files by name: "csv", "md", and "runtime" / "precision_recall" for the plots.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise EgncError(f"{out}: cannot create folder: {error.strerror or error}") from None
    written = {"csv": out / "results.csv", "md": out / "results.md"}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for record in records:
        writer.writerow([_csv_value(getattr(record, column)) for column in CSV_COLUMNS])
    with atomic_text_file(written["csv"]) as handle:
        handle.write(buffer.getvalue())
    rows = summarize(records, baseline_method)
    with atomic_text_file(written["md"]) as handle:
        intro = header.rstrip() + "\n\n" if header.strip() else ""
        handle.write(intro + format_markdown(rows, baseline_method) + "\n")
    if importlib.util.find_spec("matplotlib") is not None and rows:
        written["runtime"] = out / "runtime.png"
        written["precision_recall"] = out / "precision_recall.png"
        _plot_runtime(rows, baseline_method, written["runtime"])
        _plot_precision_recall(rows, written["precision_recall"])
    return written


# --- plots (matplotlib, the `plot` extra) -------------------------------------------------------


def _plot_runtime(rows: Sequence[SummaryRow], baseline_method: str | None, path: Path) -> None:
    """Bars of the time ratio to the baseline, grouped by outlier rate, one panel per dataset."""
    from matplotlib.figure import Figure

    datasets = list(dict.fromkeys(row.dataset for row in rows))
    methods = list(dict.fromkeys(row.method for row in rows))
    figure = Figure(figsize=(max(4.0, 3.2 * len(datasets)), 3.4), layout="constrained")
    axes = figure.subplots(1, len(datasets), squeeze=False)[0]
    width = 0.8 / len(methods)
    for ax, dataset in zip(axes, datasets):
        percents = sorted({row.percent for row in rows if row.dataset == dataset})
        for k, method in enumerate(methods):
            by_percent = {row.percent: row for row in rows if row.dataset == dataset and row.method == method}
            heights = [by_percent[p].time_ratio if p in by_percent else math.nan for p in percents]
            ax.bar(np.arange(len(percents)) + (k - (len(methods) - 1) / 2) * width, heights, width, label=method)
        ax.axhline(1.0, color="0.3", linewidth=0.8, linestyle="--")
        ax.set_xticks(np.arange(len(percents)), [f"{p:g}%" for p in percents])
        ax.set_title(dataset)
        ax.set_xlabel("outlier rate")
    axes[0].set_ylabel(f"runtime / {baseline_method}" if baseline_method else "runtime ratio")
    axes[-1].legend(fontsize="small")
    save_figure(figure, path, dpi=PLOT_DPI)


def _plot_precision_recall(rows: Sequence[SummaryRow], path: Path) -> None:
    """Two heat-map tables side by side (precision, recall): methods x (dataset, outlier rate)."""
    from matplotlib.figure import Figure

    methods = list(dict.fromkeys(row.method for row in rows))
    columns = list(dict.fromkeys((row.dataset, row.percent) for row in rows))
    cell = {(row.method, row.dataset, row.percent): row for row in rows}
    tables = {
        name: np.array(
            [[getattr(cell[(m, d, p)], name) if (m, d, p) in cell else math.nan for d, p in columns] for m in methods]
        )
        for name in ("precision", "recall")
    }
    finite = np.concatenate([values[np.isfinite(values)] for values in tables.values()])
    low = min(0.9, float(finite.min())) if len(finite) else 0.9  # 0.9 .. 1 unless worse
    size = (2 * (0.9 * len(columns) + 1.6) + 1.0, 0.45 * len(methods) + 1.4)
    figure = Figure(figsize=size, layout="constrained")
    axes = figure.subplots(1, 2, squeeze=False)[0]
    for ax, (name, values) in zip(axes, tables.items()):
        image = ax.imshow(values, cmap="RdYlGn", vmin=low, vmax=1.0, aspect="auto")
        for (i, j), value in np.ndenumerate(values):
            ax.text(j, i, "-" if math.isnan(value) else f"{value:.4f}", ha="center", va="center", fontsize="small")
        ax.set_yticks(np.arange(len(methods)), methods if ax is axes[0] else [])
        ax.set_xticks(np.arange(len(columns)), [f"{d}\n{p:g}%" for d, p in columns], fontsize="small")
        ax.set_title(name)
    figure.colorbar(image, ax=list(axes), shrink=0.9)
    save_figure(figure, path, dpi=PLOT_DPI)


def merged_repeats(rows: Sequence[dict], measured: Sequence[str], label: str = "") -> dict:
    """One row from the repeats `rows` of a deterministic benchmark run: the median of each
    `measured` field present (times, memory), every other field as all repeats have it.

    Raises:
        SystemExit: two repeats differ in a field outside `measured` (`label` names the run).
    """
    first = rows[0]
    for row in rows[1:]:
        differing = [key for key in first if key not in measured and row[key] != first[key]]
        if differing:
            raise SystemExit(f"{label}{': ' if label else ''}repeats differ in {', '.join(differing)}")
    return {**first, **{key: float(np.median([row[key] for row in rows])) for key in measured if key in first}}


def installed_versions(packages: Sequence[str], show_absent: bool = True) -> str:
    """`"Python 3.11.7, numpy 2.4.6, ..., 2 cores"` for the benchmark scripts' headers.

    A package that is not installed reads `"<name> absent"`, or is left out without `show_absent`.
    """
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for package in packages:
        try:
            found.append(f"{package} {version(package)}")
        except PackageNotFoundError:
            if show_absent:
                found.append(f"{package} absent")
    return f"Python {platform.python_version()}, {', '.join(found)}, {os.cpu_count()} cores"
