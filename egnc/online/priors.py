"""The measurement priors an online map holds (GNSS fixes, pose priors), and the gauge they set.

A prior measures one pose in the world frame: a pose prior its whole pose (residual
`Log(Z^-1 X)`, dimension `d`), a position prior its translation (residual `t - z`, dimension
`dim`), as in a batch graph (`egnc.graph.priors`). They join the online solver's factors the
way the batch solve takes them: the linear layer sees each prior as an edge from one fixed
virtual pose (`egnc.nonlinear.prior_gauge`), and every per-factor array of the map (`r`, `mu`,
`mu_init`, the candidate flags) holds the `E` edges then the `K` priors
(`egnc.robust.factor_set`'s layout). A prior that is a candidate graduates like a new loop
closure, its chi-square tests at its own dimension; a known-inlier prior stays quadratic.

The gauge: until the priors pin the map's placement (`egnc.graph.priors.unpinned_directions`),
the first pose stays held as without priors, and every new prior moves the map rigidly onto the
fixes (the batch solve's trimmed fit, `egnc.nonlinear.prior_alignment.frame_motion`: a wrong fix
does not drag it). The update whose priors first pin the map moves it onto them once more and
frees the held pose: from then on the priors alone hold the map, as `egnc.solve` holds a graph
with priors and no FIX line. A pose held by `OnlineSolver.add_prior` stays held: the map is then
not moved onto the fixes (as a FIX line in a batch graph).
"""

from __future__ import annotations

import numpy as np

from egnc.graph import POSE_SIZE, TANGENT_SIZE
from egnc.graph.priors import POSE, Priors, unpinned_directions
from egnc.nonlinear.prior_alignment import frame_motion
from egnc.nonlinear.prior_factors import PriorFactors

__all__ = ["MapPriors"]


class MapPriors:
    """The priors of an online map, in arrival order (prior index `k`, factor index `E + k`).

    Attributes:
        dim: 2 or 3.
        rows: `(K,)` pose row each prior measures.
        kinds: `(K,)` int8, `POSE` (0) or `POSITION` (1) (`egnc.graph.priors`).
        measurements: `(K, P)` a pose prior's pose, a position prior's `dim` coordinates then zeros.
        information: `(K, d, d)` a position prior's `(dim, dim)` block top-left, zeros elsewhere.
    """

    def __init__(self, dim: int):
        self.dim = dim
        self.rows = np.zeros(0, dtype=np.int64)
        self.kinds = np.zeros(0, dtype=np.int8)
        self.measurements = np.zeros((0, POSE_SIZE[dim]))
        self.information = np.zeros((0, TANGENT_SIZE[dim], TANGENT_SIZE[dim]))
        self._factors: PriorFactors | None = None

    def __len__(self) -> int:
        return len(self.rows)

    def append(self, rows: np.ndarray, kinds: np.ndarray, measurements: np.ndarray, information: np.ndarray) -> None:
        """Add priors on pose `rows` `(Q,)` of `kinds` `(Q,)` with padded `measurements` `(Q, P)`
        and `information` `(Q, d, d)` (checked by `egnc.online.intake`)."""
        self.rows = np.concatenate((self.rows, rows))
        self.kinds = np.concatenate((self.kinds, kinds))
        self.measurements = np.concatenate((self.measurements, measurements))
        self.information = np.concatenate((self.information, information))
        self._factors = None

    def priors(self, rows: np.ndarray | None = None) -> Priors:
        """The priors as a graph's `Priors`, on pose `rows` `(K,)` of another order (default: the map's rows)."""
        rows = self.rows if rows is None else rows
        return Priors(self.dim, rows, self.kinds, self.measurements, self.information)

    def factors(self) -> PriorFactors | None:
        """The priors' factors (None without priors), built when first needed after one arrived."""
        if not len(self):
            return None
        if self._factors is None:
            self._factors = PriorFactors.from_priors(self.priors())
        return self._factors

    @property
    def dims(self) -> np.ndarray:
        """`(K,)` residual dimension of each prior: `d` for a pose prior, `dim` for a position prior."""
        return np.where(self.kinds == POSE, TANGENT_SIZE[self.dim], self.dim)

    def pin_the_map(self) -> bool:
        """Whether the priors pin the map's placement (no direction left free)."""
        return len(self) > 0 and unpinned_directions(self.priors()) is None

    def onto_fixes(self, T: np.ndarray) -> np.ndarray:
        """`(N, n, n)` poses `T` moved rigidly onto the priors' positions (the trimmed fit)."""
        return frame_motion(self.priors(), T[self.rows, : self.dim, self.dim]) @ T

    def residual_norms(self, T: np.ndarray, first: int = 0) -> np.ndarray:
        """`(K - first,)` whitened residual norms of the priors from index `first` on, at poses `T` `(N, n, n)`."""
        factors = self.factors()
        if factors is None or first >= len(self):
            return np.zeros(0)
        if first:
            factors = factors.subset(np.arange(first, len(self)))
        return factors.whitened_norms(factors.residuals(T))
