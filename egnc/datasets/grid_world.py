"""Synthetic grid-world pose graphs with known ground truth (Manhattan/City10000-style).

A robot walks on an integer grid of `size` x `size` cells (and `levels` floors in 3D), one cell
of `step` metres per pose. At each step it keeps its heading or turns 90 degrees left or right
(probability `turn_probability` of turning, split evenly), choosing only among moves that stay
inside the square, so the walk stays bounded and keeps revisiting cells. In 3D it sometimes
(`climb_probability`) moves one level up or down instead, keeping its heading and climbing in one
direction until it reaches the top or bottom floor, like a robot using a spiral staircase.
Headings are multiples of 90 degrees about z, so ground-truth rotations are exact.

Edges, in the order they are written (time order, as in Manhattan3500):
- odometry `(k - 1, k)` for every step k;
- a loop closure `(j, k)` right after it whenever pose k revisits a cell, with probability
  `loop_probability`, where j is the most recent earlier visit of that cell (never k - 1).

Every measurement is the true relative pose perturbed on the right by Gaussian tangent noise,
`Z = (X_i^-1 X_j) Exp(n)` with `n ~ N(0, diag(sigma^2))` (tangent order `[v, omega]`), and its
information matrix is `diag(1 / sigma^2)` (a zero sigma is an exact measurement whose
information is capped at 1e12). The initial guess chains the noisy odometry from the
true first pose, which sits at the origin.

Reproducibility: every random number comes from one `np.random.default_rng(seed)` stream (PCG64,
whose bits and Gaussian samples are the same on every platform) in a fixed order: first one
`(num_poses, 3)` uniform block for the walk, then one `(E, d)` standard-normal block for the
noise. The transcendental functions used to apply the noise may differ across platforms' math
libraries in the last ulp; measurements, information and initial poses are therefore rounded to
`decimals` decimal places, which absorbs such differences (and keeps g2o files short).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from egnc.errors import EgncError
from egnc.graph import TANGENT_SIZE, PoseGraph
from egnc.nonlinear.factors import from_matrices, group_of, to_matrices

_MIN_SIGMA = 1e-6
"""A zero sigma makes the measurement exact; its information is capped at `1 / _MIN_SIGMA^2`."""

# Heading h in 0..3 means yaw h * 90 degrees; unit steps and exact rotations per heading.
_STEP_X = (1, 0, -1, 0)
_STEP_Y = (0, 1, 0, -1)
_YAW = np.array([0.0, 0.5 * math.pi, math.pi, -0.5 * math.pi])
_HALF = math.sqrt(0.5)  # IEEE sqrt is correctly rounded, so this is the same everywhere
_QUAT_Z = np.array([0.0, _HALF, 1.0, -_HALF])  # sin(yaw / 2)
_QUAT_W = np.array([1.0, _HALF, 0.0, _HALF])  # cos(yaw / 2)


@dataclass(frozen=True, eq=False)
class GridWorld:
    """A generated grid-world dataset.

    Attributes:
        graph: the pose graph: noisy measurements, initial guess = chained noisy odometry.
        ground_truth: `(N, P)` true poses in the graph's parametrization (`(x, y, theta)` in 2D,
            `(x, y, z, qx, qy, qz, qw)` in 3D), metres and radians.
    """

    graph: PoseGraph
    ground_truth: np.ndarray


def grid_world(
    dim: int,
    num_poses: int,
    *,
    seed: int,
    step: float = 1.0,
    odometry_sigma: Sequence[float] = (0.05, 0.01),
    loop_sigma: Sequence[float] = (0.1, 0.02),
    loop_probability: float = 1.0,
    turn_probability: float = 0.4,
    climb_probability: float = 0.2,
    size: int | None = None,
    levels: int | None = None,
    decimals: int | None = 9,
    noise_scale: float = 1.0,
) -> GridWorld:
    """Generate a seeded grid-world pose graph and its ground truth.

    Args:
        dim: 2 (SE(2)) or 3 (SE(3)).
        num_poses: number of poses N >= 2.
        seed: seed of `np.random.default_rng`; the same seed gives identical arrays.
        step: grid spacing in metres (also the height of a level in 3D).
        odometry_sigma: noise standard deviations of odometry edges: either
            `(translation m, rotation rad)`, or one value per tangent component (`(d,)`, order
            `[v, omega]`). Zero gives exact measurements.
        loop_sigma: the same for loop closures.
        loop_probability: probability that a revisit of a cell adds a loop closure.
        turn_probability: probability of turning left or right (half each) at a step, before
            moves that would leave the square are excluded.
        climb_probability: 3D only: probability that a step changes level instead.
        size: cells per side of the square; default `round(sqrt(N / levels))` (at least 2), so
            that there are about as many cells as poses.
        levels: 3D only: number of floors; default `max(2, round(cbrt(N) / 2))`.
        decimals: round measurements, information and initial poses to this many decimals (see
            the module docstring); None keeps full precision.
        noise_scale: the noise actually drawn is `noise_scale * sigma` while the information stays
            `1 / sigma^2`. Public benchmarks have conservative noise models (at their optimum,
            loop closures have mean `r^2` of 0.03 to 0.3 instead of d), which a value below 1
            reproduces; 1 makes the model exact.

    Returns:
        The `GridWorld` with the graph and `(N, P)` ground truth.

    Raises:
        EgncError: an argument is out of range.
    """
    _check_ranges(dim, num_poses, step, noise_scale, loop_probability, turn_probability, climb_probability)
    d = TANGENT_SIZE[dim]
    sigma_odometry = expand_sigmas(odometry_sigma, dim, "grid_world: odometry_sigma")
    sigma_loop = expand_sigmas(loop_sigma, dim, "grid_world: loop_sigma")
    size, levels = _extent(dim, num_poses, size, levels)

    rng = np.random.default_rng(seed)
    walk_draws = rng.random((num_poses, 3))
    cells, headings, edges, is_loop = _walk(
        walk_draws, size, levels, loop_probability, turn_probability, climb_probability if dim == 3 else 0.0
    )
    noise = rng.standard_normal((len(edges), d))

    ground_truth = _ground_truth(dim, (cells - cells[0]) * float(step), headings)
    sigma = np.where(is_loop[:, None], sigma_loop, sigma_odometry)
    graph = _measured_graph(dim, ground_truth, edges, is_loop, noise * (noise_scale * sigma), sigma, decimals)
    ground_truth.setflags(write=False)
    return GridWorld(graph=graph, ground_truth=ground_truth)


def _check_ranges(
    dim: int,
    num_poses: int,
    step: float,
    noise_scale: float,
    loop_probability: float,
    turn_probability: float,
    climb_probability: float,
) -> None:
    """Refuse a dimension, size, step, noise scale or probability out of range (`EgncError`)."""
    if dim not in (2, 3):
        raise EgncError(f"grid_world: dim must be 2 or 3, got {dim}")
    if num_poses < 2:
        raise EgncError(f"grid_world: num_poses must be at least 2, got {num_poses}")
    if not step > 0.0:
        raise EgncError(f"grid_world: step must be positive, got {step}")
    if not noise_scale >= 0.0:
        raise EgncError(f"grid_world: noise_scale must be non-negative, got {noise_scale}")
    for name, value in (
        ("loop_probability", loop_probability),
        ("turn_probability", turn_probability),
        ("climb_probability", climb_probability),
    ):
        if not 0.0 <= value <= 1.0:
            raise EgncError(f"grid_world: {name} must lie in [0, 1], got {value}")


def _extent(dim: int, num_poses: int, size: int | None, levels: int | None) -> tuple[int, int]:
    """`(size, levels)`: the grid's cells per side and floors, the defaults of `grid_world` where None."""
    if dim == 2:
        levels = 1
    elif levels is None:
        levels = max(2, round(num_poses ** (1.0 / 3.0) / 2.0))
    elif levels < 2:
        raise EgncError(f"grid_world: levels must be at least 2 in 3D, got {levels}")
    if size is None:
        size = max(2, round(math.sqrt(num_poses / levels)))
    elif size < 2:
        raise EgncError(f"grid_world: size must be at least 2, got {size}")
    return size, levels


def _measured_graph(
    dim: int,
    ground_truth: np.ndarray,
    edges: np.ndarray,
    is_loop: np.ndarray,
    noise: np.ndarray,
    sigma: np.ndarray,
    decimals: int | None,
) -> PoseGraph:
    """The graph of the walk: each edge's true relative pose times `Exp(noise)`, information
    `diag(1 / sigma^2)`, and the noisy odometry chained from the first true pose as initial guess.

    Args:
        dim: 2 or 3.
        ground_truth: `(N, P)` the true poses.
        edges: `(E, 2)` the walk's edges; odometry `(k - 1, k)` for k = 1..N-1, in this order among them.
        is_loop: `(E,)` bool, the loop closures.
        noise: `(E, d)` the tangent noise drawn for each edge.
        sigma: `(E, d)` the standard deviations the information says.
        decimals: rounding of measurements, information and initial poses (None: none).
    """
    d = TANGENT_SIZE[dim]
    group = group_of(dim)
    T_world = to_matrices(dim, ground_truth)
    T_i_j = group.between(T_world[edges[:, 0]], T_world[edges[:, 1]])
    measurements = rounded(from_matrices(dim, group.compose(T_i_j, group.exp(noise))), decimals)
    Z_odometry = to_matrices(dim, measurements[~is_loop])
    T_chain = _prefix_products(np.concatenate((T_world[:1], Z_odometry)))
    information = np.zeros((len(edges), d, d))
    # Rounded too: 1 / 0.05^2 is 399.99999999999994 in floating point, and files should say 400.
    information[:, np.arange(d), np.arange(d)] = rounded(1.0 / np.maximum(sigma, _MIN_SIGMA) ** 2, decimals)
    return PoseGraph(
        dim=dim,
        vertex_ids=np.arange(len(ground_truth), dtype=np.int64),
        poses=rounded(from_matrices(dim, T_chain), decimals),
        edges=edges,
        measurements=measurements,
        information=information,
    )


def expand_sigmas(value: Sequence[float], dim: int, name: str) -> np.ndarray:
    """Expand `(translation, rotation)` or `(d,)` standard deviations to `(d,)` (metres, radians).

    Args:
        value: two values, or one per tangent component (order `[v, omega]`).
        dim: 2 or 3.
        name: what the caller calls it, for the error message (e.g. `"grid_world: loop_sigma"`).

    Raises:
        EgncError: wrong length, or a negative or non-finite entry.
    """
    d = TANGENT_SIZE[dim]
    sigma = np.asarray(value, dtype=np.float64)
    if sigma.shape == (2,):
        sigma = np.concatenate((np.full(dim, sigma[0]), np.full(d - dim, sigma[1])))
    if sigma.shape != (d,):
        raise EgncError(f"{name} must have 2 or {d} entries, got shape {sigma.shape}")
    if not np.all(np.isfinite(sigma) & (sigma >= 0.0)):
        raise EgncError(f"{name} must be finite and non-negative, got {sigma.tolist()}")
    return sigma


def _walk(
    draws: np.ndarray,
    size: int,
    levels: int,
    loop_probability: float,
    turn_probability: float,
    climb_probability: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Walk the grid and collect the edges.

    The walk is inherently sequential (each move depends on the position), so it is one Python loop
    on plain ints; it takes a few milliseconds per thousand poses.

    Args:
        draws: `(N, 3)` uniforms in [0, 1); row k drives step k (row 0 is unused): column 0 picks
            the move, 1 decides climbing, 2 decides whether a revisit adds a loop closure.
        size, levels: grid extent in cells.
        loop_probability, turn_probability, climb_probability: as in `grid_world`.

    Returns:
        `(cells, headings, edges, is_loop)`: `(N, 3)` int64 cells (x, y, level), `(N,)` int64
        headings in 0..3, `(E, 2)` int64 edges and `(E,)` bool loop-closure flags.
    """
    weights = (1.0 - turn_probability, 0.5 * turn_probability, 0.5 * turn_probability)
    x = y = size // 2
    z, heading, climb = 0, 0, 1
    cells = [(x, y, z)]
    headings = [heading]
    edges: list[tuple[int, int]] = []
    is_loop: list[bool] = []
    last_visit = {(x, y, z): 0}
    for k, (u_move, u_climb, u_loop) in enumerate(draws.tolist()):
        if k == 0:
            continue
        if u_climb < climb_probability:
            if not 0 <= z + climb < levels:
                climb = -climb
            z += climb
        else:
            options = [(heading + turn) % 4 for turn in (0, 1, 3)]  # forward, left, right
            inside = [0 <= x + _STEP_X[h] < size and 0 <= y + _STEP_Y[h] < size for h in options]
            # A square of side >= 2 always leaves a way out that is not backwards.
            candidates = [(h, w) for h, w, ok in zip(options, weights, inside) if ok]
            total = sum(w for _, w in candidates)
            if total <= 0.0:  # turn_probability 0 or 1 with the only weighted move blocked
                candidates = [(h, 1.0) for h, _ in candidates]
                total = float(len(candidates))
            target = u_move * total
            heading = candidates[-1][0]
            for h, w in candidates:
                if target < w:
                    heading = h
                    break
                target -= w
            x += _STEP_X[heading]
            y += _STEP_Y[heading]
        cell = (x, y, z)
        cells.append(cell)
        headings.append(heading)
        edges.append((k - 1, k))
        is_loop.append(False)
        previous = last_visit.get(cell)
        if previous is not None and previous < k - 1 and u_loop < loop_probability:
            edges.append((previous, k))
            is_loop.append(True)
        last_visit[cell] = k
    return (
        np.array(cells, dtype=np.int64),
        np.array(headings, dtype=np.int64),
        np.array(edges, dtype=np.int64).reshape(-1, 2),
        np.array(is_loop, dtype=bool),
    )


def _ground_truth(dim: int, positions: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """True poses `(N, P)` from positions `(N, 3)` metres and headings `(N,)` in 0..3 (exact)."""
    if dim == 2:
        return np.column_stack((positions[:, :2], _YAW[headings]))
    zeros = np.zeros(len(headings))
    return np.column_stack((positions, zeros, zeros, _QUAT_Z[headings], _QUAT_W[headings]))


def _prefix_products(T: np.ndarray) -> np.ndarray:
    """Running products `T_0 T_1 ... T_k` of `(N, n, n)` matrices, for all k at once.

    Hillis-Steele scan: after the pass with shift s each entry holds the product of the last 2s
    factors up to it, so log2(N) batched matrix products replace N sequential ones.
    """
    out = np.array(T, dtype=np.float64)
    shift = 1
    while shift < len(out):
        out[shift:] = out[:-shift] @ out[shift:]
        shift *= 2
    return out


def rounded(values: np.ndarray, decimals: int | None) -> np.ndarray:
    """`values` rounded to `decimals` places (unchanged when None), with -0.0 turned into 0.0."""
    if decimals is None:
        return np.array(values, dtype=np.float64)
    return np.round(values, decimals) + 0.0
