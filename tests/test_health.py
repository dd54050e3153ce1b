"""Numerically meaningless problems: refused before the solve, or stopped with status 5."""

from __future__ import annotations

import numpy as np
import pytest

import egnc
from egnc.datasets import grid_world
from egnc.graph.health import check_representable
from egnc.nonlinear.factors import to_matrices
from egnc.nonlinear.least_squares import NUMERICAL_FAILURE, STATUS_MESSAGES, Problem, solve_least_squares


@pytest.fixture(scope="module")
def graph():
    return grid_world(2, 200, seed=4).graph


@pytest.mark.parametrize("x", [1e20, 1e300])
def test_a_pose_too_far_out_for_doubles_is_refused_in_one_line(graph, x, capfd):
    poses = graph.poses.copy()
    poses[100, 0] = x  # neighbouring doubles are 16 km apart at 1e20: no 1 cm step survives
    with pytest.raises(egnc.NumericalError, match="cannot be represented in double precision") as error:
        egnc.solve(graph.with_poses(poses))
    assert "\n" not in str(error.value)
    assert capfd.readouterr().out == ""  # nothing reached BLAS to complain on stdout


def test_ordinary_and_large_but_representable_graphs_pass(graph):
    check_representable(graph)
    far = graph.poses.copy()
    far[:, :2] += 1e6  # a UTM-like offset: spacing 1e-10 m, far below the noise
    check_representable(graph.with_poses(far))


def test_non_finite_numbers_stop_the_solver_with_status_5(graph):
    poses = to_matrices(2, graph.poses)
    poses[7, 0, 2] = np.nan
    result = solve_least_squares(Problem.from_graph(graph, "scipy"), poses)
    assert result.status == NUMERICAL_FAILURE and not result.converged
    assert result.message == STATUS_MESSAGES[NUMERICAL_FAILURE]
