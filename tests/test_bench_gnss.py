"""The GNSS benchmark's guesses: the file's own, or its odometry chained with seeded drift."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from egnc.datasets import grid_world

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))  # the benchmarks are scripts, imported as test_fuzz imports fuzz

from _lib.robust_gnss import guessed  # noqa: E402
from robust import parser  # noqa: E402


def test_guess_is_the_files_own_or_drifted_and_seeded():
    graph = grid_world(2, 200, seed=1).graph
    assert guessed(graph, "file", 1) is graph
    drifted = guessed(graph, "heading:0.3", 1)
    np.testing.assert_array_equal(drifted.measurements, graph.measurements)
    assert np.max(np.abs(drifted.poses[:, :2] - graph.poses[:, :2])) > 1.0  # metres: the chain drifted
    np.testing.assert_array_equal(guessed(graph, "heading:0.3", 1).poses, drifted.poses)
    with pytest.raises(ValueError, match="unknown drift"):
        guessed(graph, "sideways:1", 1)


def test_gnss_command_takes_the_guess_and_the_reference_time_limit():
    args = parser().parse_args(["gnss", "--guess", "heading:0.3", "--gtsam-time-limit", "60"])
    assert (args.guess, args.gtsam_time_limit) == ("heading:0.3", 60.0)
    default = parser().parse_args(["gnss"])
    assert (default.guess, default.gtsam_time_limit) == ("file", 900.0)
