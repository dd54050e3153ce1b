"""From a GTSAM `NonlinearFactorGraph` and `Values` to a `PoseGraph`, and a `Result` back to GTSAM.

GTSAM's Python SLAM code holds its problem as factors and values keyed by `gtsam.Symbol`s
(`x0`, `a12`, `b7` for two robots). `from_gtsam` reads them without a g2o file in between:

- `BetweenFactorPose2/3` become edges, `PriorFactorPose2/3` pose priors and `GPSFactor` (3D)
  position priors (`egnc.graph.priors`); the residuals are GTSAM's (`Logmap(Z^-1 Xi^-1 Xj)`,
  `Logmap(Z^-1 X)`, `t - z`), so egnc's cost at the values is `graph.error(values)`.
- A noise model becomes its information matrix `R^T R` (Gaussian, diagonal, isotropic, unit).
  GTSAM orders a `Pose3` tangent `[omega, v]` and egnc `[v, omega]`: the blocks are swapped
  (`P Omega P^T`, as `gtsam.readG2o` does the other way). A robust model (`noiseModel.Robust`)
  is read as its Gaussian part, with an `EgncWarning`: egnc decides the outliers itself.
- Any other factor or noise model (constrained, a factor on landmarks, ...) is an
  `UnsupportedFactorError` naming the factor's index and type.

Keys. GTSAM keys are `uint64`; egnc's vertex ids are `int64`. Each key becomes the id with the same
64 bits (`keys.view(np.int64)`): lossless both ways, and `Symbol(c, i)` and `Symbol(c, i + 1)` stay
consecutive ids, so each robot's odometry is still the default's known inliers. Symbols whose
character is above `0x7f` have keys of `2**63` or more and become negative ids (sorted first);
`GtsamGraph.keys` holds the original keys row by row.

Factor indices. Each factor's index in the GTSAM graph is kept as its "line" (index + 1), so the
edges and priors of the `PoseGraph` are numbered as the GTSAM factors are (`Result.rejected_edges`
are GTSAM factor indices when the graph has no empty slot); `inlier_factor_mask` maps a result
back over the original indices for `graph.at(i)`.

`gtsam` is imported inside the functions: `egnc` itself never needs it (the `gtsam` extra).
"""

from __future__ import annotations

import time
import typing
import warnings
from dataclasses import dataclass

import numpy as np

from egnc.errors import EgncError, EgncWarning, GraphError, OptionError, UnsupportedFactorError
from egnc.graph import PoseGraph
from egnc.graph.priors import POSE, POSITION, Priors
from egnc.nonlinear.factors import BetweenFactors, from_matrices, to_matrices
from egnc.nonlinear.prior_factors import prior_cost
from egnc.robust.result import Result

__all__ = [
    "GtsamGraph",
    "from_gtsam",
    "gtsam_error",
    "inlier_factor_mask",
    "to_gtsam",
    "to_gtsam_values",
    "values_to_poses",
]

_BETWEEN = {"BetweenFactorPose2": 2, "BetweenFactorPose3": 3}
_PRIOR = {"PriorFactorPose2": 2, "PriorFactorPose3": 3}
_POSITION = {"GPSFactor": 3}
_SUPPORTED = "BetweenFactorPose2/3, PriorFactorPose2/3 and GPSFactor"


@dataclass(frozen=True, eq=False)
class GtsamGraph:
    """A GTSAM graph read by `from_gtsam`.

    Attributes:
        graph: the `PoseGraph`; its vertex ids are the keys' 64 bits as `int64`.
        keys: `(N,)` uint64 GTSAM key of each pose row (`graph.vertex_ids.view(np.uint64)`).
        factor_index: `(F,)` int64, for each factor index of the GTSAM graph, the factor index of
            egnc (`PoseGraph.edge_factor_index`, `prior_factor_index`), -1 for an empty slot.
        seconds: wall time of the conversion.
    """

    graph: PoseGraph
    keys: np.ndarray
    factor_index: np.ndarray
    seconds: float = 0.0

    def robots(self) -> np.ndarray:
        """`(N,)` str: the `Symbol` character of each pose row (`"x"`, `"a"`, `"b"`, ...)."""
        return np.array([chr(c) for c in (self.keys >> np.uint64(56)).astype(np.uint8)])


class _Factors(typing.NamedTuple):
    """The factors of a GTSAM graph sorted into egnc's, each list in factor order."""

    dim: int
    edges: list[tuple[int, int, int]]  # (factor index, key i, key j)
    edge_matrices: list[np.ndarray]
    edge_information: list[np.ndarray]
    priors: list[tuple[int, int, int]]  # (factor index, key, kind)
    prior_measurements: list[np.ndarray]
    prior_information: list[np.ndarray]
    size: int


def from_gtsam(graph: typing.Any, values: typing.Any) -> GtsamGraph:
    """Read a `gtsam.NonlinearFactorGraph` and its `gtsam.Values` into a `PoseGraph`.

    Args:
        graph: the factors: `BetweenFactorPose2/3`, `PriorFactorPose2/3`, `GPSFactor`, with
            Gaussian, diagonal, isotropic, unit or robust noise models (module docstring).
        values: a `Pose2` (2D) or `Pose3` (3D) for every key, the initial guess.

    Returns:
        The `GtsamGraph`: the `PoseGraph`, the key of each pose row and the map of factor indices.

    Raises:
        UnsupportedFactorError: a factor, or its noise model, has no counterpart in egnc (its index
            and type are named).
        GraphError: a factor's key has no value, a value is not a pose of the graph's dimension,
            or the graph has no between-factor.

    Warns:
        EgncWarning: robust noise models were read as their Gaussian part.
    """
    started = time.perf_counter()
    factors = _read_factors(graph)
    keys, poses = values_to_poses(values, factors.dim)
    order = np.argsort(keys.view(np.int64), kind="stable")  # egnc's ids sort as int64
    keys, poses = keys[order], poses[order]
    ids = keys.view(np.int64)
    edge_keys = np.array([(i, j) for _, i, j in factors.edges], dtype=np.uint64).reshape(-1, 2)
    prior_keys = np.array([key for _, key, _ in factors.priors], dtype=np.uint64)
    edge_rows = _rows_of(keys, edge_keys, [index for index, _, _ in factors.edges])
    prior_rows = _rows_of(keys, prior_keys, [index for index, _, _ in factors.priors])
    dim = factors.dim
    information = np.array(factors.edge_information).reshape(-1, 3 * (dim - 1), 3 * (dim - 1))
    measurements = from_matrices(dim, np.array(factors.edge_matrices).reshape(-1, dim + 1, dim + 1))
    priors = Priors.from_lists(
        dim,
        prior_rows.tolist(),
        ["pose" if kind == POSE else "position" for _, _, kind in factors.priors],
        factors.prior_measurements,
        factors.prior_information,
    )
    priors = Priors(
        dim,
        priors.rows,
        priors.kinds,
        priors.measurements,
        priors.information,
        lines=np.array([index + 1 for index, _, _ in factors.priors], dtype=np.int64),
    )
    pose_graph = PoseGraph(
        dim,
        ids,
        poses,
        edge_rows,
        measurements,
        information,
        edge_lines=np.array([index + 1 for index, _, _ in factors.edges], dtype=np.int64),
        priors=priors,
    )
    factor_index = np.full(factors.size, -1, dtype=np.int64)
    factor_index[[index for index, _, _ in factors.edges]] = pose_graph.edge_factor_index
    factor_index[[index for index, _, _ in factors.priors]] = pose_graph.prior_factor_index
    return GtsamGraph(pose_graph, keys, factor_index, time.perf_counter() - started)


def _read_factors(graph: typing.Any) -> _Factors:
    """Sort the factors of a `NonlinearFactorGraph` into edges and priors (`from_gtsam`)."""
    edges: list[tuple[int, int, int]] = []
    priors: list[tuple[int, int, int]] = []
    edge_matrices, edge_information, prior_measurements, prior_information = [], [], [], []
    dim = 0
    robust: list[int] = []
    size = int(graph.size())
    for index in range(size):
        if not graph.exists(index):  # a slot left empty by graph.remove(index)
            continue
        factor = graph.at(index)
        name = type(factor).__name__
        factor_dim = _BETWEEN.get(name) or _PRIOR.get(name) or _POSITION.get(name)
        if factor_dim is None:
            raise UnsupportedFactorError(index, name, f"egnc reads {_SUPPORTED} only")
        if dim and factor_dim != dim:
            raise UnsupportedFactorError(index, name, f"a {factor_dim}D factor among {dim}D ones")
        dim = factor_dim
        info = _information(factor, index, name, robust)
        keys = [int(key) for key in factor.keys()]
        if name in _BETWEEN:
            edges.append((index, keys[0], keys[1]))
            edge_matrices.append(_pose_matrix(factor.measured(), dim))
            edge_information.append(info)
        elif name in _PRIOR:
            priors.append((index, keys[0], POSE))
            prior_measurements.append(from_matrices(dim, _pose_matrix(factor.prior(), dim)))
            prior_information.append(info)
        else:
            priors.append((index, keys[0], POSITION))
            prior_measurements.append(np.asarray(factor.measurementIn(), dtype=np.float64).reshape(3))
            prior_information.append(info)
    if not edges:
        raise GraphError("the GTSAM graph has no BetweenFactorPose2/3: there is no pose graph to solve")
    if robust:
        warnings.warn(
            f"{len(robust)} factors have robust noise models (the first: factor {robust[0]}); egnc reads "
            "their Gaussian part and decides the outliers itself",
            EgncWarning,
            stacklevel=3,
        )
    return _Factors(dim, edges, edge_matrices, edge_information, priors, prior_measurements, prior_information, size)


def _information(factor: typing.Any, index: int, name: str, robust: list[int]) -> np.ndarray:
    """The information matrix of a factor's noise model in egnc's tangent order (`[v, omega]`)."""
    import gtsam

    noise = factor.noiseModel()
    if isinstance(noise, gtsam.noiseModel.Robust):
        robust.append(index)
        noise = noise.noise()
    if not isinstance(noise, gtsam.noiseModel.Gaussian) or noise.isConstrained():
        raise UnsupportedFactorError(
            index,
            name,
            f"noise model {type(noise).__name__} has no information matrix "
            "(egnc reads Gaussian, Diagonal, Isotropic, Unit and Robust ones)",
        )
    R = np.asarray(noise.R(), dtype=np.float64)
    info = R.T @ R
    if info.shape == (6, 6):  # GTSAM's Pose3 tangent is [omega, v]
        info = _swap_pose3_blocks(info)
    return info


def _swap_pose3_blocks(info: np.ndarray) -> np.ndarray:
    """`P Omega P^T` with `P` swapping the two 3-blocks of a `(..., 6, 6)` matrix (its own inverse)."""
    swap = np.r_[3:6, 0:3]
    return info[..., swap, :][..., :, swap]


def _pose_matrix(pose: typing.Any, dim: int) -> np.ndarray:
    """The homogeneous matrix `(dim + 1, dim + 1)` of a `Pose2` or `Pose3`."""
    if dim == 2:
        return to_matrices(2, np.array([pose.x(), pose.y(), pose.theta()]))
    return np.asarray(pose.matrix(), dtype=np.float64)


def values_to_poses(values: typing.Any, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """`(keys (N,) uint64, poses (N, P))` of `gtsam.Values` that hold only poses of dimension `dim`,
    in GTSAM's key order (unsigned), poses in egnc's parametrization.

    Raises:
        GraphError: a value is not a `Pose2` (dim 2) or `Pose3` (dim 3).
    """
    import gtsam

    keys = np.array(list(values.keys()), dtype=np.uint64)
    if dim == 2:
        poses = np.asarray(gtsam.utilities.extractPose2(values), dtype=np.float64).reshape(-1, 3)
    else:
        flat = np.asarray(gtsam.utilities.extractPose3(values), dtype=np.float64).reshape(-1, 12)
        T = np.zeros((len(flat), 4, 4))
        T[:, :3, :3] = flat[:, :9].reshape(-1, 3, 3)
        T[:, :3, 3] = flat[:, 9:]
        T[:, 3, 3] = 1.0
        poses = from_matrices(3, T)
    if len(poses) != len(keys):
        for key in keys:  # name the first value that is not a pose of this dimension
            if not values.exists(int(key)) or not _is_pose(values, int(key), dim):
                name = gtsam.DefaultKeyFormatter(int(key))
                raise GraphError(f"value {name} is not a Pose{dim}: egnc reads poses of one dimension only")
    return keys, poses


def _is_pose(values: typing.Any, key: int, dim: int) -> bool:
    """Whether `values[key]` is a `Pose2` (dim 2) or `Pose3` (dim 3)."""
    try:
        values.atPose2(key) if dim == 2 else values.atPose3(key)
    except RuntimeError:
        return False
    return True


def _rows_of(keys: np.ndarray, wanted: np.ndarray, factor_indices: list[int]) -> np.ndarray:
    """Row of each key of `wanted` in the sorted-as-int64 `keys`; a key without a value is a `GraphError`."""
    ids = keys.view(np.int64)
    flat = wanted.reshape(-1).view(np.int64)
    rows = np.minimum(np.searchsorted(ids, flat), max(len(ids) - 1, 0))
    missing = np.flatnonzero(ids[rows] != flat) if len(ids) else np.arange(len(flat))
    if len(missing):
        first = missing[0]
        per_factor = flat.size // max(len(factor_indices), 1)
        import gtsam

        key = int(wanted.reshape(-1)[first])
        raise GraphError(
            f"factor {factor_indices[first // per_factor]}: key {gtsam.DefaultKeyFormatter(key)} has no value"
        )
    return rows.reshape(wanted.shape)


def to_gtsam_values(result: Result | PoseGraph, keys: np.ndarray | GtsamGraph) -> typing.Any:
    """The poses of a solve (or of a graph) as `gtsam.Values` under their GTSAM keys.

    Args:
        result: a `Result` of a graph `from_gtsam` read, or a `PoseGraph`.
        keys: `(N,)` uint64 key of each pose row (`GtsamGraph.keys`), or the `GtsamGraph`.
    """
    import gtsam

    graph = result.graph if isinstance(result, Result) else result
    keys = keys.keys if isinstance(keys, GtsamGraph) else np.asarray(keys, dtype=np.uint64)
    if keys.shape != (graph.num_poses,):
        raise OptionError(f"keys must hold one key per pose ({graph.num_poses}), got shape {keys.shape}")
    values = gtsam.Values()
    if graph.dim == 2:
        for key, (x, y, theta) in zip(keys.tolist(), graph.poses.tolist()):
            values.insert(key, gtsam.Pose2(x, y, theta))
    else:
        for key, T in zip(keys.tolist(), to_matrices(3, graph.poses)):
            values.insert(key, gtsam.Pose3(T))
    return values


def inlier_factor_mask(result: Result, bridge: GtsamGraph) -> np.ndarray:
    """`(F,)` bool over the original GTSAM factor indices: whether egnc kept factor `i`.

    False for the rejected loop closures (and rejected priors) and for empty slots; the factors
    where it is true are the cleaned graph, e.g. for `gtsam.ISAM2`.
    """
    graph = bridge.graph
    if not isinstance(result, Result) or result.graph.num_edges != graph.num_edges:
        raise OptionError("result must be the Result of a solve of bridge.graph")
    accepted = np.ones(graph.num_edges + graph.num_priors, dtype=bool)
    accepted[result.rejected_edges] = False
    accepted[result.rejected_priors] = False
    present = bridge.factor_index >= 0
    mask = np.zeros(len(bridge.factor_index), dtype=bool)
    mask[present] = accepted[bridge.factor_index[present]]
    return mask


def to_gtsam(graph: PoseGraph, keys: np.ndarray | None = None) -> tuple[typing.Any, typing.Any]:
    """A `PoseGraph` as GTSAM's `(NonlinearFactorGraph, Values)`: the inverse of `from_gtsam`.

    Edges and priors are added in egnc's factor order with `Gaussian` noise models; `fixed` poses
    are not represented (GTSAM has none: add a prior). `keys` defaults to the vertex ids' bits.
    """
    import gtsam

    if keys is None:
        keys = graph.vertex_ids.view(np.uint64)
    keys = np.asarray(keys, dtype=np.uint64)
    values = to_gtsam_values(graph, keys)
    info = graph.information if graph.dim == 2 else _swap_pose3_blocks(graph.information)
    pose_type = gtsam.Pose2 if graph.dim == 2 else gtsam.Pose3
    between = gtsam.BetweenFactorPose2 if graph.dim == 2 else gtsam.BetweenFactorPose3
    added: list[typing.Any] = [None] * (graph.num_edges + graph.num_priors)
    for edge, (i, j) in enumerate(graph.edges.tolist()):
        Z = _pose_of(pose_type, graph.dim, graph.measurements[edge])
        noise = gtsam.noiseModel.Gaussian.Information(info[edge])
        added[graph.edge_factor_index[edge]] = between(int(keys[i]), int(keys[j]), Z, noise)
    priors = graph.priors
    for k in range(len(priors)):
        key = int(keys[priors.rows[k]])
        factor: typing.Any
        if priors.kinds[k] == POSE:
            block = priors.information[k] if graph.dim == 2 else _swap_pose3_blocks(priors.information[k])
            prior = gtsam.PriorFactorPose2 if graph.dim == 2 else gtsam.PriorFactorPose3
            Z = _pose_of(pose_type, graph.dim, priors.measurements[k])
            factor = prior(key, Z, gtsam.noiseModel.Gaussian.Information(block))
        elif graph.dim == 3:
            noise = gtsam.noiseModel.Gaussian.Information(priors.information[k, :3, :3])
            factor = gtsam.GPSFactor(key, priors.measurements[k, :3], noise)
        else:
            raise EgncError(f"prior {k}: GTSAM has no 2D position prior factor")
        added[graph.prior_factor_index[k]] = factor
    factors = gtsam.NonlinearFactorGraph()
    for factor in added:
        factors.add(factor)
    return factors, values


def _pose_of(pose_type: typing.Any, dim: int, params: np.ndarray) -> typing.Any:
    """A `Pose2` or `Pose3` from egnc's stored parameters `(P,)`."""
    if dim == 2:
        return pose_type(*params.tolist())
    return pose_type(to_matrices(3, params))


def gtsam_error(graph: PoseGraph) -> float:
    """`0.5 sum r^T Omega r` over the edges and priors at the graph's poses: GTSAM's `graph.error(values)`."""
    factors = BetweenFactors.from_graph(graph)
    r = factors.whitened_norms(factors.residuals(to_matrices(graph.dim, graph.poses)))
    return float(0.5 * np.sum(r**2)) + prior_cost(graph.priors, graph.poses)
