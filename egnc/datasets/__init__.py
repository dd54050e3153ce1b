"""Synthetic benchmark data: grid-world pose graphs, false loop closures and their label files."""

from egnc.datasets.false_loops import VARIANTS, CorruptedGraph, add_false_loops, false_loop_count
from egnc.datasets.grid_world import GridWorld, grid_world
from egnc.datasets.labels import read_labels, write_labels

__all__ = [
    "VARIANTS",
    "CorruptedGraph",
    "GridWorld",
    "add_false_loops",
    "false_loop_count",
    "grid_world",
    "read_labels",
    "write_labels",
]
