"""From GTSAM and back: egnc decides the false loop closures, GTSAM's ISAM2 continues on the rest.

Needs the `gtsam` extra (`pip install "egnc[gtsam]"`). Run from anywhere:

    python examples/03_from_gtsam.py
"""

from pathlib import Path

import gtsam
import numpy as np

import egnc
from egnc.interop.gtsam import inlier_factor_mask, to_gtsam_values

DATASET = Path(__file__).resolve().parents[1] / "datasets" / "grid2d_outliers.g2o"


def main() -> None:
    # A GTSAM user's problem: factors and values (here read from a g2o file) and a prior as the gauge.
    graph, initial = gtsam.readG2o(str(DATASET), False)
    graph.add(gtsam.PriorFactorPose2(0, initial.atPose2(0), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))

    bridge = egnc.from_gtsam(graph, initial)  # PoseGraph, GTSAM keys, factor indices
    print(f"from_gtsam: {bridge.graph} in {bridge.seconds:.3f} s; GTSAM error {graph.error(initial):.6g}")
    result = egnc.solve(bridge.graph)
    keep = inlier_factor_mask(result, bridge)  # (F,) bool over graph's factor indices
    print(f"egnc rejected {np.count_nonzero(~keep)} of {graph.size()} factors, the first {np.flatnonzero(~keep)[:8]}")

    # The cleaned graph, solved incrementally by ISAM2 from egnc's estimate.
    clean = gtsam.NonlinearFactorGraph()
    for index in np.flatnonzero(keep):
        clean.add(graph.at(int(index)))
    isam = gtsam.ISAM2()
    isam.update(clean, to_gtsam_values(result, bridge))
    estimate = isam.calculateEstimate()
    print(f"ISAM2 on the kept factors: error {clean.error(estimate):.6g} (egnc's {result.accepted_cost:.6g})")


if __name__ == "__main__":
    main()
