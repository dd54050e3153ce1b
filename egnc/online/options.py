"""Options of the online protocol (`OnlineOptions`) and the checked settings an online solver is made with.

`Settings` bundles what `egnc.online.OnlineSolver` was given (dimension, schedule, backend, the
three option sets) once checked, with the IRLS kernel and the per-stage solver options they
imply; every part of the solver reads them from there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

from egnc.errors import EgncError, OptionError
from egnc.graph import TANGENT_SIZE, is_dim
from egnc.graph.checks import check_bool, check_choice, check_float, check_instance, check_int, describe
from egnc.linalg.linear_solvers import resolve_name
from egnc.nonlinear.least_squares import SolverOptions
from egnc.robust.gnc import GncOptions, known_inlier_kinds
from egnc.robust.kernels import Kernel, make_kernel

__all__ = ["ONLINE_METHODS", "OnlineOptions", "Settings"]

ONLINE_METHODS = ("egnc", "risam")
"""Schedules the online solver graduates new loop closures with."""


@dataclass(frozen=True)
class OnlineOptions:
    """Options of the online protocol.

    Attributes:
        regraduate: which loops an update with new loop closures graduates: `"reference"`
            (default) the new ones and every older loop whose `mu_init` is 0, as riSAM
            re-graduates the loops its update touches; `"new"` only the new ones (older loops keep
            their `mu`, 1 once graduated): fewer iterations, but the running estimate went
            astray on some logs (docs/online.md).
        low_quantile: after an update's graduation, a loop with `r^2` (or `r`, by
            `GncOptions.threshold`) below `chi2.ppf(low_quantile, d)` gets `mu_init = 0`.
        high_quantile: ... and above `chi2.ppf(high_quantile, d)` gets `mu_init = 1`: it is not
            graduated again and keeps its Geman-McClure weight, which comes back by itself if the
            map moves towards it.
        stage_iterations: at most this many solver steps per graduation stage but the last,
            which converges (to `rel_cost_tol`); None: every stage converges. riSAM and EGNC-PGO
            take one step per `mu` value (one iSAM2 update each).
        strong_at_arrival: `egnc` only: a new loop whose residual at the current (converged)
            estimate is above the strong-outlier threshold (`high_quantile`) is a strong outlier
            at once and starts at `mu = 1`, as EGNC's Algorithm 1 treats a factor found strong
            after a solve; it skips the `mu = 0` stage, where a false loop would bend the map.
            Off by default (EGNC-PGO starts every new loop at 0): drifted odometry puts true
            loops far off at arrival too (docs/online.md has the measurements).
        decide_at_arrival: `egnc` only: predict an update's first stage (one Gauss-Newton step
            with its new loops at `mu = 0`) from the map factorized after the last whole-map solve
            (`egnc.online.arrival`), and solve nothing when the update would end where it starts, with
            its new loops off (module docstring): fewer iterations and the same decisions, for a
            factorization of the map after every whole-map solve (docs/online.md says when
            that pays).
        rel_cost_tol: the last stage of an update stops when an accepted step lowers the cost
            by at most this fraction (riSAM stops at 1e-2; docs/online.md says how the default
            was chosen).
        region_hops: an update with loop closures first solves the poses within this many
            trusted edges of its new edges' ends, with their other neighbours held
            (`egnc.online.region`), and falls back to the whole map when the region's stages end a
            loop on the other side of the strong-outlier line or its boundary would still move
            (module docstring; docs/online.md has the measurements). None: every update solves
            the whole map.
        boundary_share: a region's update goes on over the whole map for its last stage when its
            boundary poses' own Newton steps (block Jacobi) would lower the cost by more than this
            share of the update's tolerance (`rel_cost_tol` times the cost). One pose at a time
            underestimates what the map's long, soft modes release, hence a small share. Larger:
            fewer whole-map stages and a lower latency, for a running estimate further from the
            whole map's optimum (docs/online.md has the measurements).
    """

    regraduate: Literal["reference", "new"] = "reference"
    low_quantile: float = 0.25
    high_quantile: float = 0.9
    stage_iterations: int | None = 1
    strong_at_arrival: bool = False
    decide_at_arrival: bool = False
    rel_cost_tol: float = 1e-4
    region_hops: int | None = 8
    boundary_share: float = 1e-3

    def __post_init__(self) -> None:
        """Check every field's type and range (`egnc.graph.checks`), storing plain Python values."""
        name = "OnlineOptions."
        checked: dict[str, object] = {
            "regraduate": check_choice(name + "regraduate", self.regraduate, ("reference", "new")),
            "rel_cost_tol": check_float(name + "rel_cost_tol", self.rel_cost_tol, 0.0, 1.0, open_high=True),
            "boundary_share": check_float(name + "boundary_share", self.boundary_share, 0.0, 1.0),
        }
        low, high = (
            check_float(name + field_name, getattr(self, field_name), 0.0, 1.0, open_low=True, open_high=True)
            for field_name in ("low_quantile", "high_quantile")
        )
        if not low < high:
            raise OptionError(f"need {name}low_quantile < {name}high_quantile, got {low} and {high}")
        checked["low_quantile"], checked["high_quantile"] = low, high
        for field_name in ("strong_at_arrival", "decide_at_arrival"):
            checked[field_name] = check_bool(name + field_name, getattr(self, field_name))
        for field_name in ("stage_iterations", "region_hops"):  # None: no limit / no region
            value = getattr(self, field_name)
            checked[field_name] = None if value is None else check_int(name + field_name, value, 1)
        for field_name, value in checked.items():
            object.__setattr__(self, field_name, value)


@dataclass(eq=False)
class Settings:
    """What an online solver was made with, checked (`make`), and what follows from it.

    Every part of the solver holds the same instance: an option set assigned to the solver
    (`OnlineSolver.online_options = ...`) applies to all of them from the next update on.
    `dim`, `d` and `kernel` are fixed when the solver is made.

    Attributes:
        dim: 2 (SE(2)) or 3 (SE(3)).
        method: a schedule of `ONLINE_METHODS`.
        linear_solver: the resolved backend name (`egnc.linalg.linear_solvers`).
        options, gnc_options, online_options: as given to `egnc.online.OnlineSolver`, defaults filled in.
        priors_known: whether measurement priors are known inliers by default (`OnlineSolver`'s
            `known_inliers` names `"priors"`); else they are candidates, as in `egnc.solve`.
        d: tangent size of a pose (3 or 6).
        kernel: the SIG kernel of shape `gnc_options.c` every loop closure is weighed with.
    """

    dim: int
    method: str
    linear_solver: str
    options: SolverOptions
    gnc_options: GncOptions
    online_options: OnlineOptions
    priors_known: bool = False
    d: int = field(init=False)
    kernel: Kernel = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.d = TANGENT_SIZE[self.dim]
        self.kernel = make_kernel("sig", c=self.gnc_options.c)

    @classmethod
    def make(
        cls,
        dim: int,
        method: str,
        linear_solver: str,
        options: SolverOptions | None,
        gnc_options: GncOptions | None,
        online_options: OnlineOptions | None,
        known_inliers: str | Sequence[str] = "odometry",
    ) -> Settings:
        """Check `egnc.online.OnlineSolver`'s arguments (its Raises) and fill in the default options."""
        if not is_dim(dim):
            raise OptionError(f"dim must be 2 or 3, got {describe(dim)}")
        check_choice("online method", method, ONLINE_METHODS)
        for name, value, kind in (
            ("options", options, SolverOptions),
            ("gnc_options", gnc_options, GncOptions),
            ("online_options", online_options, OnlineOptions),
        ):
            if value is not None:
                check_instance(name, value, kind)
        rules = ("strong_at_arrival", "decide_at_arrival")
        egnc_only = [name for name in rules if getattr(online_options, name, False)]
        if method != "egnc" and egnc_only:
            raise EgncError(f"OnlineOptions.{egnc_only[0]} applies to the egnc schedule (EGNC's strong-outlier rule)")
        return cls(
            int(dim),
            method,
            resolve_name(linear_solver),
            options or SolverOptions(),
            gnc_options or GncOptions(),
            online_options or OnlineOptions(),
            _priors_known(known_inliers),
        )

    @property
    def known_inliers(self) -> str:
        """The kinds held quadratic, as `OnlineSolver`'s `known_inliers` names them."""
        return "odometry,priors" if self.priors_known else "odometry"

    @property
    def predicts_first_stage(self) -> bool:
        """Whether updates are predicted from the factorized map (`OnlineOptions.decide_at_arrival`)."""
        return self.method == "egnc" and self.online_options.decide_at_arrival

    def stage_options(self) -> tuple[SolverOptions, SolverOptions]:
        """Options of the last stage (converged to `rel_cost_tol`) and of the stages before it."""
        tight = replace(self.options, rel_cost_tol=max(self.options.rel_cost_tol, self.online_options.rel_cost_tol))
        if self.online_options.stage_iterations is None:
            return tight, tight
        return tight, replace(tight, max_iterations=self.online_options.stage_iterations)


def _priors_known(known_inliers: object) -> bool:
    """Whether `known_inliers` (kinds, `egnc.robust.gnc.KNOWN_INLIER_KINDS`) names the priors.

    Raises:
        OptionError: not kinds (a mask has no meaning before the factors arrive), an unknown
            kind, or `"loops"` (an online solver's edges take their role from the call adding them).
    """
    if not isinstance(known_inliers, str) and not (
        isinstance(known_inliers, (tuple, list)) and all(isinstance(kind, str) for kind in known_inliers)
    ):
        raise OptionError(
            f"known_inliers of an online solver must name kinds (e.g. 'odometry,priors'), got {describe(known_inliers)}"
        )
    kinds = known_inlier_kinds(known_inliers)
    if "loops" in kinds:
        raise OptionError("an online solver's loop closures are candidates: add known-inlier edges with add_odometry")
    return "priors" in kinds
