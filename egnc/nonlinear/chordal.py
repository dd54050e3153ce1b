"""Chordal initialization: rotations by a linear relaxation, then translations, no odometry chaining.

Rotations. An edge measures `R_j = R_i Z_ij`. Dropping the constraint that each `R_i` be a
rotation (the chordal relaxation) leaves the linear least-squares problem

    min sum_ij  w_ij || R_j - R_i Z_ij ||_F^2      over free real matrices R_i,

with the gauge poses held at their given rotations. Row by row, `R_j[r, :] = R_i[r, :] Z_ij`, so
the rows decouple: with `u_i = R_i[r, :]^T` every row is the same sparse system
`u_j - Z_ij^T u_i = 0`, d unknowns per pose, solved once with one right-hand side per row (three
in 3D). In 2D a rotation is fixed by its first row `(cos, -sin)`, so one right-hand side suffices
(LAGO's relaxation in (cos, sin) coordinates). Each solution is then projected on SO(d) (nearest
rotation in the Frobenius norm: SVD with a determinant fix).

Rotation weight. For small errors `||R_j - R_i Z_ij||_F^2 ~ ||[e_omega]x||_F^2`, proportional to
`|e_omega|^2`, so the relaxation can only carry an isotropic rotation precision per edge. egnc
takes the mean of the diagonal of the information's rotation block (exact for isotropic noise,
which most benchmark files use; GTSAM's InitializePose3 also reduces each edge to one isotropic
rotation precision). Only ratios between edges matter.

Translations. With the rotations fixed, `t_j - t_i = R_i t_ij` is linear in the translations.
Its error, expressed in pose j's frame as the residual's `v` part is to first order, is
`R_j^T (t_j - t_i - R_i t_ij)`; it is weighted by the information's translation block (the
precision of `v` given `omega`, consistent with holding the rotations fixed), whitened by that
block's Cholesky factor. The gauge poses keep their given translations.

Both steps solve sparse normal equations with egnc's linear solvers (CHOLMOD when installed,
else SuperLU). The result does not depend on the initial guess at all, except at the gauge poses,
which are returned exactly as given.

References:
    L. Carlone, R. Tron, K. Daniilidis, F. Dellaert, "Initialization techniques for 3D SLAM: a
    survey on rotation estimation and its use in pose graph optimization", ICRA 2015.
    L. Carlone, R. Aragues, J. A. Castellanos, B. Bona, "A fast and accurate approximation for
    planar pose graph optimization", IJRR 33(7), 2014 (LAGO).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.linalg.linear_solvers import make_linear_solver, resolve_name
from egnc.nonlinear.factors import from_matrices, to_matrices


def chordal_initialization(
    graph: PoseGraph, weights: np.ndarray | None = None, *, linear_solver: str = "auto"
) -> np.ndarray:
    """Return poses from the chordal rotation relaxation followed by a linear translation solve.

    Args:
        graph: the pose graph; its `fixed` poses (or, if none, pose 0) are the gauge and are
            returned exactly as given. No other pose of `graph.poses` is read.
        weights: optional `(E,)` factors in [0, 1] multiplying each edge's information (e.g. the
            weights of a robust kernel); an edge with weight 0 is ignored.
        linear_solver: `"auto"`, `"cholmod"`, `"rslab"` or `"scipy"`, as in `egnc.solve`.

    Returns:
        `(N, P)` float64 poses in the graph's parametrization (`(x, y, theta)` or
        `(x, y, z, qx, qy, qz, qw)`), metres and radians.

    Raises:
        EgncError: `weights` has the wrong shape or values outside [0, 1].
        SolverError: the normal equations are singular, e.g. some pose is not connected to the
            gauge by edges of nonzero weight (CHOLMOD detects this; SuperLU may not).
    """
    edge_weights = _validated_weights(weights, graph.num_edges)
    dim = graph.dim
    anchored = graph.fixed.copy()
    if not anchored.any():
        anchored[0] = True
    if anchored.all():
        return graph.poses.copy()
    backend = resolve_name(linear_solver)
    T_anchor = to_matrices(dim, graph.poses[anchored])
    Z = to_matrices(dim, graph.measurements)
    rotation_info = graph.information[:, dim:, dim:]
    translation_info = graph.information[:, :dim, :dim]

    rotations = chordal_rotations(
        graph.num_poses,
        graph.edges,
        Z[:, :dim, :dim],
        edge_weights * np.trace(rotation_info, axis1=1, axis2=2) / rotation_info.shape[1],
        anchored,
        T_anchor[:, :dim, :dim],
        backend,
    )
    translation_sqrt_info = np.sqrt(edge_weights)[:, None, None] * np.linalg.cholesky(translation_info).swapaxes(1, 2)
    translations = translations_given_rotations(
        rotations, graph.edges, Z[:, :dim, dim], translation_sqrt_info, anchored, T_anchor[:, :dim, dim], backend
    )
    T = np.zeros((graph.num_poses, dim + 1, dim + 1))
    T[:, :dim, :dim] = rotations
    T[:, :dim, dim] = translations
    T[:, dim, dim] = 1.0
    poses = from_matrices(dim, T)
    poses[anchored] = graph.poses[anchored]  # exactly as given, no round trip through matrices
    return poses


def chordal_rotations(
    num_poses: int,
    edges: np.ndarray,
    Z_rotations: np.ndarray,
    rotation_weights: np.ndarray,
    anchored: np.ndarray,
    anchor_rotations: np.ndarray,
    linear_solver: str = "auto",
) -> np.ndarray:
    """Solve the chordal relaxation for all rotations and project each on SO(d).

    Args:
        num_poses: N.
        edges: `(E, 2)` int rows `(i, j)`; edge k measures `R_i^T R_j = Z_rotations[k]`.
        Z_rotations: `(E, d, d)` measured relative rotations.
        rotation_weights: `(E,)` scalar precision of each edge's rotation (>= 0).
        anchored: `(N,)` bool, the gauge rotations (at least one).
        anchor_rotations: `(A, d, d)` the rotations of the anchored poses, in row order.
        linear_solver: `"auto"`, `"cholmod"`, `"rslab"` or `"scipy"`.

    Returns:
        `(N, d, d)` rotation matrices; anchored ones exactly as given.
    """
    d = Z_rotations.shape[-1]
    rows_used = 1 if d == 2 else d  # in 2D the first row (cos, -sin) determines the rotation
    sqrt_w = np.sqrt(rotation_weights)[:, None, None]
    identity = np.broadcast_to(np.eye(d), Z_rotations.shape)
    # Unknowns u_i = R_i[r, :]^T; residual u_j - Z^T u_i for each used row r.
    A = _edge_block_matrix(num_poses, edges, -sqrt_w * Z_rotations.swapaxes(1, 2), sqrt_w * identity)
    anchor_values = anchor_rotations.swapaxes(1, 2)[:, :, :rows_used]  # (A, d, rows_used)
    rows_T = _anchored_least_squares(A, np.zeros((A.shape[0], rows_used)), anchored, anchor_values, linear_solver)
    if d == 2:  # R^T = [[a, -b], [b, a]] from its first column (a, b) = (cos, -sin)
        a, b = rows_T[:, 0, 0], rows_T[:, 1, 0]
        rows_T = np.stack([np.stack([a, -b], axis=-1), np.stack([b, a], axis=-1)], axis=-2)
    rotations = nearest_rotation(rows_T.swapaxes(1, 2))
    rotations[anchored] = anchor_rotations
    return rotations


def translations_given_rotations(
    rotations: np.ndarray,
    edges: np.ndarray,
    Z_translations: np.ndarray,
    translation_sqrt_info: np.ndarray,
    anchored: np.ndarray,
    anchor_translations: np.ndarray,
    linear_solver: str = "auto",
) -> np.ndarray:
    """Solve the weighted linear least squares `t_j - t_i = R_i t_ij` with the rotations fixed.

    Args:
        rotations: `(N, d, d)` world-from-pose rotations.
        edges: `(E, 2)` int rows `(i, j)`.
        Z_translations: `(E, d)` measured translations `t_ij`, metres, in pose i's frame.
        translation_sqrt_info: `(E, d, d)` `L` with `L^T L` the translation block of the
            information (1/m^2), in pose j's frame.
        anchored: `(N,)` bool, the gauge poses (at least one).
        anchor_translations: `(A, d)` translations of the anchored poses, metres.
        linear_solver: `"auto"`, `"cholmod"`, `"rslab"` or `"scipy"`.

    Returns:
        `(N, d)` translations, metres; anchored ones exactly as given.
    """
    i, j = edges[:, 0], edges[:, 1]
    # Whitened residual L R_j^T (t_j - t_i - R_i t_ij).
    J = translation_sqrt_info @ rotations[j].swapaxes(1, 2)
    A = _edge_block_matrix(len(rotations), edges, -J, J)
    measured = np.einsum("eab,ebc,ec->ea", J, rotations[i], Z_translations)
    translations = _anchored_least_squares(
        A, measured.reshape(-1, 1), anchored, anchor_translations[:, :, None], linear_solver
    )[:, :, 0]
    translations[anchored] = anchor_translations
    return translations


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """Return the rotation closest to each matrix in the Frobenius norm: `(..., d, d) -> (..., d, d)`.

    `U diag(1, ..., 1, det(U V^T)) V^T` from the SVD `M = U S V^T`, so the result has determinant
    +1 even when `M` has a negative determinant.
    """
    U, _, Vt = np.linalg.svd(M)
    U[..., :, -1] *= np.sign(np.linalg.det(U @ Vt))[..., None]  # the smallest singular value's column
    return U @ Vt


def _edge_block_matrix(num_poses: int, edges: np.ndarray, J_i: np.ndarray, J_j: np.ndarray) -> sp.csc_matrix:
    """Return the sparse `(E m, N d)` matrix whose edge k has block `J_i[k]` at pose i and `J_j[k]` at j.

    `J_i`, `J_j`: `(E, m, d)`. Parallel edges and edges (i, i) are summed.
    """
    num_edges, m, d = J_i.shape
    row = np.arange(num_edges * m).reshape(num_edges, m, 1)
    col = np.arange(d).reshape(1, 1, d)
    rows = np.broadcast_to(row, (num_edges, m, d))
    cols_i = np.broadcast_to(edges[:, 0, None, None] * d + col, (num_edges, m, d))
    cols_j = np.broadcast_to(edges[:, 1, None, None] * d + col, (num_edges, m, d))
    return sp.csc_matrix(
        (
            np.concatenate([J_i.ravel(), J_j.ravel()]),
            (np.concatenate([rows.ravel(), rows.ravel()]), np.concatenate([cols_i.ravel(), cols_j.ravel()])),
        ),
        shape=(num_edges * m, num_poses * d),
    )


def _anchored_least_squares(
    A: sp.csc_matrix, b: np.ndarray, anchored: np.ndarray, anchor_values: np.ndarray, linear_solver: str
) -> np.ndarray:
    """Minimize `||A x - b||^2` over the free pose blocks, the anchored blocks held at their values.

    Args:
        A: `(M, N d)` sparse, d unknowns per pose block.
        b: `(M, k)` right-hand sides, one column per independent problem.
        anchored: `(N,)` bool.
        anchor_values: `(A, d, k)` values of the anchored blocks.
        linear_solver: backend name for `resolve_name`.

    Returns:
        `(N, d, k)` all blocks, anchored ones equal to `anchor_values`.
    """
    num_poses = len(anchored)
    d, k = anchor_values.shape[1:]
    column_is_anchored = np.repeat(anchored, d)
    A_free = A[:, ~column_is_anchored]
    rhs = b - A[:, column_is_anchored] @ anchor_values.reshape(-1, k)
    normal = (A_free.T @ A_free).tocsc()
    normal.sort_indices()
    solver = make_linear_solver(resolve_name(linear_solver), normal.indptr, normal.indices)
    free = solver.solve(normal.data, A_free.T @ rhs)
    values = np.empty((num_poses * d, k))
    values[~column_is_anchored] = np.asarray(free).reshape(-1, k)
    values[column_is_anchored] = anchor_values.reshape(-1, k)
    return values.reshape(num_poses, d, k)


def _validated_weights(weights: np.ndarray | None, num_edges: int) -> np.ndarray:
    """Return `(E,)` float64 edge weights (ones for None); raise `EgncError` unless all lie in [0, 1]."""
    if weights is None:
        return np.ones(num_edges)
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape != (num_edges,):
        raise EgncError(f"weights has shape {weights.shape}, expected ({num_edges},)")
    if not np.all((weights >= 0.0) & (weights <= 1.0)):
        raise EgncError("weights must lie in [0, 1]")
    return weights
