"""Groups of loops between two otherwise separate parts (`egnc.robust.parts`, the `"parts"` start)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import egnc
from egnc.datasets import grid_world
from egnc.datasets.two_robots import GROUP_FALSE, RANDOM_FALSE, SYMBOL_B, TRUE_LOOP, robots, symbol_id, two_robots
from egnc.errors import EgncError
from egnc.nonlinear.factors import to_matrices
from egnc.robust.gnc import GncOptions
from egnc.robust.parts import part_groups


@pytest.fixture(scope="module")
def world():
    world = grid_world(2, 600, seed=5)
    return world.graph, egnc.solve(world.graph, "l2").graph.poses


def _solve(graph, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", egnc.EgncWarning)
        return egnc.solve(graph, gnc_options=GncOptions(**options) if options else None)


def test_two_robots_keep_their_own_edges_and_b_starts_in_its_own_frame(world):
    graph, reference = world
    robots = two_robots(graph, reference, true_loops=30, false_percent=20, false_group=12, seed=2)
    assert np.count_nonzero(robots.kinds == TRUE_LOOP) == 30 and np.count_nonzero(robots.kinds == GROUP_FALSE) == 12
    b0 = np.searchsorted(robots.graph.vertex_ids, symbol_id(SYMBOL_B, 0))
    assert np.allclose(robots.graph.poses[b0], 0.0)
    assert not robots.graph.is_odometry[robots.is_inter_robot].any()


def test_three_robots_each_start_in_their_own_frame_and_are_joined_pair_by_pair(world):
    graph, reference = world
    cut = robots(graph, reference, splits=(200, 400), false_percent=30, seed=3)
    assert np.array_equal(np.bincount(cut.robot), [200, 200, 200])
    assert np.array_equal(cut.graph.vertex_ids, np.concatenate([symbol_id(c, np.arange(200)) for c in "abc"]))
    assert np.allclose(cut.graph.poses[[200, 400]], 0.0)  # b0 and c0 at the identity
    pairs = {tuple(sorted(pair)) for pair in cut.robot[cut.graph.edges[cut.kinds == TRUE_LOOP]].tolist()}
    assert pairs == {(0, 1), (0, 2), (1, 2)}
    assert (cut.robot[cut.graph.edges[cut.kinds == RANDOM_FALSE, 0]] == 0).all()  # random false loops start at a
    own = cut.graph.edges[cut.kinds == 0]
    assert (cut.robot[own[:, 0]] == cut.robot[own[:, 1]]).all()  # the other edges stay within a robot
    result = _solve(cut.graph)
    assert result.inliers[cut.kinds == TRUE_LOOP].all() and not result.inliers[cut.is_false].any()
    with pytest.raises(EgncError, match="splits must increase"):
        robots(graph, reference, splits=(400, 200))


def test_a_consistent_false_group_smaller_than_the_true_loops_is_rejected_whole_with_a_warning(world):
    graph, reference = world
    robots = two_robots(graph, reference, true_loops=30, false_group=12, seed=2)
    result = _solve(robots.graph)
    assert result.inliers[robots.kinds == TRUE_LOOP].all()
    assert not result.inliers[robots.kinds == GROUP_FALSE].any()
    (warning,) = [text for text in result.warnings if "groups that disagree" in text]
    assert "between robot a (a0 to a299) and robot b (b0 to b299)" in warning  # the ids are GTSAM Symbols


def test_the_groups_are_the_true_loops_and_the_false_group(world):
    graph, reference = world
    robots = two_robots(graph, reference, true_loops=30, false_group=12, seed=2)
    inliers = robots.kinds != GROUP_FALSE
    found = part_groups(robots.graph, robots.graph.is_loop_closure, inliers, to_matrices(2, reference), 0.99)
    assert found is not None and found.count == 2
    assert set(found.members(0)) == set(np.flatnonzero(robots.kinds == TRUE_LOOP))
    assert set(found.members(1)) == set(np.flatnonzero(robots.kinds == GROUP_FALSE))


def test_a_connected_graph_has_no_parts_and_no_parts_start(world):
    graph, _ = world
    assert (
        part_groups(graph, graph.is_loop_closure, np.ones(graph.num_edges, bool), to_matrices(2, graph.poses), 0.99)
        is None
    )
    with_parts, without = _solve(graph), _solve(graph, starts=GncOptions().starts[:-1])
    assert np.array_equal(with_parts.inliers, without.inliers) and with_parts.start == without.start
