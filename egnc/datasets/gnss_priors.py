"""GNSS-like position priors for a pose graph: every k-th pose's position, with Gaussian noise.

The positions are taken from reference poses (e.g. the outlier-free optimum, or a ground truth)
and perturbed by isotropic noise of standard deviation `sigma` metres; each prior's information
is `I / sigma^2`, so that a prior's `r^2` is chi-square with `dim` degrees of freedom when the
reference is the truth. Priors are appended after the graph's own (no line: after every edge in
the factor index).
"""

from __future__ import annotations

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
    priors = Priors(
        dim,
        np.concatenate((old.rows, rows)),
        np.concatenate((old.kinds, np.full(len(rows), POSITION, dtype=np.int8))),
        np.concatenate((old.measurements, measurements)),
        np.concatenate((old.information, information)),
        np.concatenate((old.lines, np.zeros(len(rows), dtype=np.int64))),
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
        edge_lines=graph.edge_lines,
        unknown_lines=graph.unknown_lines,
        priors=priors,
    )
