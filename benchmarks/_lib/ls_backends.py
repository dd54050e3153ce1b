"""Sparse SPD solvers on egnc's own normal equations: ordering and analysis once, then factor and solve.

    python benchmarks/least_squares.py backends [--cases sphere2500,sphere2500-50,...]
        [--backends cholmod,scipy,...] [--repeat 5] [--budget 60]

Every case is a graph (a shared file, or a generated grid `grid2d-10k`, `grid3d-100k`, ... from
`egnc.datasets.grid_world`, seed 1), optionally with riSAM-protocol false loops (`-P` suffix: P %
of the loop closures, seed 1; the reference is the file's least-squares optimum or the grid's
ground truth). `grid3d-100k` and `grid2d-100k-10` are not in the default list: one CHOLMOD
factorization of either takes 25 s and 115 s, SuperLU's several minutes.

The case's Gauss-Newton matrix `H` and gradient are assembled by egnc (`NormalEquationsPattern`)
at the graph's initial guess, every edge with weight 1 and the gauge fixed on pose 0, so `H` is
the matrix a direct step factorizes. Each (case, backend) row runs in its own child process,
single-threaded (`OMP_NUM_THREADS`, `MKL_NUM_THREADS`, `OPENBLAS_NUM_THREADS` = 1; egnc's CHOLMOD
calls are serial anyway), and times:

- `order`: the fill-reducing block order egnc computes on the pose graph (egnc's backends only);
- `analyse`: the backend's own ordering and symbolic analysis, once per pattern (the second of two
  calls: the first also loads and initializes the library);
- `factor`: one numeric factorization, median of `--repeat` (fewer once `--budget` seconds are
  spent); for backends that cannot keep an analysis, the analysis is paid here every time;
- `solve`: the triangular solves for one right-hand side, median;
- `per step`: factor + solve, and its ratio to `cholmod` (egnc's CHOLMOD path, scikit-sparse) and
  to `scipy` (egnc's SuperLU path) measured in the same run.

`residual` is `||H x - b|| / ||b||` (`b` the negative gradient). Backends (each skipped when its
package is missing):

- `cholmod`: egnc's `CholmodSolver` on its block AMD order (scikit-sparse 0.4, apt SuiteSparse).
- `scipy`: egnc's `ScipySolver` (SuperLU, symmetric mode) on its postordered block MMD order.
- `superlu-unpostordered`: the same block MMD order without the postorder (egnc before issue 18).
- `superlu-mmd`, `superlu-colamd`: SuperLU ordering the scalar matrix at every factorization
  (`permc_spec` `MMD_AT_PLUS_A`, or SciPy's default `COLAMD` in unsymmetric mode).
- `cholespy`: CHOLMOD as the cholespy wheel bundles it; each factorization analyses again.
- `qdldl`: simplicial LDL^T with AMD; the analysis is kept (`update`) and includes one factorization.
- `rslab`: egnc's `RslabSolver` (rslab's supernodal LDL^T in Rust, its `auto` ordering, analysis
  kept, one thread).
- `pardiso`: MKL PARDISO through pypardiso, SPD mode, METIS ordering (phases 11, 22, 33).
- `pyamg`: reference only, not a direct solver: smoothed-aggregation AMG set up per matrix
  (`factor`), conjugate gradients to 1e-10 preconditioned by it (`solve`).
"""

from __future__ import annotations

import json
import os
import pickle
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .paths import ENTRIES, SHARED_DATASETS
from .processes import run_child as run_process

PACKAGES = {
    "cholmod": "sksparse",
    "cholespy": "cholespy",
    "qdldl": "qdldl",
    "rslab": "rslab",
    "pardiso": "pypardiso",
    "pyamg": "pyamg",
}
DISTRIBUTIONS = ("numpy", "scipy", "scikit-sparse", "cholespy", "qdldl", "rslab", "pypardiso", "mkl", "pyamg")
Factorize = Callable[[np.ndarray], Callable[[np.ndarray], np.ndarray]]


def make_graph(case: str):
    """The graph of `case`: `name[-percent]`, name a shared file or `grid2d-10k`, `grid3d-100k`, ..."""
    from egnc.api import solve
    from egnc.datasets import add_false_loops, grid_world
    from egnc.io import read_g2o

    name, _, percent = case.rpartition("-")
    if not percent.isdigit():
        name, percent = case, ""
    if name.startswith("grid"):
        grid = grid_world(int(name[4]), int(name.split("-")[1].removesuffix("k")) * 1000, seed=1)
        graph, reference = grid.graph, grid.ground_truth
    else:
        graph = read_g2o(SHARED_DATASETS / f"{name}.g2o")
        reference = solve(graph, "l2").graph.poses if percent else None
    if percent:
        graph = add_false_loops(graph, float(percent), seed=1, reference_poses=reference).graph
    return graph


def full_matrix(pattern, data: np.ndarray) -> sp.csc_matrix:
    """`H` with both triangles from a pattern's CSC data (lower triangle or whole)."""
    matrix = sp.csc_matrix((data, pattern.indices, pattern.indptr), shape=(pattern.size, pattern.size))
    return (matrix + sp.tril(matrix, -1).T).tocsc() if pattern.lower_only else matrix


def superlu_unpostordered(num_blocks: int, block_pairs: np.ndarray) -> np.ndarray:
    """egnc's SciPy block order before issue 18: SuperLU's MMD order, not postordered."""
    from scipy.sparse.linalg import splu

    pairs = block_pairs[block_pairs[:, 0] != block_pairs[:, 1]]
    rows, cols = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    adjacency = sp.csc_matrix((np.full(len(rows), -1.0), (rows, cols)), shape=(num_blocks, num_blocks))
    adjacency.sum_duplicates()
    matrix = (adjacency + sp.diags(-np.asarray(adjacency.sum(axis=0)).ravel() + 1.0)).tocsc()
    lu = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return np.argsort(lu.perm_c)


def backend_setup(backend: str, graph, fixed: np.ndarray):
    """`(order_s, pattern, analyse)` for `backend`; `analyse(data)` returns a `Factorize`.

    `data` is the first matrix's CSC data, for backends whose analysis reads values too.
    """
    from egnc.linalg.linear_solvers import CholmodSolver, RslabSolver, ScipySolver, block_order
    from egnc.linalg.normal_equations import NormalEquationsPattern

    free_block = np.cumsum(~fixed) - 1
    pairs = free_block[graph.edges[~fixed[graph.edges].any(axis=1)]]
    num_free = int(np.count_nonzero(~fixed))
    order = None
    started = time.perf_counter()
    if backend in ("cholmod", "scipy"):
        order = block_order(backend, num_free, pairs)
    elif backend == "superlu-unpostordered":
        order = superlu_unpostordered(num_free, pairs)
    order_s = time.perf_counter() - started if order is not None else None
    lower = backend in ("cholmod", "cholespy", "rslab", "pardiso")
    pattern = NormalEquationsPattern.build(graph.edges, fixed, graph.tangent_dim, lower_only=lower, block_order=order)
    indptr, indices, n = pattern.indptr, pattern.indices, pattern.size

    def csc(data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, indices, indptr), shape=(n, n))

    def superlu(permc_spec: str, symmetric: bool) -> Factorize:
        from scipy.sparse.linalg import splu

        def factorize(data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
            if symmetric:
                return splu(
                    csc(data), permc_spec=permc_spec, diag_pivot_thresh=0.0, options={"SymmetricMode": True}
                ).solve
            return splu(csc(data), permc_spec=permc_spec).solve

        return factorize

    def analyse(data: np.ndarray) -> Factorize:
        if backend == "cholmod":
            return CholmodSolver(indptr, indices, ordered=True).factorize
        if backend in ("scipy", "superlu-unpostordered"):
            return ScipySolver(indptr, indices, ordered=True).factorize
        if backend == "superlu-mmd":
            return superlu("MMD_AT_PLUS_A", True)
        if backend == "superlu-colamd":
            return superlu("COLAMD", False)
        if backend == "cholespy":
            return cholespy_factorize(n, indptr, indices)
        if backend == "qdldl":
            return qdldl_factorize(csc, data)
        if backend == "rslab":
            return RslabSolver(indptr, indices).factorize
        if backend == "pardiso":
            return pardiso_factorize(n, indptr, indices, data)
        if backend == "pyamg":
            return pyamg_factorize(csc)
        raise SystemExit(f"unknown backend {backend!r}")

    return order_s, pattern, analyse


def cholespy_factorize(n: int, indptr: np.ndarray, indices: np.ndarray) -> Factorize:
    """cholespy: analysis and factorization in one constructor call (lower triangle)."""
    import cholespy

    rows, cols = indptr.astype(np.int32), indices.astype(np.int32)

    def factorize(data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        solver = cholespy.CholeskySolverD(n, rows, cols, data, cholespy.MatrixType.CSC)

        def solve(rhs: np.ndarray) -> np.ndarray:
            x = np.zeros_like(rhs)
            solver.solve(np.ascontiguousarray(rhs), x)
            return x

        return solve

    return factorize


def qdldl_factorize(csc, first: np.ndarray) -> Factorize:
    """qdldl: `Solver` (AMD, symbolic and one numeric factorization) once, then `update` per matrix."""
    import qdldl

    solver = qdldl.Solver(csc(first), upper=False)

    def factorize(data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        solver.update(csc(data), upper=False)
        return solver.solve

    return factorize


def pardiso_factorize(n: int, indptr: np.ndarray, indices: np.ndarray, first: np.ndarray) -> Factorize:
    """MKL PARDISO via pypardiso: SPD (mtype 2), the lower CSC read as upper CSR; phases 11 / 22 / 33."""
    import pypardiso

    solver = pypardiso.PyPardisoSolver(mtype=2)
    solver.set_iparm(1, 1)  # iparm[0] = 1: take the values below, not PARDISO's defaults
    solver.set_iparm(2, 2)  # METIS nested dissection
    solver.set_iparm(8, 0)  # no iterative refinement
    solver.set_iparm(10, 8)  # pivot perturbation 1e-8 (symmetric default)
    solver.set_iparm(11, 0)  # no scaling
    solver.set_iparm(13, 0)  # no weighted matching
    solver.set_iparm(35, 0)
    # iparm[11] would be set by pypardiso for CSC input; passing CSR keeps it 0.

    def upper(data: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((data, indices, indptr), shape=(n, n))

    solver.set_phase(11)
    solver._call_pardiso(upper(first), np.zeros(n))

    def factorize(data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        matrix = upper(data)
        solver.set_phase(22)
        solver._call_pardiso(matrix, np.zeros(n))

        def solve(rhs: np.ndarray) -> np.ndarray:
            solver.set_phase(33)
            return solver._call_pardiso(matrix, np.asfortranarray(rhs))

        return solve

    return factorize


def pyamg_factorize(csc) -> Factorize:
    """pyamg (reference): smoothed aggregation set up per matrix; CG to 1e-10 preconditioned by it."""
    import pyamg

    def factorize(data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        matrix = csc(data).tocsr()
        hierarchy = pyamg.smoothed_aggregation_solver(matrix, symmetry="symmetric")

        def solve(rhs: np.ndarray) -> np.ndarray:
            return hierarchy.solve(rhs, tol=1e-10, accel="cg", maxiter=500)

        return solve

    return factorize


def run_case(case: str, backend: str, graph_file: str, repeat: int, budget: float) -> dict:
    """Time one backend on one case in this process (the child's side)."""
    from egnc.nonlinear.factors import BetweenFactors, to_matrices

    with open(graph_file, "rb") as stream:
        graph = pickle.load(stream)
    fixed = graph.fixed.copy()
    if not fixed.any():
        fixed[0] = True
    order_s, pattern, analyse = backend_setup(backend, graph, fixed)
    linearization = BetweenFactors.from_graph(graph).linearize(to_matrices(graph.dim, graph.poses))
    data, gradient = pattern.assemble(linearization, graph.information, np.ones(graph.num_edges))
    rhs = -gradient
    analyse(data)  # the first call also loads and initializes the backend's library
    started = time.perf_counter()
    factorize = analyse(data)
    analyse_s = time.perf_counter() - started
    factor_times, solve_times = [], []
    x = rhs
    while len(factor_times) < repeat and (not factor_times or sum(factor_times) + sum(solve_times) < budget):
        started = time.perf_counter()
        solve = factorize(data)
        factor_times.append(time.perf_counter() - started)
        started = time.perf_counter()
        x = solve(rhs)
        solve_times.append(time.perf_counter() - started)
    residual = float(np.linalg.norm(full_matrix(pattern, data) @ x - rhs) / np.linalg.norm(rhs))
    return {
        "unknowns": pattern.size,
        "nnz": 2 * pattern.nnz - pattern.size if pattern.lower_only else pattern.nnz,
        "order_s": order_s,
        "analyse_s": analyse_s,
        "factor_s": float(np.median(factor_times)),
        "solve_s": float(np.median(solve_times)),
        "repeats": len(factor_times),
        "residual": residual,
    }


def run_child(case: str, backend: str, graph_file: str, repeat: int, budget: float) -> dict | str:
    """Run one row in a child process; its figures plus peak resident memory (MiB), or why it failed."""
    child = json.dumps([case, backend, graph_file, repeat, budget])
    command = [sys.executable, str(ENTRIES / "least_squares.py"), "backends", "--child", child]
    env = os.environ | {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    run = run_process(command, env=env)
    if run.returncode != 0:
        lines = run.stderr.strip().splitlines()
        return f"failed ({lines[-1] if lines else f'exit code {run.returncode}'})"
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    figures["peak_mib"] = run.peak_mib
    return figures


def available(backend: str) -> bool:
    """Whether `backend`'s package can be imported here."""
    import importlib.util

    package = PACKAGES.get(backend)
    return package is None or importlib.util.find_spec(package) is not None


def run(cases: str, backends: str, repeat: int, budget: float) -> None:
    """Prepare every case's graph once, run every (case, backend) row in a child, print the table."""
    chosen = backends.split(",")
    backends_run = [b for b in chosen if available(b)]
    skipped = [b for b in chosen if b not in backends_run]
    from egnc.bench.report import installed_versions

    print(f"{time.strftime('%Y-%m-%d', time.gmtime())}; {installed_versions(DISTRIBUTIONS, show_absent=False)}")
    if skipped:
        print(f"not installed, skipped: {', '.join(skipped)}")
    print(
        "\n| case | unknowns | nnz(H) | backend | order (s) | analyse (s) | factor (s) | solve (s) | per step (s)"
        " | / cholmod | / scipy | residual | peak MiB |"
    )
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for case in filter(None, cases.split(",")):
            graph_file = str(Path(folder) / f"{case}.pickle")
            with open(graph_file, "wb") as stream:
                pickle.dump(make_graph(case), stream)
            per_step: dict[str, float] = {}
            for backend in backends_run:
                f = run_child(case, backend, graph_file, repeat, budget)
                if isinstance(f, str):
                    print(f"| {case} | | | {backend} | {f} | | | | | | | | |", flush=True)
                    continue
                step = f["factor_s"] + f["solve_s"]
                order = "" if f["order_s"] is None else f"{f['order_s']:.3f}"
                per_step[backend] = step
                ratios = [f"{step / per_step[b]:.2f}" if b in per_step else "" for b in ("cholmod", "scipy")]
                print(
                    f"| {case} | {f['unknowns']} | {f['nnz']} | {backend} | {order} | {f['analyse_s']:.3f}"
                    f" | {f['factor_s']:.3f} | {f['solve_s']:.4f} | {step:.3f} | {ratios[0]} | {ratios[1]}"
                    f" | {f['residual']:.1e} | {f['peak_mib']:.0f} |",
                    flush=True,
                )
