"""The output files of `egnc-solve`: checked before anything is read, written all or nothing.

Before reading the input, every output path is checked: it must not be the input file, nor the
path of another output, and its directory must exist and be writable. After the solve, the data
outputs are written to temporaries and renamed together (`egnc.io.atomic.all_or_nothing`), so a
failure in any of them leaves every previous file untouched, except the `--plot` figure: drawn
last, its failure is a warning and the other outputs are still written.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from egnc.api import Result
from egnc.cli.edges_csv import write_edges_csv
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io import write_g2o
from egnc.io.atomic import all_or_nothing, atomic_text_file, check_writable
from egnc.io.trajectory import TrajectoryFormat, trajectory_format, write_trajectory
from egnc.plot import figure_format, plot_trajectory, save_figure


@dataclass(frozen=True)
class OutputPlan:
    """What to write where; None skips an output.

    Attributes:
        graph: `-o`, the optimized graph (g2o).
        report: `--report`, the JSON report.
        plot: `--plot`, the trajectory figure.
        plot_size: `--plot-size`, the figure's `(width, height)` in inches; None for the default.
        dpi: `--dpi`, the figure's resolution in dots per inch.
        trajectory: `--trajectory`, the poses in TUM or KITTI format.
        trajectory_format: `"tum"`, `"kitti"`, or None to take it from the suffix.
        edges: `--edges`, the per-edge CSV.
        drop_outliers: write the graph without the rejected loop closures.
    """

    graph: Path | None = None
    report: Path | None = None
    plot: Path | None = None
    plot_size: tuple[float, float] | None = None
    dpi: float = 100.0
    trajectory: Path | None = None
    trajectory_format: TrajectoryFormat | None = None
    edges: Path | None = None
    drop_outliers: bool = False

    def paths(self) -> list[tuple[str, Path]]:
        """`(option, path)` of each output asked for."""
        named = [
            ("-o", self.graph),
            ("--report", self.report),
            ("--plot", self.plot),
            ("--trajectory", self.trajectory),
            ("--edges", self.edges),
        ]
        return [(option, path) for option, path in named if path is not None]

    def check(self, input_path: Path) -> None:
        """Refuse outputs that would destroy data or cannot be written, before any work is done.

        Raises:
            EgncError: an output is the input file or another output's file, is a directory, or
                its directory is missing or not writable; the trajectory format is unknown; or
                `--plot` is asked for without matplotlib or in a format it cannot write.
        """
        paths = self.paths()
        for k, (option, path) in enumerate(paths):
            if _same_file(path, input_path):
                raise EgncError(f"{path}: {option} names the input file; choose another output path")
            for other_option, other in paths[:k]:
                if _same_file(path, other):
                    raise EgncError(f"{path}: given to both {other_option} and {option}; choose two paths")
            check_writable(path)
        if self.trajectory is not None:
            trajectory_format(self.trajectory, self.trajectory_format)
        if self.plot is not None:
            figure_format(self.plot)

    def write(self, result: Result, initial: PoseGraph, report: dict) -> tuple[list[Path], list[str]]:
        """Write every output; returns the paths written and a warning per output that failed.

        All outputs are written all or nothing, the figure last; but a figure matplotlib cannot
        draw must not lose the solve, so its failure is a one-line warning, and the other files
        are written without it.

        Args:
            result: the solve.
            initial: the graph as read (the initial guess, drawn by `--plot`).
            report: the JSON report (`egnc.cli.report.report_dict`), written with `allow_nan=False`.
        """
        with all_or_nothing():
            if self.graph is not None:
                write_g2o(result.graph, self.graph, keep_edges=result.inliers if self.drop_outliers else None)
            if self.report is not None:
                with atomic_text_file(self.report) as out:
                    out.write(json.dumps(report, indent=2, allow_nan=False) + "\n")
            if self.trajectory is not None:
                write_trajectory(result.graph, self.trajectory, self.trajectory_format)
            if self.edges is not None:
                write_edges_csv(result, self.edges)
            notes = self._write_plot(result, initial) if self.plot is not None else []
        return [path for option, path in self.paths() if option != "--plot" or not notes], notes

    def _write_plot(self, result: Result, initial: PoseGraph) -> list[str]:
        """Draw and save the figure; a failure is returned as a one-line warning, not raised."""
        assert self.plot is not None
        try:
            save_figure(plot_trajectory(result, initial=initial, size=self.plot_size), self.plot, dpi=self.dpi)
        except Exception as error:  # noqa: BLE001 - any failure of the drawing library: the data is kept
            reason = " ".join(str(error).split()) or "no message"
            return [f"{self.plot}: --plot failed, no figure written ({type(error).__name__}: {reason})"]
        return []


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (hard links and symlinks included when both exist)."""
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()
