"""GNSS-like position priors for a pose graph: every k-th pose's position, with Gaussian noise.

The positions are taken from reference poses (e.g. the outlier-free optimum, or a ground truth)
and perturbed by isotropic noise of standard deviation `sigma` metres; each prior's information
is `I / sigma^2`, so that a prior's `r^2` is chi-square with `dim` degrees of freedom when the
reference is the truth. Priors are appended after the graph's own and after every edge in the
factor index (`_factor_lines`: a written file keeps the edges in graph order, then the fixes).

`add_multipath_outliers` then moves some fixes by jumps of tens of metres, singly or in bursts of
consecutive fixes (a street canyon's multipath), and labels them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from egnc.errors import OptionError
from egnc.graph import PoseGraph
from egnc.graph.checks import check_float, check_int
from egnc.graph.priors import POSITION, Priors


def add_position_priors(
    graph: PoseGraph,
    reference_poses: np.ndarray,
    every: int = 10,
    sigma: float = 0.5,
    seed: int = 0,
) -> PoseGraph:
    """A copy of `graph` with a position prior on every `every`-th pose row (rows 0, every, 2 every, ...).

    Args:
        graph: the graph; its own priors are kept, first.
        reference_poses: `(N, P)` poses the measured positions are drawn around, metres.
        every: prior spacing in pose rows, at least 1.
        sigma: noise standard deviation per coordinate, metres, positive.
        seed: the random generator's seed.

    Raises:
        OptionError: an argument out of range, or `reference_poses` of the wrong shape.
    """
    every = check_int("every", every, 1)
    sigma = check_float("sigma", sigma, 0.0, open_low=True)
    reference = np.asarray(reference_poses, dtype=np.float64)
    if reference.shape != graph.poses.shape:
        raise OptionError(f"reference_poses must have shape {graph.poses.shape}, got {reference.shape}")
    rng = np.random.default_rng(seed)
    rows = np.arange(0, graph.num_poses, every)
    dim, old = graph.dim, graph.priors
    measurements = np.zeros((len(rows), graph.poses.shape[1]))
    measurements[:, :dim] = reference[rows, :dim] + rng.normal(scale=sigma, size=(len(rows), dim))
    information = np.zeros((len(rows), graph.tangent_dim, graph.tangent_dim))
    information[:, np.arange(dim), np.arange(dim)] = 1.0 / sigma**2
    edge_lines, prior_lines = _factor_lines(graph, len(rows))
    priors = Priors(
        dim,
        np.concatenate((old.rows, rows)),
        np.concatenate((old.kinds, np.full(len(rows), POSITION, dtype=np.int8))),
        np.concatenate((old.measurements, measurements)),
        np.concatenate((old.information, information)),
        np.concatenate((old.lines, prior_lines)),
        np.concatenate((old.param_ids, np.zeros(len(rows), dtype=np.int64))),
    )
    return PoseGraph(
        dim,
        graph.vertex_ids,
        graph.poses,
        graph.edges,
        graph.measurements,
        graph.information,
        fixed=graph.fixed,
        edge_lines=edge_lines,
        unknown_lines=graph.unknown_lines,
        priors=priors,
    )


def _factor_lines(graph: PoseGraph, count: int) -> tuple[np.ndarray, np.ndarray]:
    """`(E,)` edge lines and `(count,)` lines of new priors that put the priors after every factor
    and keep the edges in graph order (the factor index, `PoseGraph.edge_factor_index`, and so a
    written file). A graph whose edges are not numbered in row order (a generator's edges
    without a line among read ones, `egnc.datasets.add_false_loops`) and holds no prior yet is
    numbered afresh, 1 to E: its file's edge order is then its graph order, as its labels expect."""
    lines = graph.edge_lines
    in_order = len(lines) and lines[0] > 0 and np.all(np.diff(lines) > 0)
    if not in_order and not graph.num_priors:
        lines = np.arange(1, graph.num_edges + 1, dtype=np.int64)
    last = max(int(lines.max(initial=0)), int(graph.priors.lines.max(initial=0)))
    return lines, last + 1 + np.arange(count, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class PriorOutliers:
    """A graph whose position priors were corrupted by multipath jumps, and the labels.

    Attributes:
        graph: the graph, priors in the input's order, some of them moved.
        is_outlier: `(K,)` bool, true for the moved priors.
    """

    graph: PoseGraph
    is_outlier: np.ndarray


def add_multipath_outliers(
    graph: PoseGraph,
    percent: float,
    seed: int = 0,
    *,
    bursts: bool = False,
    jump: tuple[float, float] = (10.0, 50.0),
    burst_size: tuple[int, int] = (5, 20),
    reference_poses: np.ndarray | None = None,
) -> PriorOutliers:
    """Move `percent` % of the graph's position priors by multipath jumps, and label them.

    A jump is a horizontal offset (the x-y plane; in 3D the height is kept) of length uniform in
    `jump` metres and uniform direction. Single jumps (`bursts=False`) hit fixes drawn at
    random. Bursts hit runs of consecutive position priors, as a street canyon does: each burst
    is `burst_size` fixes long (uniform, both ends included) and shares one offset, so its fixes
    agree with each other and only the rest of the map refutes them. Bursts are placed at random
    without overlap until the wanted count is reached (the last may be cut short).

    Args:
        graph: a graph with position priors (`add_position_priors`).
        percent: share of the position priors to move, in [0, 100).
        seed: the random generator's seed.
        bursts: consecutive fixes in bursts instead of single jumps.
        jump: smallest and largest jump, metres.
        burst_size: smallest and largest burst, fixes.
        reference_poses: `(N, P)` the poses the fixes were drawn around (`add_position_priors`);
            given, a moved fix is its pose's reference position plus the jump, so that it is
            off by the jump itself (a jump added to the fix's own noise can cancel part of it:
            an 11 m jump landed 6 m from the truth, within the noise of a 2 m fix). None adds
            the jump to the fix as measured.

    Raises:
        OptionError: an argument out of range, or a graph without position priors.
    """
    percent = check_float("percent", percent, 0.0, 100.0, open_high=True)
    low, high = (check_float("jump", value, 0.0) for value in jump)
    shortest, longest = (check_int("burst_size", value, 1) for value in burst_size)
    if high < low or longest < shortest:
        raise OptionError(f"jump and burst_size must be (smallest, largest), got {jump} and {burst_size}")
    positions = np.flatnonzero(graph.priors.kinds == POSITION)
    if not len(positions):
        raise OptionError("add_multipath_outliers: the graph has no position prior")
    rng = np.random.default_rng(seed)
    wanted = int(round(percent * len(positions) / 100.0))
    moved = np.zeros(len(positions), dtype=bool)
    offsets = np.zeros((len(positions), graph.dim))
    if bursts:
        attempts = 0
        while moved.sum() < wanted and attempts < 100 * len(positions):
            attempts += 1
            size = min(int(rng.integers(shortest, longest + 1)), wanted - int(moved.sum()))
            first = int(rng.integers(0, len(positions) - size + 1))
            run = slice(first, first + size)
            if moved[max(first - 1, 0) : first + size + 1].any():  # bursts stay apart
                continue
            moved[run] = True
            offsets[run] = _jumps(rng, 1, graph.dim, low, high)
    else:
        chosen = rng.choice(len(positions), size=wanted, replace=False)
        moved[chosen] = True
        offsets[chosen] = _jumps(rng, wanted, graph.dim, low, high)
    measurements = graph.priors.measurements.copy()
    if reference_poses is not None:
        reference = np.asarray(reference_poses, dtype=np.float64)
        if reference.shape != graph.poses.shape:
            raise OptionError(f"reference_poses must have shape {graph.poses.shape}, got {reference.shape}")
        origin = reference[graph.priors.rows[positions], : graph.dim]
        measurements[positions[moved], : graph.dim] = origin[moved]
    measurements[positions, : graph.dim] += offsets
    is_outlier = np.zeros(graph.num_priors, dtype=bool)
    is_outlier[positions] = moved
    priors = replace(graph.priors, measurements=measurements)
    return PriorOutliers(replace(graph, priors=priors), is_outlier)


def _jumps(rng: np.random.Generator, count: int, dim: int, low: float, high: float) -> np.ndarray:
    """`(count, dim)` horizontal offsets of length uniform in `[low, high]` metres."""
    angle = rng.uniform(0.0, 2.0 * np.pi, size=count)
    length = rng.uniform(low, high, size=count)
    offsets = np.zeros((count, dim))
    offsets[:, 0], offsets[:, 1] = length * np.cos(angle), length * np.sin(angle)
    return offsets
