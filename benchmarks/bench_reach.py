"""Readmission's joint covariance `B^T H^-1 B` by whole solves against the solve on the reach of `B`.

    python benchmarks/bench_reach.py [--grid 25000,100000] [--grid3d 20000] [--loops 64]
        [--backends cholmod,scipy] [--repeats 3]

For each generated grid (`egnc.datasets.grid_world`, seed 1, its guess as the linearization
point) `--loops` random loop closures are left out of the map, as a readmission batch is, and
`egnc.nonlinear.marginals.quadratic_form` computes their `B^T H^-1 B` (`3 --loops` columns in 2D, `6
--loops` in 3D) from one factorization of the map's information, both ways:

- `whole s`: forward and back solves of every column over all unknowns;
- `reach s`: `W = L^-1 P B` on the reach of the batch's poses only, then `W^T D^-1 W`;
- `factor s`: exposing the factor as sparse arrays (once per factorization; not in `reach s`).

`reach rows` and `reach entries` are the reach's share of the unknowns and of `L`'s stored
entries; `default` is the path `quadratic_form` takes (the reach on systems of at least
`REACH_MIN_UNKNOWNS` unknowns whose reach holds at most `REACH_MAX_SHARE` of `L`'s entries);
`max rel diff` compares the two results. Times are medians of
`--repeats`.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

import egnc.nonlinear.marginals as marginals
from egnc.datasets import grid_world
from egnc.linalg.linear_solvers import cholmod_available
from egnc.nonlinear.factors import BetweenFactors, to_matrices
from egnc.nonlinear.least_squares import Problem


def _median_time(run, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        out = run()
        times.append(time.perf_counter() - started)
    return statistics.median(times), out


def measure(dim: int, poses: int, loops: int, backend: str, repeats: int) -> dict:
    """One row: the grid of `poses` poses in `dim` D with `loops` loops left out, on `backend`."""
    graph = grid_world(dim, poses, seed=1).graph
    candidates = np.flatnonzero(graph.is_loop_closure)
    left_out = np.zeros(graph.num_edges, dtype=bool)
    left_out[np.random.default_rng(1).choice(candidates, loops, replace=False)] = True
    problem = Problem.from_graph(graph.subgraph_edges(~left_out), backend)
    matrices = to_matrices(dim, graph.poses)
    batch = BetweenFactors.from_graph(graph.subgraph_edges(left_out))
    linearization = batch.linearize(matrices)
    B = marginals.transposed_jacobians(
        problem.pattern, batch.edges, np.stack([linearization.J_e_xi, linearization.J_e_xj], axis=1)
    )
    factorization = marginals.covariance_solver(problem, matrices)
    factor_s, factor = _median_time(factorization.triangular, 1)
    if factor is None:
        raise SystemExit(f"{backend} does not expose its factor")
    whole_s, whole = _median_time(lambda: _quadratic_form(B, factorization, on_reach=False), repeats)
    reach_s, on_reach = _median_time(lambda: _quadratic_form(B, factorization, on_reach=True), repeats)
    with _gates(0, 1.0):
        reach, _ = marginals._reach_solve(factor, B)
    entries = marginals._entries(factor.lower, reach) / factor.lower.nnz
    default = problem.pattern.size >= marginals.REACH_MIN_UNKNOWNS and entries <= marginals.REACH_MAX_SHARE
    return {
        "grid": f"{dim}D {poses}",
        "backend": backend,
        "unknowns": problem.pattern.size,
        "L entries": factor.lower.nnz,
        "columns": B.shape[1],
        "reach rows": len(reach) / problem.pattern.size,
        "reach entries": entries,
        "whole s": whole_s,
        "reach s": reach_s,
        "factor s": factor_s,
        "whole / reach": whole_s / reach_s,
        "default": "reach" if default else "whole",
        "max rel diff": f"{np.abs(on_reach - whole).max() / np.abs(whole).max():.1e}",
    }


@contextmanager
def _gates(min_unknowns: float, max_share: float) -> Iterator[None]:
    """`egnc.nonlinear.marginals`' reach gates set to these values for the block."""
    saved = marginals.REACH_MIN_UNKNOWNS, marginals.REACH_MAX_SHARE
    marginals.REACH_MIN_UNKNOWNS, marginals.REACH_MAX_SHARE = min_unknowns, max_share
    try:
        yield
    finally:
        marginals.REACH_MIN_UNKNOWNS, marginals.REACH_MAX_SHARE = saved


def _quadratic_form(B, factorization, on_reach: bool) -> np.ndarray:
    """`egnc.nonlinear.marginals.quadratic_form` solved on the reach (`on_reach`) or whole, whatever the gates say."""
    with _gates(0, 1.0) if on_reach else _gates(np.inf, marginals.REACH_MAX_SHARE):
        return marginals.quadratic_form(B, factorization)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", default="25000,100000", help="2D grid pose counts")
    parser.add_argument("--grid3d", default="20000", help="3D grid pose counts")
    parser.add_argument("--loops", type=int, default=64)
    parser.add_argument("--backends", default="cholmod" if cholmod_available() else "scipy")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cases = [(2, int(n)) for n in args.grid.split(",") if n] + [(3, int(n)) for n in args.grid3d.split(",") if n]
    columns = None
    for backend in args.backends.split(","):
        for dim, poses in cases:
            row = measure(dim, poses, args.loops, backend, args.repeats)
            if columns is None:
                columns = list(row)
                print("| " + " | ".join(columns) + " |")
                print("|" + "---|" * len(columns))
            cells = [f"{value:.3f}" if isinstance(value, float) else str(value) for value in row.values()]
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
