"""Synthetic benchmark data: grid-world pose graphs, false loop closures, noisy-Manhattan datasets and label files."""

from egnc.datasets.false_loops import (
    OUTLIER_RULES,
    VARIANTS,
    CorruptedGraph,
    add_false_loops,
    false_loop_count,
)
from egnc.datasets.gnss_priors import PriorOutliers, add_multipath_outliers, add_position_priors
from egnc.datasets.grid_world import GridWorld, grid_world
from egnc.datasets.noisy_manhattan import NoisyGraph, make_noisy_manhattan
from egnc.io.labels import read_labels, read_prior_labels, write_labels

__all__ = [
    "OUTLIER_RULES",
    "VARIANTS",
    "CorruptedGraph",
    "GridWorld",
    "NoisyGraph",
    "PriorOutliers",
    "add_false_loops",
    "add_multipath_outliers",
    "add_position_priors",
    "false_loop_count",
    "grid_world",
    "make_noisy_manhattan",
    "read_labels",
    "read_prior_labels",
    "write_labels",
]
