"""Absolute measurements of single poses: pose priors and position priors (GNSS).

Two kinds, each with its own residual dimension `m`:

- **pose** (`PriorFactorPose2/3` in GTSAM, `EDGE_SE2_PRIOR` / `EDGE_SE3_PRIOR` in g2o): a whole
  pose `Z`; residual `Log(Z^-1 X)`, `m = d` (3 in 2D, 6 in 3D), information ordered
  translation-then-rotation like the edges'.
- **position** (`GPSFactor` in GTSAM, `EDGE_SE2_XYPRIOR` / `EDGE_SE3_XYZPRIOR` in g2o): a position
  `z` in the world frame; residual `t - z`, `m = dim` (2 or 3), information on `(x, y[, z])`.

Arrays of mixed dimension are padded to `d`: a position prior's measurement row holds its `dim`
coordinates then zeros, its information matrix is the `(m, m)` block in the top-left corner of a
`(d, d)` one filled with zeros. Every prior thus has one row in each `(K, ...)` array, and the
factors can be evaluated in one vectorized pass (`egnc.nonlinear.priors`).

The map's gauge (a rigid motion of all poses) is pinned by the priors unless they leave a direction
free: `unpinned_directions` tests the rank of their Jacobian on that motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from egnc.errors import GraphError
from egnc.graph.validity import not_positive_definite, not_positive_definite_message

PriorKind = Literal["pose", "position"]
POSE, POSITION = 0, 1
"""Codes of the two kinds in `Priors.kinds`."""
KIND_NAMES = ("pose", "position")

_POSE_SIZE = {2: 3, 3: 7}
_TANGENT_SIZE = {2: 3, 3: 6}


def _frozen(value: object, dtype: type) -> np.ndarray:
    """A read-only private copy of `value` as `dtype`."""
    array: np.ndarray = np.array(value, dtype=dtype)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Priors:
    """The priors of a graph: K unary factors, each on one pose row, in their own (file) order.

    Attributes:
        dim: spatial dimension, 2 or 3.
        rows: `(K,)` int64 pose row each prior measures.
        kinds: `(K,)` int8, `POSE` (0) or `POSITION` (1).
        measurements: `(K, P)` float64; a pose prior's pose in the poses' parametrization
            (`x y theta` or `x y z qx qy qz qw`), a position prior's `dim` coordinates then zeros.
        information: `(K, d, d)` float64; a position prior's `(dim, dim)` information in the
            top-left corner, zeros elsewhere.
        lines: `(K,)` int64 1-based source line of each prior (0 when not read from a file).
        param_ids: `(K,)` int64, the g2o `PARAMS_SE3OFFSET` id a 3D prior names (0 by default;
            unused in 2D), kept so that `write_g2o` writes the record back as read.

    The constructor checks shapes, finite values, kinds and positive-definite information (of each
    prior's own dimension), raising `GraphError` naming the prior's index.
    """

    dim: int
    rows: np.ndarray
    kinds: np.ndarray
    measurements: np.ndarray
    information: np.ndarray
    lines: np.ndarray = None  # type: ignore[assignment]
    param_ids: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        p, d = _POSE_SIZE[self.dim], _TANGENT_SIZE[self.dim]
        try:
            object.__setattr__(self, "rows", _frozen(self.rows, np.int64))
            object.__setattr__(self, "kinds", _frozen(self.kinds, np.int8))
            object.__setattr__(self, "measurements", _frozen(self.measurements, np.float64))
            object.__setattr__(self, "information", _frozen(self.information, np.float64))
            lines = np.zeros(len(self.rows), dtype=np.int64) if self.lines is None else self.lines
            object.__setattr__(self, "lines", _frozen(lines, np.int64))
            params = np.zeros(len(self.rows), dtype=np.int64) if self.param_ids is None else self.param_ids
            object.__setattr__(self, "param_ids", _frozen(params, np.int64))
        except (TypeError, ValueError) as error:
            raise GraphError(f"priors must be arrays of numbers: {error}") from None
        k = len(self.rows)
        shapes = {
            "rows": (k,),
            "kinds": (k,),
            "measurements": (k, p),
            "information": (k, d, d),
            "lines": (k,),
            "param_ids": (k,),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise GraphError(f"priors.{name} has shape {getattr(self, name).shape}, expected {shape}")
        self._check_values()

    def _check_values(self) -> None:
        """Kinds known, values finite, information positive definite on each prior's own block."""
        bad_kind = np.flatnonzero((self.kinds != POSE) & (self.kinds != POSITION))
        if len(bad_kind):
            raise GraphError(
                f"prior {bad_kind[0]}: kind must be 0 (pose) or 1 (position), got {self.kinds[bad_kind[0]]}"
            )
        finite = np.isfinite(self.measurements).all(axis=1) & np.isfinite(self.information).all(axis=(1, 2))
        if not finite.all():
            raise GraphError(f"prior {np.flatnonzero(~finite)[0]}: measurement or information is not finite")
        for kind, m in ((POSE, self.tangent_dim), (POSITION, self.dim)):
            chosen = np.flatnonzero(self.kinds == kind)
            block = self.information[chosen][:, :m, :m]
            bad = not_positive_definite(block)
            if len(bad):
                raise GraphError(f"prior {chosen[bad[0]]}: {not_positive_definite_message(block, bad)}")
            outside = self.information[chosen].copy()
            outside[:, :m, :m] = 0.0
            if kind == POSITION and np.any(outside):
                raise GraphError(
                    f"prior {chosen[np.flatnonzero(outside.any(axis=(1, 2)))[0]]}: a position prior's "
                    f"information must be zero outside its top-left ({m}, {m}) block"
                )
            if kind == POSITION and np.any(self.measurements[chosen][:, m:]):
                raise GraphError("a position prior's measurement must be zero past its coordinates")

    @classmethod
    def empty(cls, dim: int) -> Priors:
        """No prior."""
        p, d = _POSE_SIZE[dim], _TANGENT_SIZE[dim]
        return cls(dim, np.zeros(0, np.int64), np.zeros(0, np.int8), np.zeros((0, p)), np.zeros((0, d, d)))

    @classmethod
    def from_lists(
        cls,
        dim: int,
        rows: list[int],
        kinds: list[PriorKind],
        measurements: list[np.ndarray],
        information: list[np.ndarray],
    ) -> Priors:
        """Build from one entry per prior, each at its own size (`(m,)` or `(P,)` measurement, `(m, m)` information)."""
        p, d = _POSE_SIZE[dim], _TANGENT_SIZE[dim]
        k = len(rows)
        padded_z, padded_info = np.zeros((k, p)), np.zeros((k, d, d))
        for index, (z, info) in enumerate(zip(measurements, information)):
            z, info = np.asarray(z, dtype=float), np.asarray(info, dtype=float)
            padded_z[index, : len(z)] = z
            padded_info[index, : len(info), : len(info)] = info
        codes = [KIND_NAMES.index(kind) for kind in kinds]
        return cls(dim, np.asarray(rows, dtype=np.int64), np.asarray(codes, dtype=np.int8), padded_z, padded_info)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def tangent_dim(self) -> int:
        """Tangent dimension d of the poses: 3 in 2D, 6 in 3D."""
        return _TANGENT_SIZE[self.dim]

    @property
    def factor_dims(self) -> np.ndarray:
        """`(K,)` residual dimension m of each prior: d for a pose prior, `dim` for a position prior."""
        return np.where(self.kinds == POSE, self.tangent_dim, self.dim)

    def counts(self) -> dict[str, int]:
        """Number of priors of each kind, by name."""
        return {name: int(np.count_nonzero(self.kinds == code)) for code, name in enumerate(KIND_NAMES)}

    def subset(self, keep: np.ndarray) -> Priors:
        """The priors `keep` selects (`(K,)` bool mask or increasing indices), in order."""
        return Priors(
            self.dim,
            self.rows[keep],
            self.kinds[keep],
            self.measurements[keep],
            self.information[keep],
            self.lines[keep],
            self.param_ids[keep],
        )

    def with_rows(self, rows: np.ndarray) -> Priors:
        """The same priors on other pose rows `(K,)` (a graph's rows renumbered)."""
        return Priors(self.dim, rows, self.kinds, self.measurements, self.information, self.lines, self.param_ids)


def gauge_jacobian(priors: Priors) -> np.ndarray:
    """`(sum m, d)` whitened Jacobian of all priors w.r.t. a rigid motion `X <- Exp(xi) X` of the whole map.

    Evaluated where the priors hold exactly (at their measurements), so it depends on the graph
    alone. A position prior moves as `t <- t + v + omega x t`: `[I, -[z]x]` (2D: `[I, (-z_y, z_x)]`);
    a pose prior's Jacobian at zero residual is `Ad(Z^-1)`, invertible, so any pose prior pins all `d`
    directions and its rows are written as `sqrt(Omega)` times an invertible matrix (`I` is as good for a rank).
    """
    d, dim = priors.tangent_dim, priors.dim
    blocks = []
    for k in range(len(priors)):
        m = d if priors.kinds[k] == POSE else dim
        if priors.kinds[k] == POSE:
            J = np.eye(d)
        else:
            z = priors.measurements[k, :dim]
            J = np.zeros((dim, d))
            J[:, :dim] = np.eye(dim)
            if dim == 2:
                J[:, 2] = (-z[1], z[0])
            else:
                J[:, 3:] = -np.array([[0.0, -z[2], z[1]], [z[2], 0.0, -z[0]], [-z[1], z[0], 0.0]])
        blocks.append(np.linalg.cholesky(priors.information[k, :m, :m]).T @ J)
    return np.concatenate(blocks) if blocks else np.zeros((0, d))


def unpinned_directions(priors: Priors) -> str | None:
    """What the priors leave free of the map's placement, in words, or None when they pin it all.

    A rank test of `gauge_jacobian` (singular values below `1e-9` times the largest, scaled by the
    map's extent, count as zero). Only reached for graphs with priors and no pose held fixed.
    """
    if len(priors) == 0:
        return "no prior pins the map"
    if np.any(priors.kinds == POSE):
        return None
    J = gauge_jacobian(priors)
    # Positions far from the origin make the rotation columns large: scale them to unit extent so
    # that the tolerance is relative to the map and not to where its origin is.
    dim = priors.dim
    extent = max(1.0, float(np.max(np.abs(priors.measurements[:, :dim]))))
    J = J.copy()
    J[:, dim:] /= extent
    singular = np.linalg.svd(J, compute_uv=False)
    rank = int(np.count_nonzero(singular > 1e-9 * max(singular.max(initial=0.0), 1e-300)))
    if rank == J.shape[1]:
        return None
    if dim == 2:
        return "the heading (rotation about the single prior position)"
    if len(priors) == 1 or rank <= 3:
        return "the rotation about the single prior position"
    return "the rotation about the line through the prior positions (they are collinear)"
