"""Pose-graph file formats."""

from egnc.io.g2o import read_g2o, write_g2o

__all__ = ["read_g2o", "write_g2o"]
