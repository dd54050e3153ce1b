"""Pose-graph file formats: g2o, and riSAM's Incremental Robot Log (IRL).

Also the online solver's checkpoint file (`egnc.io.checkpoint`).
"""

from egnc.io.g2o import read_g2o, write_g2o
from egnc.io.irl import IrlLog, IrlPrior, read_irl, write_irl

__all__ = ["IrlLog", "IrlPrior", "read_g2o", "read_irl", "write_g2o", "write_irl"]
