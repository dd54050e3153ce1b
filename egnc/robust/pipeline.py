"""The outlier decision as one pipeline of named starts, each proposing a classification.

A graduated solve decides which loop closures are false in rounds on least-squares maps
(`egnc.robust.decision`). Where those rounds begin matters: from a drifted guess the GNC stage
can settle in a wrong basin that the rounds then confirm. So several starts propose a decision,
each from poses of its own, and the one of lowest truncated cost wins (`egnc.robust.costs`):

    guess ──► GNC stage ──► decision ──┐
                                       ├─► lowest truncated cost ──► Result
    each of GncOptions.starts ──► propose(search) ──► decision ──┘

Every start is an object with a `name` (what `Result.start` reports), a `description` (how
the result's message names it) and `propose(search)`, which returns its decision (or None
where it does not apply) and the reports of the solves it ran. `STARTS` holds them by name;
`GncOptions.starts` chooses which run and in what order (all of `START_NAMES` by default):

- `"runs"` (`egnc.robust.regroup.runs_start`): the GNC stage starts from the chordal map of the
  loops that come in runs, where that fits better than the guess. It must come first, since it
  chooses where the GNC stage starts; the guess's own GNC stage then runs only where the runs'
  decision rejects a whole run (the map may be bent).
- `"guess"` (always, implicit): the GNC stage from the initial guess, then the decision.
- `"chordal"` (`egnc.robust.starts.chordal_decision`): the chordal initialization of the edges
  the GNC stage trusted.
- `"chordal-all"` (`egnc.robust.starts.all_edges_decision`): the GNC stage again from the
  chordal initialization of every edge.
- `"regrouped"` (`egnc.robust.regroup.regrouped_decision`): rejected runs of loops put back.
- `"elimination"` (`egnc.robust.elimination.elimination_decision`): backward elimination from
  least squares over every edge.
- `"parts"` (`egnc.robust.parts`): where the known inliers fall into parts (two robots), one
  decision per group of agreeing loops between them, that group alone accepted between the parts.

Where the graph has priors, every chordal map (the runs', chordal, chordal-all, regrouped) is
moved onto the fixes by a trimmed rigid fit (`egnc.robust.decision.StartContext.chordal_poses`),
so it starts in their frame as the guess does. Where priors are candidates
(`egnc.robust.factor_set`) those starts classify every factor, priors included, each at its own
dimension; `"elimination"` and `"parts"` do not run: they reason about loop closures alone
(backward elimination over loops, groups of loops between parts) and do not weigh priors.

Each start after the guess tries to beat the best decision so far (`Search.best`); a decision
replaces the kept one only when lower by more than rounding
(`egnc.robust.costs.lower_by_more_than_rounding`), candidates visited in the order they were
proposed, so two starts that reach the same decision keep the earlier.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

import numpy as np

from egnc.nonlinear.least_squares import NUMERICAL_FAILURE
from egnc.robust.costs import lower_by_more_than_rounding
from egnc.robust.decision import Decision, StartContext
from egnc.robust.elimination import elimination_decision
from egnc.robust.gnc import START_NAMES, GncOutcome, StageReport, StageStart, classify_inliers
from egnc.robust.parts import part_groups
from egnc.robust.regroup import RunsStart, regrouped_decision, runs_start
from egnc.robust.starts import all_edges_decision, chordal_decision

Graduate = Callable[[np.ndarray, StageStart], GncOutcome]
"""Runs the GNC stage from `(N, n, n)` poses (the solve's schedule), its reports labelled with the start."""

Proposal = tuple[Decision | None, tuple[StageReport, ...]]
"""A start's decision (None where it does not apply or cannot beat the best so far) and the
reports of every solve it ran."""


@dataclass(eq=False)
class Search:
    """What the starts share: the graph and options, the decisions so far, every stage run.

    Attributes:
        context: the graph, its factors, options and callbacks.
        initial: `(N, n, n)` the initial guess.
        graduate: the GNC stage of the solve's method.
        first: the first GNC stage run (from the runs' map or the guess); its weights, `mu`
            and timings go into the `Result`. None before it runs.
        first_start: the start of `first`.
        runs: the runs start's map where the GNC stage began there.
        bent: whether the decision from the runs' map rejected a whole run
            (`egnc.robust.regroup.RunsStart.contradicted`).
        candidates: each start's decision by name, in the order they were proposed.
        stages: the reports of every solve run, in order.
    """

    context: StartContext
    initial: np.ndarray
    graduate: Graduate
    first: GncOutcome | None = None
    first_start: StageStart = "guess"
    runs: RunsStart | None = None
    bent: bool = False
    candidates: dict[str, Decision] = field(default_factory=dict)
    stages: tuple[StageReport, ...] = ()

    @property
    def failed(self) -> bool:
        """Whether the first GNC stage failed numerically: there is nothing to decide on."""
        return self.first is not None and self.first.status == NUMERICAL_FAILURE

    def best(self) -> Decision:
        """The decision of lowest truncated cost so far (the first of equals)."""
        return min(self.candidates.values(), key=lambda candidate: candidate.truncated_cost)

    def graduated(self, poses: np.ndarray, start: StageStart) -> Proposal:
        """The GNC stage from `poses` `(N, n, n)` and the decision from its classification; the
        first GNC stage run becomes `first`. No decision where the stage failed numerically."""
        outcome = self.graduate(poses, start)
        if self.first is None:
            self.first, self.first_start = outcome, start
        if outcome.status == NUMERICAL_FAILURE:
            return None, outcome.stages
        context = self.context
        r = context.factors.whitened_norms(context.factors.residuals(outcome.poses))
        inliers = classify_inliers(r, context.robust, context.dims, context.gnc_options)
        decision = context.decide(outcome.poses, inliers, start)
        return decision, (*outcome.stages, *decision.reports)

    def consider(self, name: str, proposal: Proposal) -> None:
        """Record a start's reports and, where it decided, its decision."""
        decision, reports = proposal
        self.stages += reports
        if decision is not None:
            self.candidates[name] = decision

    def kept(self) -> str:
        """The name of the decision kept: the first start's, unless another's truncated cost is
        lower by more than rounding (each compared with the one kept so far, in proposal order)."""
        start: str = self.first_start
        for name, candidate in self.candidates.items():
            if lower_by_more_than_rounding(candidate.truncated_cost, self.candidates[start].truncated_cost):
                start = name
        return start

    def note(self, start: str) -> str:
        """What the result's message adds about the kept decision of `start`: where it came from,
        and, when not from the first start, the truncated cost it beat."""
        first = self.first_start
        if start != first:
            kept, other = self.candidates[start].truncated_cost, self.candidates[first].truncated_cost
            return (
                f"; decision from the {DESCRIPTIONS[start]} (truncated cost {kept:.6g},"
                f" against {other:.6g} from the {DESCRIPTIONS[first]})"
            )
        return f"; decision from the {DESCRIPTIONS[first]}" if first != "guess" else ""

    def disputed(self, start: str) -> np.ndarray | None:
        """`(E,)` bool, the loops the decision of `start` rejects and another start's accepted;
        None when only one start decided."""
        if len(self.candidates) == 1:
            return None
        others = [candidate.inliers for name, candidate in self.candidates.items() if name != start]
        return self.context.robust & ~self.candidates[start].inliers & np.logical_or.reduce(others)


class Start(Protocol):
    """A strategy that proposes a decision from poses of its own (module docstring)."""

    name: ClassVar[str]
    description: ClassVar[str]

    def propose(self, search: Search) -> Proposal:
        """Its decision and the reports of its solves, given the search so far."""
        ...


class LoopRunsStart:
    """The GNC stage from the chordal map of the known inliers and the loops in runs."""

    name: ClassVar[str] = "runs"
    description: ClassVar[str] = "GNC stage from the chordal map of the loop closures in runs"

    def propose(self, search: Search) -> Proposal:
        runs = runs_start(search.context, search.initial)
        if runs is None:  # no runs, or a map no better than the guess: the guess begins
            return None, ()
        search.runs = runs
        decision, reports = search.graduated(runs.poses, "runs")
        search.bent = decision is not None and runs.contradicted(decision.inliers)  # the runs' map may be bent
        return decision, reports


class GuessStart:
    """The GNC stage from the initial guess: always, unless the runs' decision stands."""

    name: ClassVar[str] = "guess"
    description: ClassVar[str] = "initial guess"

    def propose(self, search: Search) -> Proposal:
        if search.candidates and not search.bent:
            return None, ()
        return search.graduated(search.initial, "guess")


class ChordalStart:
    """The chordal initialization of the edges the first GNC stage trusted (`egnc.robust.starts`)."""

    name: ClassVar[str] = "chordal"
    description: ClassVar[str] = "chordal initialization"

    def propose(self, search: Search) -> Proposal:
        context = search.context
        assert search.first is not None
        trusted = ~context.robust | (search.first.weights >= context.solver_options.trust_weight)
        best = search.best()
        # After a runs start the chordal start classifies at the runs' chordal map (egnc.robust.starts).
        runs_map = search.runs.poses if search.runs is not None and not search.bent else None
        return chordal_decision(context, best, trusted, runs_map)


class ChordalAllStart:
    """The GNC stage again from the chordal initialization of every edge (`egnc.robust.starts`)."""

    name: ClassVar[str] = "chordal-all"
    description: ClassVar[str] = "GNC stage run again from the chordal initialization of every edge"

    def propose(self, search: Search) -> Proposal:
        return all_edges_decision(search.context, search.best(), search.graduate)


class RegroupedStart:
    """The best decision's rejected runs of loops put back together (`egnc.robust.regroup`)."""

    name: ClassVar[str] = "regrouped"
    description: ClassVar[str] = "rejected runs of loop closures put back together"

    def propose(self, search: Search) -> Proposal:
        return regrouped_decision(search.context, search.best())


class EliminationStart:
    """Backward elimination from least squares over every edge (`egnc.robust.elimination`)."""

    name: ClassVar[str] = "elimination"
    description: ClassVar[str] = "backward elimination over every edge"

    def propose(self, search: Search) -> Proposal:
        return elimination_decision(search.context, search.best())


class PartsStart:
    """One decision per group of agreeing loops between two otherwise separate parts (`egnc.robust.parts`)."""

    name: ClassVar[str] = "parts"
    description: ClassVar[str] = "group of agreeing loop closures between two separate parts"

    def propose(self, search: Search) -> Proposal:
        context, best = search.context, search.best()
        quantile = context.gnc_options.outlier_quantile
        tried: list[np.ndarray] = [np.flatnonzero(best.inliers & context.robust)]  # best keeps these: done
        decisions: list[Decision] = []
        reports: tuple[StageReport, ...] = ()
        for backend in (None, context.linear_solver):  # groups at the best map, then at each part's own
            found = part_groups(context.graph, context.robust, best.inliers, best.poses, quantile, backend)
            if found is None or found.count < 2:  # connected known inliers, or one group only
                continue
            for group in range(found.count):
                inliers = best.inliers.copy()
                inliers[found.loops] = False
                inliers[found.members(group)] = True
                if any(np.array_equal(np.flatnonzero(inliers & context.robust), seen) for seen in tried):
                    continue
                tried.append(np.flatnonzero(inliers & context.robust))
                poses = best.poses.copy()
                poses[found.moved] = found.motions[group] @ poses[found.moved]
                decision = context.decide(poses, inliers, "parts")
                decisions.append(decision)
                reports += decision.reports
        if not decisions:
            return None, reports
        return min(decisions, key=lambda decision: decision.truncated_cost), reports


GUESS = GuessStart()
"""The start that always runs: the GNC stage from the initial guess."""

STARTS: dict[str, Start] = {
    start.name: start
    for start in (
        LoopRunsStart(),
        ChordalStart(),
        ChordalAllStart(),
        RegroupedStart(),
        EliminationStart(),
        PartsStart(),
    )
}
"""The starts `GncOptions.starts` chooses from, by name (`egnc.robust.gnc.START_NAMES`)."""
assert tuple(STARTS) == START_NAMES

LOOPS_ONLY = ("elimination", "parts")
"""The starts that do not run where priors are candidates (module docstring)."""

DESCRIPTIONS = {start.name: start.description for start in (GUESS, *STARTS.values())}
"""How a result's message names each start."""


def search_decisions(context: StartContext, initial: np.ndarray, graduate: Graduate, names: tuple[str, ...]) -> Search:
    """Run the starts `names` (`GncOptions.starts`) around the guess's GNC stage and collect their decisions.

    `"runs"`, if named, runs first; then the guess; then the others in the order named. The
    search stops after a first GNC stage that failed numerically.

    Args:
        context: the graph at its initial guess, its factors, options and callbacks.
        initial: `(N, n, n)` the initial guess.
        graduate: the GNC stage of the solve's method.
        names: the starts to run, `"runs"` first if given.
    """
    search = Search(context, initial, graduate)
    if context.with_priors:  # these starts reason about loop closures alone (module docstring)
        names = tuple(name for name in names if name not in LOOPS_ONLY)
    pipeline = [STARTS[name] for name in names]
    if pipeline[:1] == [STARTS["runs"]]:
        pipeline.insert(1, GUESS)
    else:
        pipeline.insert(0, GUESS)
    for start in pipeline:
        if search.failed:
            break
        search.consider(start.name, start.propose(search))
    return search
