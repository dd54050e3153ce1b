"""Regenerate the pictures in `docs/` that the README and docs/overview.md show: `python docs/make_figures.py`.

- `trajectory_grid2d.png`: egnc on `datasets/grid2d_outliers.g2o`: initial guess, result,
  accepted and rejected loop closures (the same figure as `egnc-solve ... --plot`).
- `trajectory_grid3d.png`: the same for the 3D grid, `datasets/grid3d_outliers.g2o`.
- `trajectory_intel30.png`: the Intel lab dataset with 30 % false loop closures added in memory
  (`egnc.datasets.add_false_loops`, seed 1, against the least-squares optimum of the clean file),
  solved with the default `egnc.solve`. It needs `../shared/datasets/intel.g2o` beside the
  checkout (or `--data-dir`); without it this figure is skipped with a message.
- `kernel.png`: the SIG kernel `rho(r; mu)` and `d2rho/dr2` for mu = 0, 0.25, 0.5, 0.75, 1.
- `mu_star.png`: the convexity boundary `mu*(r)` and its asymptote 1/2.

Needs `pip install -e ".[plot]"`. The PNGs are reduced to a 128-colour palette (Pillow, which
matplotlib depends on), which keeps line art identical to the eye at a third of the size.
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import egnc
from egnc.datasets import add_false_loops, read_labels
from egnc.io.atomic import atomic_binary_file
from egnc.plot import plot_kernel, plot_mu_star, plot_trajectory, require_matplotlib

ROOT = Path(__file__).resolve().parents[1]
DPI = 120
PALETTE_COLORS = 128
LINEAR_SOLVER = "scipy"
"""The same backend everywhere, the same picture."""


def write_png(figure, path: Path) -> None:
    """Write `figure` as a palette PNG, atomically."""
    from PIL import Image

    buffer = io.BytesIO()
    # No "Software" stamp: the files change only when the pictures do.
    figure.savefig(buffer, format="png", dpi=DPI, metadata={"Software": None})
    # Octree keeps the rare colours (a legend key, a few green lines) that median cut would merge.
    image = (
        Image.open(buffer)
        .convert("RGB")
        .quantize(colors=PALETTE_COLORS, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    )
    with atomic_binary_file(path) as out:
        image.save(out, format="png", optimize=True)
    print(f"{path} ({path.stat().st_size // 1024} KB)")


def trajectory_figure(result: egnc.Result, initial: egnc.PoseGraph, title: str):
    """`plot_trajectory` of a solve, titled, with the count of false loops it rejected."""
    figure = plot_trajectory(result, initial=initial)
    figure.axes[0].set_title(title, fontsize="medium")
    return figure


def shipped_figure(name: str):
    """egnc on a shipped grid with 30 % false loops; the title checks the rejections against the labels."""
    dataset = ROOT / "datasets" / f"{name}_outliers.g2o"
    graph = egnc.read_g2o(dataset)
    is_outlier, _ = read_labels(dataset.with_suffix(".labels.json"))
    result = egnc.solve(graph, linear_solver=LINEAR_SOLVER)
    caught = int((is_outlier & ~result.inliers).sum())
    title = (
        f"{dataset.name}: egnc rejected {len(result.rejected_edges)} of {int((~result.known_inliers).sum())}"
        f" loop closures,\n{caught} of the {int(is_outlier.sum())} false ones"
    )
    return trajectory_figure(result, graph, title)


def intel_figure(path: Path, percent: float = 30.0, seed: int = 1):
    """egnc on the Intel dataset with `percent` % false loop closures added in memory."""
    clean = egnc.read_g2o(path)
    reference = egnc.solve(clean, "l2", linear_solver=LINEAR_SOLVER).graph.poses
    corrupted = add_false_loops(clean, percent, seed=seed, reference_poses=reference)
    result = egnc.solve(corrupted.graph, linear_solver=LINEAR_SOLVER)
    is_outlier = corrupted.is_outlier
    caught = int((is_outlier & ~result.inliers).sum())
    title = (
        f"intel.g2o + {percent:g} % false loops (seed {seed}): egnc rejected {len(result.rejected_edges)}"
        f" of {int((~result.known_inliers).sum())},\n{caught} of the {int(is_outlier.sum())} false ones"
    )
    return trajectory_figure(result, corrupted.graph, title)


def main(argv: list[str] | None = None) -> int:
    """Write the figures into `--out` (default: this folder)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="folder to write into (default: docs/)")
    parser.add_argument(
        "--data-dir",
        type=Path,
        default=ROOT.parent / "shared" / "datasets",
        help="where intel.g2o is (default: ../shared/datasets beside the checkout)",
    )
    args = parser.parse_args(argv)
    require_matplotlib()
    args.out.mkdir(parents=True, exist_ok=True)

    write_png(shipped_figure("grid2d"), args.out / "trajectory_grid2d.png")
    write_png(shipped_figure("grid3d"), args.out / "trajectory_grid3d.png")
    intel = args.data_dir / "intel.g2o"
    if intel.is_file():
        write_png(intel_figure(intel), args.out / "trajectory_intel30.png")
    else:
        print(f"skipping trajectory_intel30.png: {intel} is not there", file=sys.stderr)
    write_png(plot_kernel(), args.out / "kernel.png")
    write_png(plot_mu_star(), args.out / "mu_star.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
