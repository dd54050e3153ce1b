"""Noisy-Manhattan datasets: the EGNC-PGO paper's second experiment (DESIGN.md section 5).

Starting from a ground-truth trajectory and the edges of a pose graph (manhattanOlson3500 with
its outlier-free optimum as ground truth, or a `grid_world`), every measurement is synthesised
from the ground truth:

- odometry (consecutive ids): `Z = (X_i^-1 X_j) Exp(n)`, `n ~ N(0, diag(odometry_sigma^2))`;
- inlier loop closures: the same with `loop_sigma` (zero by default: exact measurements);
- outliers: a seeded share `outlier_fraction` of the loop closures, chosen uniformly without
  replacement, measure `(X_i^-1 X_j) Exp(p)` with `p ~ N(0, diag(outlier_sigma^2))`, and a draw is
  kept only if the loop really is an outlier: its squared whitened error `e^T Omega e`,
  `e = Log(Z^-1 X_i^-1 X_j)`, exceeds `chi2.ppf(0.95, d)` (the EGNC paper's outlier rule, DESIGN.md
  section 4; egnc's own decision uses `GncOptions.outlier_quantile`, 0.99) both at the ground
  truth and at the outlier-free optimum, the least-squares optimum of the noisy graph without the
  outliers. Rejected draws are redrawn. The second test matters: odometry noise moves the optimum
  away from the ground truth, and a draw just above the threshold at the ground truth can fall
  below it at the optimum (6 of 630 on manhattanOlson3500 with seed 1), where even a perfect
  rejection would then be scored as a miss. The outlier-free optimum does not depend on the
  outliers' measurements, so it is solved once, before they are drawn.

How gross the outliers are decides the experiment. With the default test, part of the
outliers sit just above the threshold, and 630 of them (30 % of manhattanOlson3500's loop
closures) can bend its loosely weighted graph (information 44.7, a standard deviation of
0.15 m and 0.15 rad) far enough to take many in: any robust solve then ends with a recall
near 0.9, and success (every outlier found) is rare. The shipped case's outliers all have
squared errors above 90; `outlier_min_r2=90` keeps only such gross outliers.

Every edge keeps its information matrix from the source graph, and its place in the edge order
(the outliers are the source's own loop closures, perturbed, so their position gives nothing
away). The initial guess composes the noisy odometry from the ground-truth first pose.

How this follows the EGNC-PGO repository. Its generator script is not published (riSAM's
`make-gridworld-dataset`, which it inherits, makes identity-measurement outliers instead); its
one shipped case, `manhattan_noisy.irl`, was read instead (`../shared/datasets`). There, the
Manhattan grid trajectory is the ground truth (the exact grid motions behind
manhattanOlson3500's odometry); odometry is that motion plus noise on x and theta only
(standard deviations about 0.061 m and 0.0152 rad, clipped at one standard deviation, so about
a third of the draws sit on the clip value); the loop closures are not manhattanOlson3500's
(733 instead of 2099, 18 % shared) but join revisits of the same cell, the inliers measure the
ground truth exactly, and 30.4 % (223 of 733) are outliers whose
whitened error is large (squared errors 90 to 134, against a threshold of 7.8): a rotation
error of 1.366 rad (78 degrees) each and translation errors of 0.4 to 1.1 m; every edge has
the same isotropic information 44.17. Followed here: ground truth as the source of every
measurement, exact inlier loops by default, noisy odometry, a 30 % share of the loop
closures perturbed in place, outliers far above the threshold. Differences, chosen on purpose:
Gaussian noise on every tangent component without clipping (pass per-component sigmas such as
`(0.061, 0.0, 0.0152)` for x-and-theta-only noise), Gaussian outlier perturbations
(`DEFAULT_OUTLIER_SIGMA`, of the shipped case's order of magnitude) instead of one fixed
rotation offset, and the source's own information matrices.

Reproducibility: one `np.random.default_rng(seed)` stream in a fixed order: the outlier
choice, one `(E, d)` standard-normal block for the measurement noise of every edge, then
`(k, d)` blocks for the outlier perturbations until all k remaining outliers are accepted.
Measurements and initial poses are rounded to `decimals` places, as in `grid_world`, and the
outlier test is made on the rounded measurement. The outlier-free optimum is solved with SciPy's
sparse solver from the ground truth (`egnc.solve(..., "l2", linear_solver="scipy")`), so the
result does not depend on optional extras.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from egnc.api import solve
from egnc.datasets.grid_world import expand_sigmas, rounded
from egnc.errors import EgncError
from egnc.graph import POSE_SIZE, PoseGraph
from egnc.io.irl import IrlLog
from egnc.nonlinear.factors import from_matrices, group_of, to_matrices
from egnc.nonlinear.initialize import initialize_poses
from egnc.robust.kernels import chi2_quantile

__all__ = [
    "ACCEPT_QUANTILE",
    "DEFAULT_ODOMETRY_SIGMA",
    "DEFAULT_OUTLIER_SIGMA",
    "NoisyGraph",
    "make_noisy_manhattan",
    "outlier_count",
]

ACCEPT_QUANTILE = 0.95
"""An outlier draw is kept when its squared whitened error exceeds `chi2.ppf(ACCEPT_QUANTILE, d)`."""

DEFAULT_ODOMETRY_SIGMA = (0.06, 0.015)
"""Odometry noise `(translation m, rotation rad)`: the shipped case's 0.061 m and 0.0152 rad."""

DEFAULT_OUTLIER_SIGMA = (0.5, 1.0)
"""Outlier perturbation `(translation m, rotation rad)`: the shipped case has 0.4-1.1 m and 1.37 rad."""

_MAX_ROUNDS = 1000
"""Give up when some outlier is still rejected after this many redraws."""


@dataclass(frozen=True, eq=False)
class NoisyGraph:
    """A noisy-Manhattan dataset: the graph, its outlier labels and its ground truth.

    Attributes:
        graph: the source's edges and information with synthesised measurements; initial guess =
            the noisy odometry composed from the ground-truth first pose.
        is_outlier: `(E,)` bool, the perturbed loop closures, in `graph`'s edge order.
        ground_truth: `(N, P)` the ground truth every measurement was made from.
        reference: `(N, P)` the outlier-free optimum: the least-squares optimum of `graph`
            without the outliers, what a perfect robust solve returns.
    """

    graph: PoseGraph
    is_outlier: np.ndarray
    ground_truth: np.ndarray
    reference: np.ndarray

    def to_irl(self, name: str = "noisy_manhattan", *, date: str | None = None, notes: str = "") -> IrlLog:
        """The dataset as an IRL log whose LOOP entries carry the labels (`write_irl` writes it)."""
        return IrlLog.from_graph(self.graph, self.is_outlier, name=name, date=date, notes=notes)


def outlier_count(num_loops: int, fraction: float) -> int:
    """Loop closures to perturb: `round(fraction * num_loops)`, halves rounded up."""
    return math.floor(fraction * num_loops + 0.5)


def make_noisy_manhattan(
    graph: PoseGraph,
    ground_truth: np.ndarray,
    *,
    seed: int,
    odometry_sigma: Sequence[float] = DEFAULT_ODOMETRY_SIGMA,
    outlier_fraction: float = 0.3,
    outlier_sigma: Sequence[float] = DEFAULT_OUTLIER_SIGMA,
    loop_sigma: Sequence[float] = (0.0, 0.0),
    outlier_min_r2: float | None = None,
    decimals: int | None = 9,
) -> NoisyGraph:
    """Make a seeded noisy-Manhattan dataset from a graph's edges and a ground truth (module docstring).

    Args:
        graph: the source: its edges (odometry = consecutive ids, the rest loop closures), edge
            order, information matrices and fixed vertices are kept; its measurements and poses
            are not used.
        ground_truth: `(N, P)` true poses in the graph's parametrization, e.g. the least-squares
            optimum of the source or `GridWorld.ground_truth`.
        seed: seed of `np.random.default_rng`; the same seed gives identical arrays.
        odometry_sigma: odometry noise standard deviations, `(translation m, rotation rad)` or
            one per tangent component (`(d,)`, order `[v, omega]`).
        outlier_fraction: share of the loop closures to perturb, in [0, 1].
        outlier_sigma: standard deviations of the outlier perturbations, same forms.
        loop_sigma: noise of the inlier loop closures, same forms; zero keeps them exact.
        outlier_min_r2: squared whitened error an outlier must exceed (at the ground truth and
            at the outlier-free optimum); None means `chi2.ppf(0.95, d)`, the paper's
            classification threshold (egnc decides at 0.99 by default). Larger values keep only
            gross outliers.
        decimals: round measurements and initial poses to this many decimals; None keeps full
            precision.

    Returns:
        The `NoisyGraph`.

    Raises:
        EgncError: invalid arguments, a source without loop closures while outliers are wanted,
            odometry that does not reach every pose, or outlier draws that keep failing the test
            (a perturbation far too small for the information matrices).
    """
    dim, d = graph.dim, graph.tangent_dim
    ground_truth = np.asarray(ground_truth, dtype=np.float64)
    sigma_odometry, sigma_loop, sigma_outlier = _checked_arguments(
        graph, ground_truth, odometry_sigma, loop_sigma, outlier_sigma, outlier_fraction
    )
    is_odometry = graph.is_odometry
    loops = np.flatnonzero(~is_odometry)
    count = outlier_count(len(loops), outlier_fraction)
    if outlier_min_r2 is not None and not (math.isfinite(outlier_min_r2) and outlier_min_r2 >= 0.0):
        raise EgncError(f"make_noisy_manhattan: outlier_min_r2 must be finite and non-negative, got {outlier_min_r2}")
    if count and not np.any(sigma_outlier > 0.0):
        raise EgncError("make_noisy_manhattan: outlier_sigma must have a positive entry to make outliers")

    rng = np.random.default_rng(seed)
    is_outlier = np.zeros(graph.num_edges, dtype=bool)
    is_outlier[np.sort(rng.choice(loops, size=count, replace=False))] = True
    noise = rng.standard_normal((graph.num_edges, d))

    group = group_of(dim)
    T_world = to_matrices(dim, ground_truth)
    T_i_j = group.between(T_world[graph.edges[:, 0]], T_world[graph.edges[:, 1]])
    sigma = np.where(is_odometry[:, None], sigma_odometry, sigma_loop)
    measurements = rounded(from_matrices(dim, group.compose(T_i_j, group.exp(noise * sigma))), decimals)

    reference = _outlier_free_optimum(graph, ground_truth, measurements, ~is_outlier)
    T_reference = to_matrices(dim, reference)
    R_i_j = group.between(T_reference[graph.edges[:, 0]], T_reference[graph.edges[:, 1]])
    threshold = chi2_quantile(ACCEPT_QUANTILE, d) if outlier_min_r2 is None else outlier_min_r2
    outliers = _OutlierDraw(graph, T_i_j, R_i_j, sigma_outlier, threshold, decimals)
    measurements[is_outlier] = outliers.draw(rng, np.flatnonzero(is_outlier))

    ground_truth = ground_truth.copy()
    for array in (is_outlier, ground_truth, reference):
        array.setflags(write=False)
    noisy = _with_odometry_guess(graph, ground_truth, measurements, decimals)
    return NoisyGraph(graph=noisy, is_outlier=is_outlier, ground_truth=ground_truth, reference=reference)


def _checked_arguments(
    graph: PoseGraph,
    ground_truth: np.ndarray,
    odometry_sigma: Sequence[float],
    loop_sigma: Sequence[float],
    outlier_sigma: Sequence[float],
    outlier_fraction: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Refuse a ground truth or a fraction that cannot apply; the three sigmas as `(d,)` arrays."""
    expected = (graph.num_poses, POSE_SIZE[graph.dim])
    if ground_truth.shape != expected:
        raise EgncError(f"make_noisy_manhattan: ground_truth has shape {ground_truth.shape}, expected {expected}")
    if not np.all(np.isfinite(ground_truth)):
        raise EgncError("make_noisy_manhattan: ground_truth contains NaN or infinite values")
    if not 0.0 <= outlier_fraction <= 1.0:
        raise EgncError(f"make_noisy_manhattan: outlier_fraction must lie in [0, 1], got {outlier_fraction}")
    return (
        expand_sigmas(odometry_sigma, graph.dim, "make_noisy_manhattan: odometry_sigma"),
        expand_sigmas(loop_sigma, graph.dim, "make_noisy_manhattan: loop_sigma"),
        expand_sigmas(outlier_sigma, graph.dim, "make_noisy_manhattan: outlier_sigma"),
    )


def _outlier_free_optimum(
    graph: PoseGraph, ground_truth: np.ndarray, measurements: np.ndarray, keep: np.ndarray
) -> np.ndarray:
    """`(N, P)` the least-squares optimum of the `keep` edges `(E,)`, solved from the ground truth.

    The outliers' measurements do not enter it, so it is solved before they are drawn.
    """
    outlier_free = PoseGraph(
        graph.dim,
        graph.vertex_ids,
        ground_truth,
        graph.edges[keep],
        measurements[keep],
        graph.information[keep],
        graph.fixed,
    )
    solved = solve(outlier_free, "l2", linear_solver="scipy")
    if not solved.converged:
        raise EgncError(f"make_noisy_manhattan: the outlier-free least-squares solve failed: {solved.message}")
    return solved.graph.poses


@dataclass(frozen=True, eq=False)
class _OutlierDraw:
    """Draws outlier measurements until each is an outlier at the ground truth and at the optimum.

    Attributes:
        graph: the source graph (edges, information).
        T_i_j: `(E, n, n)` each edge's relative pose at the ground truth.
        R_i_j: `(E, n, n)` the same at the outlier-free optimum.
        sigma: `(d,)` standard deviations of the perturbation.
        threshold: the squared whitened error an outlier must exceed at both.
        decimals: rounding of the measurements (the test is made on the rounded one).
    """

    graph: PoseGraph
    T_i_j: np.ndarray
    R_i_j: np.ndarray
    sigma: np.ndarray
    threshold: float
    decimals: int | None

    def draw(self, rng: np.random.Generator, edges: np.ndarray) -> np.ndarray:
        """`(K, P)` outlier measurements of `edges` `(K,)`, redrawing the rejected ones in rounds."""
        dim, d = self.graph.dim, self.graph.tangent_dim
        group = group_of(dim)
        measurements = np.zeros((len(edges), POSE_SIZE[dim]))
        pending = np.arange(len(edges))
        for _ in range(_MAX_ROUNDS):
            if len(pending) == 0:
                break
            perturbation = rng.standard_normal((len(pending), d)) * self.sigma
            T_pending = self.T_i_j[edges[pending]]
            candidates = rounded(from_matrices(dim, group.compose(T_pending, group.exp(perturbation))), self.decimals)
            Z_inverse = group.inverse(to_matrices(dim, candidates))
            information = self.graph.information[edges[pending]]
            accept = np.ones(len(pending), dtype=bool)
            for T_pairs in (T_pending, self.R_i_j[edges[pending]]):  # at the ground truth, at the optimum
                e = group.log(group.compose(Z_inverse, T_pairs))
                accept &= np.einsum("ki,kij,kj->k", e, information, e) > self.threshold
            measurements[pending[accept]] = candidates[accept]
            pending = pending[~accept]
        if len(pending):
            raise EgncError(
                f"make_noisy_manhattan: {len(pending)} outlier draws still pass as inliers after {_MAX_ROUNDS} "
                f"rounds: outlier_sigma {self.sigma.tolist()} is too small for the information matrices"
            )
        return measurements


def _with_odometry_guess(
    graph: PoseGraph, ground_truth: np.ndarray, measurements: np.ndarray, decimals: int | None
) -> PoseGraph:
    """`graph` with `measurements`, its initial guess the noisy odometry composed from the ground-truth first pose."""
    known = np.zeros(graph.num_poses, dtype=bool)
    known[0] = True
    is_odometry = graph.is_odometry
    poses = initialize_poses(
        graph.dim, graph.edges[is_odometry], measurements[is_odometry], poses=ground_truth, known=known
    )
    return PoseGraph(
        dim=graph.dim,
        vertex_ids=graph.vertex_ids,
        poses=rounded(poses, decimals),
        edges=graph.edges,
        measurements=measurements,
        information=graph.information,
        fixed=graph.fixed,
        edge_lines=graph.edge_lines,
    )
