"""GNSS fixes with multipath outliers and false loop closures: from a file to the rejected fixes on a plot.

Run from anywhere:

    python examples/04_gnss_priors.py [output.png]

A shipped graph with false loops gets a GNSS-like position fix every 5th pose (sigma 1 m), and a
tenth of the fixes jump 10-50 m in bursts of consecutive fixes (a street canyon's multipath). The
graph goes through a g2o file (`EDGE_SE2_XYPRIOR` lines), is solved with the defaults (loops and
fixes are both candidates for rejection, each fix tested at its own dimension), and the plot shows
the map with its rejected loops and fixes. Needs the `plot` extra.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no window

import numpy as np

import egnc
from egnc.datasets import add_multipath_outliers, add_position_priors
from egnc.plot import plot_trajectory

DATASETS = Path(__file__).resolve().parents[1] / "datasets"


def main() -> None:
    output = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("gnss.png")
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    reference = egnc.solve(graph).graph.poses  # where the simulated receiver really was
    fixed = add_position_priors(graph, reference, every=5, sigma=1.0, seed=1)
    moved = add_multipath_outliers(fixed, 10, seed=1, bursts=True, burst_size=(3, 8), reference_poses=reference)
    egnc.write_g2o(moved.graph, "gnss.g2o")  # fixes as EDGE_SE2_XYPRIOR lines
    graph = egnc.read_g2o("gnss.g2o")

    result = egnc.solve(graph)
    print(result)
    rejected = np.isin(graph.prior_factor_index, result.rejected_priors)
    print(f"rejected {rejected.sum()} of {graph.num_priors} fixes, "
          f"{(rejected & moved.is_outlier).sum()} of the {moved.is_outlier.sum()} moved ones")

    figure = plot_trajectory(result, size=(7, 6))
    ax = figure.axes[0]
    fixes, rows = graph.priors.measurements[:, :2], graph.priors.rows
    ax.scatter(*fixes[~rejected].T, s=6, color="tab:gray", label=f"accepted fixes ({(~rejected).sum()})")
    ax.scatter(*fixes[rejected].T, s=14, marker="x", color="tab:red", label=f"rejected fixes ({rejected.sum()})")
    for fix, pose in zip(fixes[rejected], result.graph.poses[rows[rejected], :2]):
        ax.plot(*np.stack((fix, pose)).T, color="tab:red", linewidth=0.5)
    for legend in figure.legends:  # one legend, in the axes, with the fixes
        legend.remove()
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"egnc: rejected {len(result.rejected_edges)} loop closures and {rejected.sum()} fixes")
    figure.savefig(output, dpi=80)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
