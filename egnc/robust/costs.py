"""Truncated least-squares cost and the thresholds of the outlier decision.

Two decisions on one graph are compared by the truncated cost of their maps: an accepted loop
closure pays `r^2 / 2`, a rejected one `chi2.ppf(q, d) / 2` (`truncated_cost`); the lower
explains the measurements better, and a rival must be lower by more than rounding to replace
the incumbent (`lower_by_more_than_rounding`). Re-admission tests at its own quantile, raised on
graphs of many loops (`readmit_quantile`).

Under the linear-Gaussian model the false-alarm rate per honest loop is below `1 - q` for the
test of accepted loops (an included loop's `r^2` is stochastically smaller than chi-square: it
pulls the map towards itself) and `1 - q_readmit` for re-admission, where `q_readmit` is raised
on graphs of many loops so that the expected number of honest loops re-admission keeps out of
one graph stays bounded.
"""

from __future__ import annotations

import numpy as np

from egnc.robust.gnc import GncOptions
from egnc.robust.kernels import chi2_quantile


def truncated_cost(r: np.ndarray, robust: np.ndarray, d: int | np.ndarray, quantile: float) -> float:
    """Truncated least-squares cost `0.5 (sum_known r^2 + sum_loops min(r^2, chi2.ppf(q, d)))`.

    The cost a classification pays under the outlier test: an accepted loop its squared residual,
    a rejected one the threshold. Two decisions on the same graph are compared by it (the lower
    explains the measurements better); it depends on the poses only.

    Args:
        r: `(E,)` whitened residual norms.
        robust: `(E,)` bool, the loop closures (truncated); the other edges are quadratic.
        d: residual dimension, or `(E,)` per factor (`egnc.robust.factor_set`).
        quantile: `q` of the outlier test (`GncOptions.outlier_quantile`).
    """
    r2 = r * r
    threshold = chi2_quantile(quantile, d)
    if np.ndim(threshold):
        threshold = threshold[robust]
    return 0.5 * float(np.sum(r2[~robust]) + np.sum(np.minimum(r2[robust], threshold)))


def lower_by_more_than_rounding(candidate: float, incumbent: float) -> bool:
    """Whether truncated cost `candidate` is below `incumbent` by more than a relative 1e-9: two
    starts that reach the same decision differ by rounding only, and the incumbent stays."""
    return candidate < incumbent * (1 - 1e-9)


def readmit_quantile(gnc_options: GncOptions, robust: np.ndarray) -> float:
    """The chi-square quantile of re-admission's test on a graph whose loop closures are `robust` `(E,)`.

    `gnc_options.readmit_quantile`, raised to `1 - readmit_false_alarms / L` on a graph of `L`
    loop closures where that is higher. An honest loop fails the test with probability
    `1 - quantile` under the linear-Gaussian model, so a fixed quantile keeps out a number of
    honest loops that grows with the graph (5.6 expected among a 100 000-pose grid's 56 000);
    the raised one bounds the expected number per graph (a Bonferroni correction).
    """
    quantile = gnc_options.readmit_quantile
    num_loops = int(np.count_nonzero(robust))
    if gnc_options.readmit_false_alarms is None or not num_loops:
        return quantile
    return max(quantile, 1.0 - gnc_options.readmit_false_alarms / num_loops)
