"""Sparse symmetric positive-definite solvers for the normal equations, behind one interface.

`cholmod` and `scipy` order the unknowns once, at the level of the `d x d` pose blocks
(`block_order`): the normal-equations pattern is then built in that order, and every
factorization uses it as is. A block ordering is cheaper to compute than a scalar one (N instead
of d N vertices) and keeps each pose's `d` unknowns together, which suits supernodes. `rslab`
orders the scalar matrix itself.

- `cholmod`: CHOLMOD through scikit-sparse (optional extra). AMD on the pose graph, or METIS
  (nested dissection) from `METIS_MIN_BLOCKS` free poses on, where its lower fill repays its
  slower ordering (when the CHOLMOD build has METIS; else AMD). The symbolic factorization is
  computed once per pattern and each solve only refactorizes numerically (supernodal or
  simplicial, as CHOLMOD decides from the flop count). CHOLMOD reads the lower triangle only, so
  the pattern stores just that. The calls run on the calling thread only
  (`serial_native_threads`): CHOLMOD 5.x scatters each supernode in an OpenMP loop with a
  compiled-in team of 4 threads, far too little work for a fork/join per supernode, and
  OpenBLAS's worker threads must be woken for every call after the NumPy phases of an iteration.
  On 2 shared cores each doubled the factorization (see BENCHMARKS.md).
- `rslab`: the supernodal `L D L^T` of the rslab package (optional extra, a Rust wheel that
  `pip install` alone brings, no system library). Its analysis (its own fill-reducing ordering
  of the scalar matrix, elimination tree, supernodes) is computed once per pattern and each
  solve refactorizes numerically, on the calling thread. It reads the lower triangle. A factor
  with a negative or zero pivot is reported as not positive definite.
- `scipy`: SuperLU through `scipy.sparse.linalg.splu` in symmetric mode (diagonal pivoting),
  which is how SuperLU is best used on SPD matrices. Its minimum-degree ordering on `A + A^T`
  is computed once on the pose graph and then postordered (`postorder`); the factorizations
  take the matrix in that order instead of reordering it every time. Computing it factorizes
  the pose graph (`orders_by_factorizing`), so it waits for a system's first factorization. The postorder matters:
  SuperLU finds its supernodes among consecutive columns but, in symmetric mode, does not
  postorder the elimination tree itself; with the same fill, a 100k-pose grid factorizes 7x
  faster (BENCHMARKS.md, issue 18). SuperLU's factorizations and solves run on the calling
  thread, as CHOLMOD's do (`serial_native_threads`): a solve with many right-hand sides calls
  the OpenBLAS bundled with SciPy for every supernode, and waking its worker for each call took
  about 100x the arithmetic on 2 shared cores (BENCHMARKS.md, issue 18). SciPy has no sparse
  Cholesky; this is the always-available fallback.

A factorization solves (`Factorization.__call__`) and, for `cholmod` and `scipy`, exposes its
factor as sparse arrays (`Factorization.triangular`, a `TriangularFactor`), which
`egnc.nonlinear.marginals` uses to solve only the part of a triangular system a few columns reach.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any, Literal, Protocol

import numpy as np
import scipy.sparse as sp

from egnc.errors import OptionError, SolverError
from egnc.graph.checks import check_instance
from egnc.graph.index_sets import sorted_unique

LinearSolverName = Literal["auto", "cholmod", "rslab", "scipy"]
LINEAR_SOLVERS = ("auto", "cholmod", "rslab", "scipy")
"""The `linear_solver` names `resolve_name` accepts (`egnc-solve --linear-solver`)."""
Backend = Literal["cholmod", "rslab", "scipy"]
"""A resolved backend name."""
_INSTALL = {
    "cholmod": "scikit-sparse: pip install 'egnc[cholmod]' (after apt-get install libsuitesparse-dev)",
    "rslab": "rslab: pip install 'egnc[rslab]'",
}


METIS_MIN_BLOCKS = 200_000
"""From this many unknown blocks (free poses) on, the `cholmod` block order is METIS's instead of
AMD's. On generated 2D grids a factorization with the METIS order took 0.77x the AMD one's time at
250k poses and 0.5-0.6x at 500k and 1M (16 % less fill), for an ordering that costs 0.7-6 s more
once per pattern; at 100k the two factorize alike (BENCHMARKS.md, issue 18)."""


class NotPositiveDefiniteError(SolverError):
    """The (damped) normal-equations matrix could not be factorized."""


@dataclass(frozen=True, eq=False)
class TriangularFactor:
    """A factorization `A = P^T L D L^T P` as sparse arrays.

    Attributes:
        lower: `(n, n)` CSC lower-triangular `L` with sorted row indices and its diagonal stored.
        order: `(n,)` the unknown at each elimination position: `(P x)[k] = x[order[k]]`.
        pivots: `(n,)` the diagonal of `D`, or None for `A = P^T L L^T P`.
    """

    lower: sp.csc_matrix
    order: np.ndarray
    pivots: np.ndarray | None


class Factorization(Protocol):
    """One numeric factorization of `A`: `rhs -> A^-1 rhs` (`rhs` `(n,)` or `(n, k)`), and its factor."""

    def __call__(self, rhs: np.ndarray) -> np.ndarray: ...

    def triangular(self, build: bool = True) -> TriangularFactor | None:
        """The factor as sparse arrays (computed on the first call), or None where the backend
        does not expose it; with `build=False`, None also where it has not been computed yet."""
        ...


class LinearSolver(Protocol):
    """Solves `A x = b` for matrices that all share one CSC pattern."""

    name: str

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the matrix with CSC values `data` `(nnz,)` and return `x` `(n,)`."""
        ...

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the matrix with CSC values `data` `(nnz,)`."""
        ...


def cholmod_available() -> bool:
    """Whether scikit-sparse's CHOLMOD wrapper can be imported (imported already, or found)."""
    # find_spec searches the import path (0.25 ms), and every Problem resolves its backend.
    return sys.modules.get("sksparse") is not None or importlib.util.find_spec("sksparse") is not None


def rslab_available() -> bool:
    """Whether the rslab package can be imported (imported already, or found)."""
    return sys.modules.get("rslab") is not None or importlib.util.find_spec("rslab") is not None


def resolve_name(name: str) -> Backend:
    """Turn `"auto"` into the fastest available backend; reject unknown or missing backends.

    `"auto"` prefers `cholmod`, then `rslab`, then `scipy` (BENCHMARKS.md, issue 18).
    """
    check_instance("linear_solver", name, str, "a backend name (str)")
    if name == "auto":
        return "cholmod" if cholmod_available() else "rslab" if rslab_available() else "scipy"
    if name == "cholmod":
        if not cholmod_available():
            raise OptionError(f"linear solver 'cholmod' needs {_INSTALL['cholmod']}")
        return "cholmod"
    if name == "rslab":
        if not rslab_available():
            raise OptionError(f"linear solver 'rslab' needs {_INSTALL['rslab']}")
        return "rslab"
    if name == "scipy":
        return "scipy"
    raise OptionError(f"unknown linear solver {name!r}: choose 'auto', 'cholmod', 'rslab' or 'scipy'")


def lower_triangle_only(name: str) -> bool:
    """Whether backend `name` reads only the lower triangle of the matrix (so patterns store just that)."""
    return name in ("cholmod", "rslab")


def orders_by_factorizing(name: str) -> bool:
    """Whether `block_order` for backend `name` factorizes the pose graph numerically (SuperLU
    factorizes what it orders), so that it is best left to a system's first factorization."""
    return name == "scipy"


def _matrix(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray) -> sp.csc_matrix:
    n = len(indptr) - 1
    return sp.csc_matrix((data, indices, indptr), shape=(n, n), copy=False)


_LOADED: dict[str, ctypes.CDLL] = {}
_CHOLMOD_MODULE = "sksparse.cholmod"
_SUPERLU_MODULE = "scipy.sparse.linalg"  # imports SuperLU, which links that OpenBLAS


def _loaded_library(name: str) -> ctypes.CDLL | None:
    """A handle on shared library `name` if something (CHOLMOD, SciPy) already loaded it, else None.

    Handles are cached (creating one costs about 0.1 ms, comparable to a small factorization).
    """
    if name not in _LOADED:
        try:
            _LOADED[name] = ctypes.CDLL(name, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except (OSError, AttributeError):  # not loaded, or no RTLD_NOLOAD on this platform
            return None
    return _LOADED[name]


def _scipy_openblas() -> ctypes.CDLL | None:
    """A handle on the OpenBLAS bundled in SciPy's wheels (the BLAS its SuperLU calls), if SuperLU is loaded.

    SciPy's wheels ship it as `scipy.libs/libscipy_openblas*` (Linux, Windows) or
    `scipy/.dylibs/libscipy_openblas*` (macOS), with `scipy_`-prefixed symbols; a SciPy built
    against a system BLAS has none (that BLAS is `libblas.so.3`).
    """
    if _SUPERLU_MODULE not in sys.modules:
        return None
    for path in _scipy_openblas_paths():
        library = _loaded_library(path)
        if library is not None:
            return library
    return None


@cache
def _scipy_openblas_paths() -> tuple[str, ...]:
    """Paths of the OpenBLAS libraries SciPy's wheels bundle (none for a SciPy on a system BLAS)."""
    import scipy

    package = Path(scipy.__file__).parent
    candidates = [*package.parent.glob("scipy.libs/libscipy_openblas*"), *package.glob(".dylibs/libscipy_openblas*")]
    return tuple(str(path) for path in candidates)


USER_CHOSE_OPENBLAS_THREADS = "OPENBLAS_NUM_THREADS" in os.environ
"""Whether `OPENBLAS_NUM_THREADS` was set when egnc was imported: OpenBLAS reads it once, when
it loads, so a value set later (Dask's `LocalCluster` sets it in its parent) is nobody's choice."""


def _openblas_thread_counts() -> list[tuple[Callable[[], int], Callable[[int], None]]]:
    """`(get, set)` of the thread count of each loaded OpenBLAS that egnc's backends call.

    CHOLMOD's (the system `libblas.so.3`, when it is OpenBLAS; looked up only once CHOLMOD is
    imported) and SciPy's bundled one (SuperLU's). None when the user chose a count with
    `OPENBLAS_NUM_THREADS` (`USER_CHOSE_OPENBLAS_THREADS`).
    """
    if USER_CHOSE_OPENBLAS_THREADS:
        return []
    system = _loaded_library("libblas.so.3") if _CHOLMOD_MODULE in sys.modules else None
    counts = []
    for library, prefix in ((system, "openblas"), (_scipy_openblas(), "scipy_openblas")):
        if library is not None and hasattr(library, f"{prefix}_set_num_threads"):
            get, set_threads = (getattr(library, f"{prefix}_{what}_num_threads") for what in ("get", "set"))
            counts.append((get, set_threads))
    return counts


@contextmanager
def serial_native_threads() -> Iterator[None]:
    """Run the backends' OpenMP regions and OpenBLAS calls on the calling thread, then restore.

    OpenMP: `max-active-levels = 0` makes every parallel region inactive, which also overrides
    CHOLMOD's `num_threads(4)` clause (unlike `OMP_NUM_THREADS`). OpenBLAS (the `libblas.so.3`
    CHOLMOD links, when it is OpenBLAS, and the one SciPy's SuperLU calls): one thread, unless
    the user chose a count with `OPENBLAS_NUM_THREADS`. Libraries that are not loaded, or are not
    these, are left alone. Each library is looked up only once its user (CHOLMOD, SuperLU) is
    imported: a failed look-up costs 15-25 us, per call.
    """
    openmp = _loaded_library("libgomp.so.1") if _CHOLMOD_MODULE in sys.modules else None
    levels = openmp.omp_get_max_active_levels() if openmp is not None else None
    blas = [(get(), set_threads) for get, set_threads in _openblas_thread_counts()]
    if openmp is not None:
        openmp.omp_set_max_active_levels(0)
    for _, set_threads in blas:
        set_threads(1)
    try:
        yield
    finally:
        if openmp is not None:
            openmp.omp_set_max_active_levels(levels)
        for threads, set_threads in blas:
            set_threads(threads)


def _cholmod_module() -> ModuleType:
    """Import scikit-sparse's CHOLMOD wrapper, its OpenBLAS starting with one thread.

    CHOLMOD's calls run on one thread anyway (`serial_native_threads`); an OpenBLAS that starts
    with more spins its idle workers (0.1 s of system time in a one-second `egnc-solve`). The
    environment is restored at once, and a thread count the user chose is left alone.
    """
    if _CHOLMOD_MODULE not in sys.modules and "OPENBLAS_NUM_THREADS" not in os.environ:
        os.environ["OPENBLAS_NUM_THREADS"] = "1"
        try:
            from sksparse import cholmod
        finally:
            del os.environ["OPENBLAS_NUM_THREADS"]
    from sksparse import cholmod

    return cholmod


def exact_factor_pattern(lower: sp.csc_matrix) -> tuple[sp.csc_matrix, np.ndarray] | None:
    """The pattern of the Cholesky factor of a symmetric matrix with the pattern of `lower` (its
    lower triangle with every diagonal entry, CSC, in the order it is eliminated), without the
    explicit zeros a supernodal factor adds; None without CHOLMOD.

    CHOLMOD's simplicial factorization of a diagonally dominant matrix with that pattern (no
    entry cancels). Returns `(factor, order)`: `factor` `(n, n)` CSC lower triangular, diagonal
    stored, and `order` `(n,)` the column of `lower` at each of its positions (CHOLMOD postorders
    the elimination tree).
    """
    if not cholmod_available():
        return None
    cholmod = _cholmod_module()
    n = lower.shape[0]
    columns = np.repeat(np.arange(n), np.diff(lower.indptr))
    diagonal = lower.indices == columns
    assert np.count_nonzero(diagonal) == n, "every diagonal entry must be stored"
    # -1 off the diagonal, each row's count of them plus 1 on it.
    degree = np.bincount(lower.indices[~diagonal], minlength=n) + np.bincount(columns[~diagonal], minlength=n)
    values = np.where(diagonal, degree[columns] + 1.0, -1.0)
    matrix = sp.csc_matrix((values, lower.indices, lower.indptr), shape=(n, n))
    with serial_native_threads():
        factor = cholmod.cholesky(matrix, ordering_method="natural", mode="simplicial")
        return sp.csc_matrix(factor.L()), np.asarray(factor.P(), dtype=np.int64)


def _lower_block_pattern(num_blocks: int, pairs: np.ndarray) -> sp.csc_matrix:
    """The lower triangle, diagonal included, of the pattern of blocks joined by `pairs` `(K, 2)`
    (no block with itself; repeats allowed), as a `(num_blocks, num_blocks)` CSC matrix of ones
    with sorted int32 indices: what CHOLMOD's symbolic analysis reads. Built from sorted keys:
    SciPy's COO conversion, duplicate sum and triangle took as long as the ordering itself."""
    stride = max(num_blocks, 1)
    low, high = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    keys = sorted_unique(np.concatenate((low * stride + high, np.arange(num_blocks) * (stride + 1))))
    columns, rows = np.divmod(keys, stride)
    indptr = np.zeros(num_blocks + 1, dtype=np.int64)
    np.cumsum(np.bincount(columns, minlength=num_blocks), out=indptr[1:])
    index = np.int32 if len(keys) < 2**31 else np.int64
    return sp.csc_matrix((np.ones(len(keys)), rows.astype(index), indptr.astype(index)), shape=(num_blocks, num_blocks))


def block_order(name: str, num_blocks: int, block_pairs: np.ndarray) -> np.ndarray:
    """Fill-reducing order of the unknown blocks for backend `name` (the identity for `"rslab"`,
    which orders the scalar matrix itself).

    Args:
        name: resolved backend name.
        num_blocks: number of blocks (free poses).
        block_pairs: `(K, 2)` block indices joined by an edge (either direction, repeats allowed).

    Returns:
        `(num_blocks,)` permutation: block `order[k]` goes to position `k` (`P A P^T = A[order][:, order]`).
    """
    if name == "rslab":
        return np.arange(num_blocks, dtype=np.int64)
    pairs = np.asarray(block_pairs, dtype=np.int64).reshape(-1, 2)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if name == "cholmod":
        cholmod = _cholmod_module()
        lower = _lower_block_pattern(num_blocks, pairs)
        try:
            ordering = cholmod.analyze(lower, ordering_method="metis" if num_blocks >= METIS_MIN_BLOCKS else "amd")
        except cholmod.CholmodNotInstalledError:  # a CHOLMOD built without METIS
            ordering = cholmod.analyze(lower, ordering_method="amd")
        return np.asarray(ordering.P(), dtype=np.int64)
    rows, cols = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    # A diagonally dominant matrix with the pose graph's pattern: the orderings read only the
    # pattern, but SuperLU factorizes what it orders.
    adjacency = sp.csc_matrix((np.full(len(rows), -1.0), (rows, cols)), shape=(num_blocks, num_blocks))
    adjacency.sum_duplicates()
    degree = -np.asarray(adjacency.sum(axis=0)).ravel()
    matrix = (adjacency + sp.diags(degree + 1.0)).tocsc()
    from scipy.sparse.linalg import splu

    lu = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    # Diagonal pivots (threshold 0 on a diagonally dominant matrix): L's rows are in column order too.
    return np.argsort(lu.perm_c)[postorder(lu.L)].astype(np.int64)


def postorder(factor: sp.spmatrix) -> np.ndarray:
    """A postorder of the elimination tree of a Cholesky-like factor.

    The parent of column `k` is the first row below the diagonal that holds a nonzero of column
    `k` of `factor`. Reordering by a postorder keeps the fill and makes each supernode (columns
    with nested patterns) a run of consecutive columns.

    Args:
        factor: `(n, n)` lower-triangular factor (stored zeros are ignored).

    Returns:
        `(n,)` the columns in postorder: children before parents, every subtree contiguous.
    """
    # Imported here, as splu is: the CHOLMOD path never needs either (tests/test_import.py).
    from scipy.sparse.csgraph import depth_first_order

    lower = sp.tril(factor, -1, format="csc")
    lower.eliminate_zeros()
    lower.sort_indices()
    n = lower.shape[0]
    has_parent = np.diff(lower.indptr) > 0
    parent = np.full(n, n)  # n: a virtual root above the roots of the forest
    parent[has_parent] = lower.indices[lower.indptr[:-1][has_parent]]
    children = sp.csr_matrix((np.ones(n), (parent, np.arange(n))), shape=(n + 1, n + 1))
    preorder = depth_first_order(children, n, directed=True, return_predecessors=False)
    # A preorder lists each subtree contiguously, its root first: reversed, the root comes last.
    return np.asarray(preorder[:0:-1], dtype=np.int64)


_NO_VALUES = np.zeros(0)
"""What `CholmodSolver`'s matrix holds between factorizations."""


class CholmodSolver:
    """CHOLMOD Cholesky with the symbolic analysis done once.

    Attributes:
        factor: the scikit-sparse `Factor` holding the analysis (and the last factorization).
    """

    name = "cholmod"

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, ordered: bool = False):
        cholmod = _cholmod_module()
        self._cholmod = cholmod
        self._indices = indices.astype(np.int32)
        self._indptr = indptr.astype(np.int32)
        # One matrix object, its values swapped in per factorization: SciPy checks a new sparse
        # matrix's arrays (about 40 us, a tenth of a small region's factorization).
        self._values = _matrix(np.ones(len(indices)), self._indices, self._indptr)
        self.factor = cholmod.analyze(self._values, ordering_method="natural" if ordered else "default")
        self._values.data = _NO_VALUES  # between factorizations it holds no values array

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the analysed pattern with values `data` and solve for `rhs`."""
        return self.factorize(data)(rhs)

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the analysed pattern with values `data`.

        The factorization is valid until the next `factorize` (the factor is updated in place).
        """
        assert data.shape == self._indices.shape and data.dtype == np.float64, "values do not fit the pattern"
        self._values.data = data
        with serial_native_threads():
            try:
                self.factor.cholesky_inplace(self._values)
            except self._cholmod.CholmodNotPositiveDefiniteError as error:
                raise NotPositiveDefiniteError(f"normal equations are not positive definite ({error})") from None
            finally:
                self._values.data = _NO_VALUES  # keep no caller's array alive past the call
        factor = self.factor

        def solve(rhs: np.ndarray) -> np.ndarray:
            with serial_native_threads():
                return factor(rhs)

        return _Factorization(solve, lambda: _cholmod_triangular(factor))


def _cholmod_triangular(factor: Any) -> TriangularFactor:
    """`L` of `A = P^T L L^T P` from a CHOLMOD `Factor`, through a copy (converting the analysed
    factor itself would make its later factorizations simplicial)."""
    with serial_native_threads():
        lower = sp.csc_matrix(factor.copy().L())
    lower.sort_indices()
    return TriangularFactor(lower, np.asarray(factor.P(), dtype=np.int64), None)


_RSLAB_COLUMNS = 8
"""Right-hand-side columns an rslab factorization solves at once. Its `solve_many` costs the same
per column at 8 columns as at 64, and holds about seven column-sized arrays per column: 64 columns
over 300 000 unknowns peaked 0.9 GiB above 8 (BENCHMARKS.md, issue 18). It takes Fortran-ordered
columns (what a sparse matrix's `toarray` gives) without a copy."""


class RslabSolver:
    """rslab's supernodal `L D L^T` with the analysis done once, one thread."""

    name = "rslab"

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, ordered: bool = False):
        """Analyse the pattern (`ordered` is ignored: rslab chooses its own ordering)."""
        import rslab

        n = len(indptr) - 1
        columns = np.repeat(np.arange(n), np.diff(indptr))
        lower = indices >= columns
        # Data slots of the lower triangle, or None when the pattern stores only that.
        self._lower = None if lower.all() else np.flatnonzero(lower)
        rows = indices[lower].astype(np.int32)
        lower_indptr = np.concatenate([[0], np.cumsum(np.bincount(columns[lower], minlength=n))]).astype(np.int32)
        pattern = sp.csc_matrix((np.ones(len(rows)), rows, lower_indptr), shape=(n, n))
        self.symbolic = rslab.analyze(pattern, path="ldlt", threads=1)

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the analysed pattern with values `data` and solve for `rhs`."""
        return self.factorize(data)(rhs)

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the analysed pattern with values `data` (its factor is not exposed: `triangular()` is None)."""
        values = np.ascontiguousarray(data if self._lower is None else data[self._lower], dtype=np.float64)
        try:
            factor = self.symbolic.factor(values)
        except RuntimeError as error:  # rslab reports a zero pivot this way
            raise NotPositiveDefiniteError(f"normal equations are singular ({error})") from None
        _, negative, zero = factor.inertia
        if negative or zero:
            raise NotPositiveDefiniteError(
                f"normal equations are not positive definite ({negative} negative, {zero} zero pivots)"
            )

        def solve(rhs: np.ndarray) -> np.ndarray:
            if rhs.ndim == 1:
                return factor.solve(np.ascontiguousarray(rhs, dtype=np.float64))
            out = np.empty(rhs.shape)
            for start in range(0, rhs.shape[1], _RSLAB_COLUMNS):
                columns = slice(start, start + _RSLAB_COLUMNS)
                out[:, columns] = factor.solve_many(np.asfortranarray(rhs[:, columns], dtype=np.float64))
            return out

        return _Factorization(solve)


class ScipySolver:
    """SuperLU in symmetric mode; refactorizes from scratch on every solve."""

    name = "scipy"

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, ordered: bool = False):
        self._indices = indices.astype(np.int32)
        self._indptr = indptr.astype(np.int32)
        self._permc_spec = "NATURAL" if ordered else "MMD_AT_PLUS_A"
        # One matrix object, its values swapped in per factorization, as `CholmodSolver` does:
        # SciPy checks a new sparse matrix's arrays, and `splu` its index format, once.
        self._values = _matrix(np.ones(len(indices)), self._indices, self._indptr)
        self._values.data = _NO_VALUES

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Factorize the matrix with values `data` (SuperLU) and solve for `rhs`."""
        return self.factorize(data)(rhs)

    def factorize(self, data: np.ndarray) -> Factorization:
        """Factorize the matrix with values `data` (SuperLU)."""
        from scipy.sparse.linalg import splu

        assert data.shape == self._indices.shape and data.dtype == np.float64, "values do not fit the pattern"
        self._values.data = data
        try:
            with serial_native_threads():
                lu = splu(
                    self._values,
                    permc_spec=self._permc_spec,
                    diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True},
                )
        except RuntimeError as error:  # SuperLU reports an exactly singular factor this way
            raise NotPositiveDefiniteError(f"normal equations are singular ({error})") from None
        finally:
            self._values.data = _NO_VALUES  # SuperLU copied the values into its factors

        def solve(rhs: np.ndarray) -> np.ndarray:
            with serial_native_threads():
                return lu.solve(rhs)

        return _Factorization(solve, lambda: _superlu_triangular(lu))


def _superlu_triangular(lu: Any) -> TriangularFactor | None:
    """`P_r A P_c = L U` of SuperLU with diagonal pivots: `P_r = P_c` and `U = D L^T` for a
    symmetric `A` (None when a pivot left the diagonal)."""
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    lower = sp.csc_matrix(lu.L)
    lower.sort_indices()
    return TriangularFactor(lower, np.argsort(lu.perm_r).astype(np.int64), lu.U.diagonal())


class _Factorization:
    """A `Factorization` from its solve and, where the backend exposes its factor, the function
    that builds the factor's sparse arrays (called once, on the first `triangular()`)."""

    def __init__(
        self,
        solve: Callable[[np.ndarray], np.ndarray],
        build_triangular: Callable[[], TriangularFactor | None] | None = None,
    ):
        self._solve = solve
        self._build_triangular = build_triangular
        self._triangular: TriangularFactor | None = None

    def __call__(self, rhs: np.ndarray) -> np.ndarray:
        return self._solve(rhs)

    def triangular(self, build: bool = True) -> TriangularFactor | None:
        """The factor as sparse arrays, or None where the backend does not expose it (or, with
        `build=False`, has not built it yet)."""
        if build and self._triangular is None and self._build_triangular is not None:
            self._triangular = self._build_triangular()
            self._build_triangular = None  # built, or not exposed: never again
        return self._triangular


def make_linear_solver(name: str, indptr: np.ndarray, indices: np.ndarray, ordered: bool = False) -> LinearSolver:
    """Create the backend `name` (a resolved `Backend`) for one CSC pattern.

    `ordered`: the pattern is already in a fill-reducing order (`block_order`); keep it.
    """
    if name == "cholmod":
        return CholmodSolver(indptr, indices, ordered)
    if name == "rslab":
        return RslabSolver(indptr, indices, ordered)
    return ScipySolver(indptr, indices, ordered)
