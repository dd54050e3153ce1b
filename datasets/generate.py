"""Regenerate the synthetic datasets shipped in this folder, deterministically.

Usage (from the repository root):

    python datasets/generate.py              # rewrite the files in datasets/
    python datasets/generate.py --out DIR    # write them into DIR instead

Each outlier file uses the l2 optimum of its clean graph (`egnc.solve`, SciPy linear backend so
that the result does not depend on optional extras) as the outlier-free reference.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from egnc.api import solve
from egnc.datasets import add_false_loops, grid_world, write_labels
from egnc.io import write_g2o


@dataclass(frozen=True)
class Spec:
    """One shipped grid world and its corrupted copy."""

    name: str
    dim: int
    num_poses: int
    seed: int
    outlier_percent: float
    outlier_seed: int


NOISE_SCALE = 0.3
"""Noise drawn at 0.3 sigma while the information says sigma: conservative noise models like those
of the public benchmarks (see `grid_world`'s `noise_scale`)."""

SPECS = (
    Spec("grid2d", dim=2, num_poses=500, seed=1, outlier_percent=30, outlier_seed=2),
    Spec("grid3d", dim=3, num_poses=300, seed=3, outlier_percent=30, outlier_seed=4),
)


def generate(out: Path) -> list[Path]:
    """Write every file of `SPECS` into `out` and return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for spec in SPECS:
        world = grid_world(spec.dim, spec.num_poses, seed=spec.seed, noise_scale=NOISE_SCALE)
        clean_path = out / f"{spec.name}.g2o"
        write_g2o(world.graph, clean_path)
        reference = solve(world.graph, "l2", linear_solver="scipy")
        corrupted = add_false_loops(
            world.graph, spec.outlier_percent, seed=spec.outlier_seed, reference_poses=reference.graph.poses
        )
        outlier_path = out / f"{spec.name}_outliers.g2o"
        labels_path = out / f"{spec.name}_outliers.labels.json"
        write_g2o(corrupted.graph, outlier_path)
        write_labels(
            labels_path,
            corrupted.is_outlier,
            {
                "graph": outlier_path.name,
                "clean_graph": clean_path.name,
                "generator": "egnc.datasets.add_false_loops",
                "percent": spec.outlier_percent,
                "variant": "random",
                "seed": spec.outlier_seed,
                "reference": f"l2 optimum of {clean_path.name} (egnc.solve, linear_solver='scipy')",
                "grid_world": {"dim": spec.dim, "num_poses": spec.num_poses, "seed": spec.seed},
            },
        )
        written += [clean_path, outlier_path, labels_path]
    return written


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, generate the files and list them."""
    parser = argparse.ArgumentParser(description="Regenerate egnc's shipped synthetic datasets.")
    here = Path(__file__).resolve().parent
    parser.add_argument("--out", type=Path, default=here, help="output directory (default: this folder)")
    args = parser.parse_args(argv)
    for path in generate(args.out):
        print(f"{path}  {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
