"""The gauge of a graph with priors, and how the priors join the linear layer.

Relative edges leave the map's placement free (a rigid motion of every pose costs nothing), so a
graph of edges alone is solved with pose 0 held. Priors can pin that freedom themselves: then
no pose is held unless the file says so (`FIX`), and the least-squares optimum is the one GTSAM
finds with the same factors. When the priors leave a direction free (one position prior in 2D
leaves the heading; position priors at one point or on one line in 3D leave a rotation;
`egnc.graph.priors.unpinned_directions`), pose 0 is held as today and an `EgncWarning` says what
the priors do not pin down.

The linear layer (`egnc.linalg`) knows only edges between poses. A prior on pose k enters it as
an edge `(N, k)` from one virtual, fixed pose at row N, whose Jacobian block is zero
(`egnc.nonlinear.prior_factors.PriorFactors.linearize`): the pattern, the direct and the CG
step solvers serve priors unchanged, and a graph without priors never sees the virtual pose.
"""

from __future__ import annotations

import warnings

import numpy as np

from egnc.errors import EgncWarning
from egnc.graph import PoseGraph
from egnc.graph.priors import unpinned_directions
from egnc.linalg.normal_equations import edge_products
from egnc.nonlinear.prior_factors import PriorFactors


def gauge_fixed(graph: PoseGraph) -> np.ndarray:
    """`(N,)` bool, the poses to hold for a graph with priors: the file's, else pose 0 when the
    priors leave a direction free (with an `EgncWarning` naming it), else none."""
    fixed = np.array(graph.fixed, dtype=bool)
    if fixed.any():
        return fixed
    free = unpinned_directions(graph.priors)
    if free is not None:
        warnings.warn(
            f"the {graph.num_priors} priors do not pin down {free}: vertex {graph.vertex_ids[0]} is held fixed",
            EgncWarning,
            stacklevel=3,
        )
        fixed[0] = True
    return fixed


def with_prior_anchor(edges: np.ndarray, fixed: np.ndarray, priors: PriorFactors) -> tuple[np.ndarray, np.ndarray]:
    """`(E + K, 2)` edges then one edge `(N, row)` per prior, and `(N + 1,)` fixed with the virtual pose held."""
    anchor = np.full(len(priors), len(fixed), dtype=np.int64)
    prior_edges = np.stack((anchor, priors.rows), axis=1)
    return np.concatenate((edges, prior_edges)), np.append(fixed, True)


def with_prior_products(
    priors: PriorFactors,
    T: np.ndarray,
    products: np.ndarray,
    weights: np.ndarray,
    trusted: np.ndarray | None,
    prior_weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The edges' normal-equation products `(E, 2d, 2d + 1)`, weights `(E,)` and trusted mask
    followed by the priors' at poses `T` `(N, n, n)`: the rows of the system `with_prior_anchor`
    lays out. `prior_weights`: `(K,)` the priors' IRLS weights (None: 1, held quadratic); a
    given `trusted` mask trusts every prior."""
    prior_weights = np.ones(len(priors)) if prior_weights is None else prior_weights
    prior_products = edge_products(priors.linearize(T), priors.information, prior_weights)
    if trusted is not None:
        trusted = np.concatenate((trusted, np.ones(len(priors), dtype=bool)))
    return np.concatenate((products, prior_products)), np.concatenate((weights, prior_weights)), trusted
