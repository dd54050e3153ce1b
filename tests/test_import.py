"""The public API, the version, and `import egnc` with nothing but NumPy and SciPy."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import egnc

PYPROJECT = Path(__file__).parents[1] / "pyproject.toml"

# Optional dependencies (extras) that egnc must never need at import or for a SciPy solve.
OPTIONAL = ("sksparse", "matplotlib", "gtsam")


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
        from egnc.linear_solvers import cholmod_available, resolve_name

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


@pytest.mark.parametrize("module", ["egnc", "egnc.cli.solve"])
def test_start_up_imports_nothing_a_small_solve_does_not_use(module):
    # scipy.stats alone cost 0.5 s of every egnc-solve; scipy.optimize is only needed for mu*.
    script = f"import sys, {module}; print(sorted(m for m in sys.modules if m.split('.')[0:2] in HEAVY))"
    heavy = "[['scipy', 'stats'], ['scipy', 'optimize'], ['matplotlib'], ['sksparse']]"
    run = subprocess.run(
        [sys.executable, "-c", f"HEAVY = {heavy}\n{script}"], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"
