"""One method on one case: solve, score against the labels and the reference, record.

Every run is scored by one yardstick. Outliers are the positive class of precision and recall
(`egnc.metrics.precision_recall`), and a run is a success when both are exactly 1
(`egnc.metrics.success`). ATE and RPE are measured against the case's outlier-free reference
(`egnc.metrics`). GTSAM's outliers are decided by egnc's own rule on its final residuals (a loop
closure is an outlier when `r^2 > chi2.ppf(q, d)`, `q` = `GncOptions.outlier_quantile`, 0.99); GTSAM's
per-edge weights are not used.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass

import numpy as np

from egnc.api import solve
from egnc.bench.cases import BenchCase
from egnc.bench.child import Outcome
from egnc.bench.gtsam import gtsam_solve
from egnc.bench.methods import MethodSpec
from egnc.metrics import ate, precision_recall, rpe, success
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.robust.gnc import GncOptions, classify_inliers

__all__ = ["CSV_COLUMNS", "RunRecord", "describe_run", "record_run", "solve_and_score"]


@dataclass(frozen=True)
class RunRecord:
    """The outcome of one method on one case (one row of `results.csv`).

    Attributes:
        dataset, percent, seed: the case.
        method: the method's label.
        status: "ok", "timeout" or "error: <message>"; the metrics are nan unless "ok".
        precision, recall: outlier detection, outliers positive (`egnc.metrics.precision_recall`).
        success: precision and recall both 1.
        ate: absolute trajectory error against the reference, metres.
        rpe: translational relative pose error (consecutive poses), metres.
        rpe_rotation: rotational relative pose error, radians.
        rpe_percent: translational RPE / mean reference step length * 100.
        stages: `len(Result.stages)` of egnc methods (a final least-squares refinement counts as
            one); -1 for GTSAM, which does not report them.
        iterations: solver iterations over all stages (-1 when not reported).
        time_s: solver time in seconds: `Result.time_s` for egnc (graph in, result out),
            `optimize()` alone for GTSAM (file reading and graph building excluded).
        wall_s: seconds from the fork of the run's child process to its answer.
        loops: loop closures in the graph (candidates for rejection).
        outliers: true outliers among them.
        rejected: loop closures the method rejected.
    """

    dataset: str
    percent: float
    seed: int | None
    method: str
    status: str
    precision: float = math.nan
    recall: float = math.nan
    success: bool = False
    ate: float = math.nan
    rpe: float = math.nan
    rpe_rotation: float = math.nan
    rpe_percent: float = math.nan
    stages: int = -1
    iterations: int = -1
    time_s: float = math.nan
    wall_s: float = math.nan
    loops: int = 0
    outliers: int = 0
    rejected: int = 0

    @property
    def ok(self) -> bool:
        """Whether the run finished."""
        return self.status == "ok"

    @property
    def kept_precision_recall(self) -> tuple[float, float]:
        """Precision and recall in riSAM's convention, accepted loops positive (the paper's Table 1).

        From the counts: a kept true loop is a true positive, a kept false loop a false positive,
        a rejected true loop a false negative. Precision is 1 when nothing is kept.
        """
        rejected_false = round(self.recall * self.outliers) if self.outliers else 0
        kept_false = self.outliers - rejected_false
        kept_true = self.loops - self.outliers - (self.rejected - rejected_false)
        true_loops = self.loops - self.outliers
        precision = kept_true / (kept_true + kept_false) if kept_true + kept_false else 1.0
        return precision, (kept_true / true_loops if true_loops else 1.0)


CSV_COLUMNS = tuple(field.name for field in dataclasses.fields(RunRecord))
"""Columns of `results.csv`, in order."""


def solve_and_score(case: BenchCase, spec: MethodSpec, linear_solver: str) -> dict:
    """Solve one case with one method, then score it against the labels and the reference.

    Runs in a child process (`egnc.bench.child`); returns the `RunRecord` fields it measures.
    """
    if spec.is_gtsam:
        poses, time_s, iterations = gtsam_solve(case.graph, case.known_inliers, spec.method)
        # GTSAM's outliers by egnc's first rule, r^2 > chi2.ppf(outlier_quantile, d), at its poses.
        factors = BetweenFactors.from_graph(case.graph)
        r = factors.whitened_norms(factors.residuals(to_matrices(case.graph.dim, poses)))
        predicted = ~classify_inliers(r, ~case.known_inliers, case.graph.tangent_dim, GncOptions())
        stages = -1
    else:
        result = solve(
            case.graph,
            spec.method,
            known_inliers=case.known_inliers,
            linear_solver=linear_solver,
            gnc_options=spec.gnc_options(),
        )
        poses, time_s, iterations = result.graph.poses, result.time_s, result.iterations
        predicted, stages = ~result.inliers, len(result.stages)
    precision, recall = precision_recall(predicted, case.is_outlier)
    relative = rpe(poses, case.reference, case.graph.dim)
    return dict(
        precision=precision,
        recall=recall,
        success=success(precision, recall),
        ate=ate(poses, case.reference, case.graph.dim),
        rpe=relative.translation,
        rpe_rotation=relative.rotation,
        rpe_percent=relative.percent,
        stages=stages,
        iterations=iterations,
        time_s=time_s,
        rejected=int(np.count_nonzero(predicted)),
    )


def record_run(case: BenchCase, spec: MethodSpec, outcome: Outcome) -> RunRecord:
    """The `RunRecord` of `solve_and_score(case, spec, ...)` that ended with `outcome`."""
    common: dict[str, typing.Any] = dict(
        dataset=case.dataset,
        percent=case.percent,
        seed=case.seed,
        method=spec.label,
        wall_s=outcome.wall_s,
        loops=int(np.count_nonzero(~case.known_inliers)),
        outliers=int(np.count_nonzero(case.is_outlier)),
    )
    if outcome.status != "ok":
        return RunRecord(status=outcome.status, **common)
    return RunRecord(status="ok", **outcome.value, **common)


def describe_run(record: RunRecord) -> str:
    """One line about a run, e.g. `csail 30% seed 2 egnc: ok P 1.000 R 0.992 ATE 0.0123 m 0.41 s`."""
    seed = "" if record.seed is None else f" seed {record.seed}"
    head = f"{record.dataset} {record.percent:g}%{seed} {record.method}"
    if not record.ok:
        return f"{head}: {record.status}"
    return f"{head}: ok P {record.precision:.3f} R {record.recall:.3f} ATE {record.ate:.4g} m {record.time_s:.3f} s"
