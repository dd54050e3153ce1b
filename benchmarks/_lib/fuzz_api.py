"""Fuzz the public API with misuse: wrong argument types and values, and invalid graphs built in code.

Each case is one call that is wrong by construction (`MISUSES`): a junk value where `egnc.solve`
expects a graph, options, a method, known inliers, an init, a backend or a callback; the two
option classes swapped; `write_g2o` and `read_g2o` with junk or swapped arguments;
`marginal_covariances` of junk or of unknown ids; `subgraph_edges` and `with_poses` with
wrong-shaped arrays; and `PoseGraph`s made directly or with `dataclasses.replace` from a valid
graph with one array broken (information not positive definite, self-loops, no edges, ids
unsorted, rows out of range, shapes wrong, a zero quaternion, NaN); and the online solver
(`egnc.online`) built with junk options, given junk or inconsistent entries, asked for a result,
a checkpoint or a load with junk arguments, and `egnc.online.replay.replay` with one junk argument;
since issue 56 also ids of uint64 beyond int64 (on a graph holding the id they would wrap to), a
str where a sequence of str or ids belongs, and empty `add_*` batches. Each must end in an
`EgncError` (egnc's argument errors, `OptionError`, are `TypeError`s or `ValueError`s too) with
a one-line message, within `fuzz_core.TIME_LIMIT_S`; anything else is a bug: a `TypeError` or
`ValueError` egnc did not raise itself ("foreign error": NumPy's words, naming no argument),
another exception ("crash", e.g. an `AttributeError` from inside), a hang, a multi-line message,
or a call that returns (a "converged" result counted apart). The calls that are valid by
construction (`VALID_CALLS`: empty batches) must return; an error is a bug ("refused valid").

Run from `benchmarks/fuzz.py --target api`; `tests/test_fuzz.py` runs fewer cases.
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import egnc
from egnc.api import marginal_covariances
from egnc.errors import EgncError
from egnc.io import read_g2o, read_irl, write_g2o
from egnc.online import OnlineOptions, OnlineSolver
from egnc.online.replay import replay

from .fuzz_core import TIME_LIMIT_S, Hang, outcomes_table, time_limit
from .paths import SHIPPED_DATASETS

JUNK: tuple[object, ...] = (
    None, 0, -1, 2.5, float("nan"), True, "", "x", b"bytes", [], [1, 2], {}, {"max_iterations": 5}, (None,),
    object(), np.zeros(3), np.array([[1.0]]), np.array(["a"]), egnc.SolverOptions(), egnc.GncOptions(), print,
)  # fmt: skip
CLASSES = ("clean error", "valid call returned", "returned", "returned converged", "refused valid",
           "multi-line message", "foreign error", "crash", "hang")  # fmt: skip
BAD = CLASSES[2:]
VALID_CALLS = ("OnlineSolver: empty batch",)
"""Misuse names whose calls are valid: an empty batch is natural in a front-end's loop (issue 56)."""
UINT64_BEYOND = (np.array([2**64 - 1], dtype=np.uint64), np.array([2**63], dtype=np.uint64), [2**64 - 1],
                 np.uint64(2**64 - 1))  # fmt: skip
"""Ids NumPy would wrap to int64's negative ids (`2**64 - 1` to -1) were they converted unchecked."""


@dataclass
class ApiCase:
    """One misuse and what happened."""

    kind: str
    outcome: str


def _graph() -> egnc.PoseGraph:
    graph = egnc.read_g2o(SHIPPED_DATASETS / "grid2d_outliers.g2o")
    return graph.subgraph_edges((graph.edges < 20).all(axis=1)).with_poses(graph.poses)


def _junk(rng: random.Random, *, not_: tuple[type, ...] = ()) -> object:
    """A junk value that is not an instance of `not_`, nor None or a function (defaults and callbacks)."""
    defaults = (None, print)  # None is every optional argument's default, print a valid callback
    return rng.choice([v for v in JUNK if not isinstance(v, not_) and all(v is not d for d in defaults)])


def _broken_arrays(graph: egnc.PoseGraph, rng: random.Random) -> dict[str, object]:
    """`dataclasses.replace` changes that make the graph invalid."""
    e, n = graph.num_edges, graph.num_poses
    information = np.array(graph.information)
    choice = rng.randrange(12)
    if choice == 0:  # negative definite
        return {"information": -information}
    if choice == 1:  # one edge indefinite
        information[rng.randrange(e)] *= np.array([1.0, -1.0, 1.0])
        return {"information": information}
    if choice == 2:
        return {"information": np.zeros_like(information)}
    if choice == 3:  # only self-loops
        rows = rng.choices(range(n), k=e)
        return {"edges": np.stack([rows, rows], axis=1)}
    if choice == 4:  # no edges
        return {"edges": np.zeros((0, 2), int), "measurements": np.zeros((0, 3)), "information": np.zeros((0, 3, 3)),
                "edge_lines": np.zeros(0, int)}  # fmt: skip
    if choice == 5:
        return {"vertex_ids": np.array(graph.vertex_ids)[::-1]}
    if choice == 6:
        edges = np.array(graph.edges)
        edges[rng.randrange(e), rng.randrange(2)] = rng.choice((-1, n, 10**12))
        return {"edges": edges}
    if choice == 7:
        return {rng.choice(("poses", "measurements", "information", "fixed", "edge_lines")): np.zeros((2, 2))}
    if choice == 8:
        return {"dim": rng.choice((1, 4, "2", None, True, 2.5))}
    if choice == 9:  # NaN in a measurement or an information matrix
        name = rng.choice(("measurements", "information"))
        values = np.array(getattr(graph, name))
        values.reshape(e, -1)[rng.randrange(e), 0] = np.nan
        return {name: values}
    if choice == 10:
        return {rng.choice(("edges", "vertex_ids")): rng.choice((None, "x", [[0.5, 1.5]]))}
    return {"information": information * np.inf}


def _graph3d_zero_quaternion(rng: random.Random) -> egnc.PoseGraph:
    graph = egnc.read_g2o(SHIPPED_DATASETS / "grid3d.g2o")
    measurements = np.array(graph.measurements)
    measurements[rng.randrange(graph.num_edges), 3:] = 0.0
    return dataclasses.replace(graph, measurements=measurements)


def misuses(graph: egnc.PoseGraph, result: egnc.Result, folder: Path) -> dict[str, Callable[[random.Random], object]]:
    """Misuse name -> a function of the random generator making one wrong call."""
    path = SHIPPED_DATASETS / "grid2d.g2o"
    out = folder / "out.g2o"
    small = graph.first_poses(20)  # a replay needs every pose on an edge
    # ids -1 and -2**63 exist here: a uint64 id wrapped to them would find a vertex
    shifted = egnc.solve(dataclasses.replace(small, vertex_ids=small.vertex_ids + np.iinfo(np.int64).min), "l2")
    wrapped = egnc.solve(dataclasses.replace(small, vertex_ids=small.vertex_ids - 1), "l2")
    return {
        **_issue56_misuses(graph, result, shifted, wrapped),
        "solve: graph": lambda rng: egnc.solve(_junk(rng, not_=(str,))),  # type: ignore[arg-type]
        "solve: options": lambda rng: egnc.solve(graph, options=_junk(rng, not_=(egnc.SolverOptions,))),  # type: ignore[arg-type]
        "solve: gnc_options": lambda rng: egnc.solve(graph, gnc_options=_junk(rng, not_=(egnc.GncOptions,))),  # type: ignore[arg-type]
        "solve: options swapped": lambda rng: egnc.solve(
            graph,
            options=egnc.GncOptions(),
            gnc_options=egnc.SolverOptions(),  # type: ignore[arg-type]
        ),
        "solve: method": lambda rng: egnc.solve(graph, rng.choice(("EGNC", "gnc", "", None, 1, "l2 "))),  # type: ignore[arg-type]
        "solve: init": lambda rng: egnc.solve(graph, init=rng.choice(("none", None, 0, "File"))),
        "solve: linear_solver": lambda rng: egnc.solve(graph, linear_solver=rng.choice(("cg", None, 1, "SCIPY"))),  # type: ignore[arg-type]
        "solve: known_inliers": lambda rng: egnc.solve(
            graph,
            known_inliers=rng.choice(
                (
                    "all",
                    "",
                    np.ones(graph.num_edges - 1, bool),
                    np.ones(graph.num_edges),
                    np.arange(graph.num_edges),
                    np.ones((graph.num_edges, 1), bool),
                    [True],
                    None,
                )  # fmt: skip
            ),
        ),
        "solve: callback": lambda rng: egnc.solve(graph, **{rng.choice(("on_stage", "on_iteration")): _junk(rng)}),
        "write_g2o: swapped": lambda rng: write_g2o(str(out), graph),  # type: ignore[arg-type]
        "write_g2o: junk": lambda rng: write_g2o(_junk(rng), out),  # type: ignore[arg-type]
        "write_g2o: path": lambda rng: write_g2o(graph, _junk(rng, not_=(str,))),  # type: ignore[arg-type]
        "write_g2o: keep_edges": lambda rng: write_g2o(graph, out, keep_edges=np.ones(rng.choice((0, 3)), bool)),
        "read_g2o: path": lambda rng: read_g2o(rng.choice((graph, None, 3, [path]))),  # type: ignore[arg-type]
        "read_g2o: options": lambda rng: read_g2o(
            path, **rng.choice(({"skip_unknown": "yes"}, {"information": "repair"}, {"information": None}))
        ),
        "read_irl: path": lambda rng: read_irl(_junk(rng, not_=(str,))),  # type: ignore[arg-type]
        "marginal_covariances: result": lambda rng: marginal_covariances(rng.choice((None, graph, {}, 3))),  # type: ignore[arg-type]
        "marginal_covariances: ids": lambda rng: marginal_covariances(
            result, rng.choice(([10**9], [-5], np.array([1.5]), ["a"], [[0, 1], [2]]))
        ),
        "subgraph_edges: mask": lambda rng: graph.subgraph_edges(
            rng.choice((np.ones(graph.num_edges - 1, bool), np.ones(graph.num_edges), [True], None, "all"))
        ),
        "with_poses: poses": lambda rng: graph.with_poses(rng.choice((np.zeros((2, 3)), np.zeros(3), None, "x"))),
        "PoseGraph: replace": lambda rng: egnc.solve(dataclasses.replace(graph, **_broken_arrays(graph, rng))),
        "PoseGraph: direct": lambda rng: egnc.solve(
            egnc.PoseGraph(**{**_fields(graph), **_broken_arrays(graph, rng)})  # type: ignore[arg-type]
        ),
        "PoseGraph: zero quaternion": lambda rng: egnc.solve(_graph3d_zero_quaternion(rng)),
        "OnlineSolver: dim": lambda rng: OnlineSolver(_junk(rng)),  # type: ignore[arg-type]
        "OnlineSolver: method": lambda rng: OnlineSolver(2, rng.choice(("EGNC", "gnc-gm", "", None, 1, np.zeros(2)))),  # type: ignore[arg-type]
        "OnlineSolver: options": lambda rng: OnlineSolver(
            2,
            **{
                rng.choice(("options", "gnc_options", "online_options", "linear_solver")): _junk(
                    rng, not_=(str, egnc.SolverOptions, egnc.GncOptions)
                )
            },
        ),
        "OnlineOptions: field": lambda rng: OnlineOptions(**_bad_online_option(rng)),
        "OnlineSolver: add": lambda rng: rng.choice(_bad_additions())(_online()),
        "replay: arguments": lambda rng: replay(
            small,
            **rng.choice(
                (
                    {"known_inliers": rng.choice(("all", [True], np.ones(3), [[0, 1], [2]]))},
                    {"checkpoint_every": rng.choice((0, 2.5, None, "5", True))},
                    {"stop_after": rng.choice((-1, 1.5, "3", np.zeros(2)))},
                    {"checkpoint": rng.choice((3, b"x", [folder], object()))},
                    {"on_step": rng.choice((1, "print", [print]))},
                    {"method": rng.choice(("gnc-gm", None, 1))},
                )
            ),
        ),
        "OnlineSolver: result, save, load": lambda rng: rng.choice(
            (
                lambda solver: solver.result(decide=_junk(rng, not_=(bool,))),
                lambda solver: solver.save(_junk(rng, not_=(str,))),
                lambda solver: solver.save(
                    folder / "state.npz", meta=rng.choice(([1], "x", {"a": object()}, {"b": b"x"}))
                ),
                lambda solver: OnlineSolver.load(rng.choice((_junk(rng, not_=(str,)), path, folder / "none.npz"))),
            )
        )(_online()),
    }


def _issue56_misuses(
    graph: egnc.PoseGraph, result: egnc.Result, shifted: egnc.Result, wrapped: egnc.Result
) -> dict[str, Callable[[random.Random], object]]:
    """Issue 56's misuses: uint64 ids beyond int64, a str for a sequence, empty batches (valid)."""
    eye = np.eye(3)
    return {
        "marginal_covariances: uint64 ids": lambda rng: marginal_covariances(
            rng.choice((shifted, wrapped)), rng.choice(UINT64_BEYOND)
        ),
        "PoseGraph: str for a sequence": lambda rng: egnc.PoseGraph(
            **{**_fields(graph), "unknown_lines": rng.choice(("LANDMARK 1 2", b"LANDMARK", "", "\n"))}
        ),
        "str for ids": lambda rng: rng.choice(
            (
                lambda: marginal_covariances(result, rng.choice(("0", "01", b"0"))),
                lambda: _online().add_poses(rng.choice(("2", "23", b"2")), None),
                lambda: _online().add_loops(rng.choice(("01", "0 1")), [[1.0, 0.0, 0.0]], [eye]),
            )
        )(),
        "OnlineSolver: uint64 ids": lambda rng: rng.choice(
            (
                lambda solver: solver.add_loop(
                    rng.choice((2**63, 2**64 - 1, np.uint64(2**63))), 0, [1.0, 0.0, 0.0], eye
                ),
                lambda solver: solver.add_pose(rng.choice(UINT64_BEYOND[3:] + (2**63,))),
                lambda solver: solver.add_loops(np.array([[2**63, 0]], dtype=np.uint64), [[1.0, 0.0, 0.0]], [eye]),
                lambda solver: solver.add_poses(rng.choice(UINT64_BEYOND[:3])),
            )
        )(_online()),
        "OnlineSolver: empty batch": lambda rng: rng.choice(
            (
                lambda solver: solver.add_loops([], [], []),
                lambda solver: solver.add_odometry_batch([], [], []),
                lambda solver: solver.add_poses([], rng.choice(([], None, np.zeros((0, 3))))),
                lambda solver: solver.add_loops(np.zeros((0, 2), int), np.zeros((0, 3)), np.zeros((0, 3, 3))),
            )
        )(_online()),
    }


def _online() -> OnlineSolver:
    """A 2D online solver holding two poses and their odometry, updated."""
    solver = OnlineSolver(2)
    solver.add_prior(0, [0.0, 0.0, 0.0])
    solver.add_odometry(0, 1, [1.0, 0.0, 0.0], np.eye(3))
    solver.update()
    return solver


def _bad_online_option(rng: random.Random) -> dict[str, object]:
    """One `OnlineOptions` field with a value of the wrong type or out of range."""
    bad = {
        "regraduate": ("all", None, 1, np.zeros(2)),
        "low_quantile": (0.0, 1.0, -1, "0.25", None, np.nan, np.zeros((2, 2))),
        "high_quantile": (0.1, 1.5, None, True),  # 0.1: below the default low_quantile
        "stage_iterations": (0, 2.5, "1", True),
        "strong_at_arrival": ("yes", 1, None, np.zeros(2)),
        "decide_at_arrival": ("no", 0, None),
        "rel_cost_tol": (1.0, -1e-4, np.nan, "1e-4", None),
        "region_hops": (0, -1, 2.5, True, "8"),
        "boundary_share": (-1e-3, 1.5, np.inf, np.nan, "1e-3", None, True),
    }
    name = rng.choice(sorted(bad))
    return {name: rng.choice(bad[name])}


def _bad_additions() -> tuple[Callable[[OnlineSolver], object], ...]:
    """Wrong `add_*` calls on a solver holding poses 0 and 1."""
    eye = np.eye(3)
    return (
        lambda solver: solver.add_pose(1, [0.0, 0.0, 0.0]),  # already added
        lambda solver: solver.add_pose(5, {"x": 1.0}),  # type: ignore[arg-type]
        lambda solver: solver.add_poses([5, 6], [[0.0, 0.0, 0.0], [1.0]]),  # ragged
        lambda solver: solver.add_odometry([1, 2], 3, [1.0, 0.0, 0.0], eye),
        lambda solver: solver.add_odometry(1, 2, "x", eye),
        lambda solver: solver.add_odometry(1, 2, [1.0, 0.0, 0.0], np.full((3, 3), np.nan)),
        lambda solver: solver.add_odometry(1, 2, [1.0, 0.0, 0.0], -eye),
        lambda solver: solver.add_loop(0, 99, [1.0, 0.0, 0.0], eye),  # unknown pose
        lambda solver: solver.add_loop(0, 1.5, [1.0, 0.0, 0.0], eye),  # type: ignore[arg-type]
        lambda solver: solver.add_loops(0, [[1.0, 0.0, 0.0]], [eye]),
        lambda solver: solver.add_loops([[0, 1]], [[1.0, 0.0]], [eye]),
        lambda solver: solver.add_prior(1, [0.0, 0.0, 0.0]),  # a second prior
        lambda solver: OnlineSolver(3).add_prior(0, [0.0] * 7),  # a zero quaternion
    )


def _fields(graph: egnc.PoseGraph) -> dict[str, object]:
    return {field.name: getattr(graph, field.name) for field in dataclasses.fields(graph)}


def run_case(call: Callable[[random.Random], object], rng: random.Random) -> str:
    """Make one wrong call and classify what happened."""
    try:
        with time_limit(TIME_LIMIT_S):
            returned = call(rng)
    except Hang:
        return "hang"
    except EgncError as error:
        return "clean error" if "\n" not in str(error) else "multi-line message"
    except (TypeError, ValueError):  # from NumPy or Python inside egnc: it names no argument
        return "foreign error"
    except Exception:  # noqa: BLE001 - the class of failure is the finding
        return "crash"
    converged = isinstance(returned, egnc.Result) and returned.converged
    return "returned converged" if converged else "returned"


def classify(name: str, outcome: str) -> str:
    """The class of `outcome` for the misuse `name`: a valid call (`VALID_CALLS`) must return."""
    if name not in VALID_CALLS:
        return outcome
    return "valid call returned" if outcome.startswith("returned") else "refused valid"


def fuzz_api(cases: int, seed: int, folder: Path) -> list[ApiCase]:
    """Run `cases` misuses, cycling over `misuses` in a seeded random order."""
    rng = random.Random(seed)
    graph = _graph()
    calls = misuses(graph, egnc.solve(graph, "l2"), folder)
    names = sorted(calls)
    chosen = (rng.choice(names) for _ in range(cases))
    return [ApiCase(name, classify(name, run_case(calls[name], rng))) for name in chosen]


def table(results: list[ApiCase]) -> str:
    """Markdown: per misuse, the calls made by outcome class."""
    return outcomes_table(((case.kind, case.outcome) for case in results), CLASSES, "calls", "misuse")


def run_target(cases: int, seed: int) -> tuple[str, int]:
    """The API target for `fuzz.py`: its table and the number of cases that are bugs."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        results = fuzz_api(cases, seed, Path(folder))
    return table(results), sum(case.outcome in BAD for case in results)
