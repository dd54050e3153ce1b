"""The public API, the version, and `import egnc` with nothing but NumPy and SciPy."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import pytest

import egnc
from egnc.linalg.linear_solvers import resolve_name

PYPROJECT = Path(__file__).parents[1] / "pyproject.toml"

# Optional dependencies (extras) that egnc must never need at import or for a SciPy solve.
OPTIONAL = ("sksparse", "rslab", "matplotlib", "gtsam")


def run_without_optional(script: str) -> subprocess.CompletedProcess:
    """Run `script` in a fresh interpreter where importing any of `OPTIONAL` fails."""
    block = "import sys\n" + "".join(f"sys.modules[{name!r}] = None\n" for name in OPTIONAL)
    return subprocess.run(
        [sys.executable, "-c", block + textwrap.dedent(script)], capture_output=True, text=True, timeout=300
    )


def test_public_api_is_reexported():
    for name in egnc.__all__:
        assert getattr(egnc, name) is not None, name
    assert {"solve", "Result", "StageReport", "SolverOptions", "PoseGraph", "read_g2o", "write_g2o",
            "EgncError", "G2oFormatError", "GraphError", "SolverError", "__version__"} <= set(egnc.__all__)  # fmt: skip
    assert issubclass(egnc.G2oFormatError, egnc.EgncError)


def test_namespace_holds_only_the_public_api():
    """`dir(egnc)` shows `__all__` and the package's own submodules, no helper (`sys`, `version`, ...)."""
    public = {
        name
        for name in dir(egnc)
        if not name.startswith("_")
        and not (isinstance(getattr(egnc, name), types.ModuleType) and getattr(egnc, name).__name__.startswith("egnc."))
    }
    assert public | {"__version__"} == set(egnc.__all__)
    for helper in ("sys", "version", "PackageNotFoundError"):
        assert not hasattr(egnc, helper), helper


def test_version_matches_pyproject():
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    if not PYPROJECT.is_file():
        pytest.skip("not run from a source checkout")
    assert egnc.__version__ == tomllib.loads(PYPROJECT.read_text())["project"]["version"]


def test_import_and_solve_with_only_numpy_and_scipy():
    grid3d = Path(__file__).parents[1] / "datasets" / "grid3d.g2o"
    run = run_without_optional(
        f"""
        import egnc
        from egnc.linalg.linear_solvers import cholmod_available, resolve_name

        assert not cholmod_available()
        assert resolve_name("auto") == "scipy", resolve_name("auto")
        result = egnc.solve({str(grid3d)!r}, "l2")
        assert result.linear_solver == "scipy" and result.converged, result.message
        print("solved", result.graph.num_poses, "poses")
        """
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "solved 300 poses"


def test_asking_for_cholmod_without_scikit_sparse_is_one_clear_error():
    grid2d = Path(__file__).parents[1] / "datasets" / "grid2d.g2o"
    run = run_without_optional(
        f"""
        import sys
        from egnc.cli.solve import main

        sys.exit(main([{str(grid2d)!r}, "--method", "l2", "--linear-solver", "cholmod"]))
        """
    )
    assert run.returncode == 1
    [line] = run.stderr.splitlines()
    assert line.startswith("egnc-solve: error: linear solver 'cholmod' needs scikit-sparse")
    assert "pip install 'egnc[cholmod]'" in line


@pytest.mark.skipif(importlib.util.find_spec("rslab") is None, reason="no rslab")
def test_auto_takes_rslab_without_scikit_sparse_and_names_the_extra_of_a_missing_backend():
    script = """
        import sys
        sys.modules["sksparse"] = None
        from egnc.errors import EgncError
        from egnc.linalg.linear_solvers import resolve_name

        assert resolve_name("auto") == "rslab"
        sys.modules["rslab"] = None
        assert resolve_name("auto") == "scipy"
        try:
            resolve_name("rslab")
        except EgncError as error:
            print(error)
        """
    run = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "linear solver 'rslab' needs rslab: pip install 'egnc[rslab]'"


# Modules a least-squares `egnc-solve -o` never uses, with what importing them costs: scipy.stats
# 0.5 s; scipy.optimize 0.1 s (mu* only); scipy.special 30-60 ms (mu*, untabulated chi-square
# quantiles); scipy.sparse.csgraph 0.1 s with the scipy.sparse.linalg and scipy.linalg it pulls in
# (to grow a spanning tree for missing poses, and on the SuperLU backend, which imports
# scipy.sparse.linalg anyway, to postorder the elimination tree).
NEVER_FOR_LEAST_SQUARES = ["scipy.stats", "scipy.optimize", "scipy.special", "scipy.sparse.csgraph", "matplotlib"]
NEVER_AT_IMPORT = [
    *NEVER_FOR_LEAST_SQUARES,
    "scipy.sparse.linalg",
    "scipy.linalg",
    "sksparse",
    "rslab",
    "egnc.datasets",
]


def imported(script: str, heavy: list[str]) -> list[str]:
    """The modules of `heavy` loaded after running `script` in a fresh interpreter."""
    check = f"import sys\nprint([name for name in {heavy!r} if name in sys.modules])"
    run = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(script) + "\n" + check], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return eval(run.stdout)


@pytest.mark.parametrize("module", ["egnc", "egnc.cli.solve"])
def test_start_up_imports_nothing_a_small_solve_does_not_use(module):
    assert imported(f"import {module}", NEVER_AT_IMPORT) == []


def test_least_squares_solve_and_write_import_nothing_they_do_not_use(tmp_path):
    grid2d = Path(__file__).parents[1] / "datasets" / "grid2d.g2o"
    script = f"""
        from egnc.cli.solve import main

        assert main([{str(grid2d)!r}, "--method", "l2", "-q", "-o", {str(tmp_path / "out.g2o")!r}]) == 0
        """
    never = NEVER_FOR_LEAST_SQUARES
    if resolve_name("auto") == "scipy":  # SuperLU's block order is postordered with csgraph
        never = [name for name in never if name != "scipy.sparse.csgraph"]
    assert imported(script, never) == []
    # A graph with poses missing grows a spanning tree, the one use of csgraph on this path.
    text = "".join(line + "\n" for line in grid2d.read_text().splitlines() if not line.startswith("VERTEX_SE2 5 "))
    (tmp_path / "missing.g2o").write_text(text)
    script = f"import egnc\negnc.read_g2o({str(tmp_path / 'missing.g2o')!r})"
    assert imported(script, ["scipy.sparse.csgraph"]) == ["scipy.sparse.csgraph"]


@pytest.mark.skipif(importlib.util.find_spec("sksparse") is None, reason="no scikit-sparse")
def test_cholmod_starts_its_openblas_single_threaded_and_restores_the_environment():
    script = """
        import ctypes, os
        import egnc
        egnc.solve(egnc.read_g2o({path!r}), "l2", linear_solver="cholmod")
        assert "OPENBLAS_NUM_THREADS" not in os.environ
        try:
            blas = ctypes.CDLL("libblas.so.3", mode=os.RTLD_NOLOAD)
        except OSError:
            blas = None
        if blas is not None and hasattr(blas, "openblas_get_num_threads"):
            assert blas.openblas_get_num_threads() == 1, blas.openblas_get_num_threads()
        print("ok")
    """.format(path=str(Path(__file__).parents[1] / "datasets" / "grid2d.g2o"))
    env = {key: value for key, value in os.environ.items() if key != "OPENBLAS_NUM_THREADS"}
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True, text=True, env=env)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
