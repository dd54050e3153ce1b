"""Regenerate the pictures in `docs/` that the README shows: `python docs/make_figures.py`.

- `trajectory_grid2d.png`: egnc on `datasets/grid2d_outliers.g2o`: initial guess, result,
  accepted and rejected loop closures (the same figure as `egnc-solve ... --plot`).
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
from egnc.io.atomic import atomic_binary_file
from egnc.plot import plot_kernel, plot_mu_star, plot_trajectory, require_matplotlib

ROOT = Path(__file__).resolve().parents[1]
DPI = 100
PALETTE_COLORS = 128


def write_png(figure, path: Path) -> None:
    """Write `figure` as a palette PNG, atomically."""
    from PIL import Image

    buffer = io.BytesIO()
    # No "Software" stamp: the files change only when the pictures do.
    figure.savefig(buffer, format="png", dpi=DPI, metadata={"Software": None})
    image = Image.open(buffer).convert("RGB").quantize(colors=PALETTE_COLORS)
    with atomic_binary_file(path) as out:
        image.save(out, format="png", optimize=True)
    print(f"{path} ({path.stat().st_size // 1024} KB)")


def main(argv: list[str] | None = None) -> int:
    """Write the three figures into `--out` (default: this folder)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="folder to write into (default: docs/)")
    args = parser.parse_args(argv)
    require_matplotlib()
    args.out.mkdir(parents=True, exist_ok=True)

    dataset = ROOT / "datasets" / "grid2d_outliers.g2o"
    graph = egnc.read_g2o(dataset)
    result = egnc.solve(graph, linear_solver="scipy")  # the same backend everywhere, the same picture
    figure = plot_trajectory(result, initial=graph)
    figure.axes[0].set_title(
        f"{dataset.name}: egnc rejected {len(result.rejected_edges)} of"
        f" {int((~result.known_inliers).sum())} loop closures"
    )
    write_png(figure, args.out / "trajectory_grid2d.png")
    write_png(plot_kernel(), args.out / "kernel.png")
    write_png(plot_mu_star(), args.out / "mu_star.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
