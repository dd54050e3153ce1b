"""`egnc-solve` names the `rslab` and `cholmod` extras when `auto` leaves a large graph to SciPy's SuperLU."""

from __future__ import annotations

import numpy as np
import pytest
from test_import import run_without_optional

from egnc.cli.solve import CHOLMOD_HINT_MIN_POSES, cholmod_hint
from egnc.graph import PoseGraph
from egnc.io import write_g2o

INSTALL = 'pip install "egnc[cholmod]"'
PIP_ONLY = 'pip install "egnc[rslab]"'


def chain(dim: int, num_poses: int) -> PoseGraph:
    """`num_poses` poses at the origin joined by identity odometry: a graph as cheap as its size allows."""
    size, tangent = (3, 3) if dim == 2 else (7, 6)
    identity = np.zeros(size)
    if dim == 3:
        identity[-1] = 1.0  # qw
    return PoseGraph(
        dim=dim,
        vertex_ids=np.arange(num_poses),
        poses=np.tile(identity, (num_poses, 1)),
        edges=np.stack([np.arange(num_poses - 1), np.arange(1, num_poses)], axis=1),
        measurements=np.tile(identity, (num_poses - 1, 1)),
        information=np.tile(np.eye(tangent), (num_poses - 1, 1, 1)),
    )


@pytest.mark.parametrize("dim", [2, 3])
def test_hint_from_the_measured_size_on_only_for_auto_without_a_sparse_cholesky(dim):
    threshold = CHOLMOD_HINT_MIN_POSES[dim]
    large, small = chain(dim, threshold), chain(dim, threshold - 1)
    hint = cholmod_hint(large, "auto", cholesky_installed=False)
    assert hint is not None and INSTALL in hint and PIP_ONLY in hint and "libsuitesparse-dev" in hint
    assert f"{threshold}-pose {dim}D graph" in hint
    assert cholmod_hint(small, "auto", cholesky_installed=False) is None
    assert cholmod_hint(large, "auto", cholesky_installed=True) is None
    assert cholmod_hint(large, "scipy", cholesky_installed=False) is None  # asked for by name


def test_egnc_solve_prints_the_hint_once_and_not_under_quiet(tmp_path):
    graph = tmp_path / "large3d.g2o"
    write_g2o(chain(3, CHOLMOD_HINT_MIN_POSES[3]), graph)
    small = tmp_path / "small3d.g2o"
    write_g2o(chain(3, 50), small)
    run = run_without_optional(
        f"""
        import sys
        from egnc.cli.solve import main

        for args in (["--method", "l2"], ["--method", "l2", "-q"], ["--method", "l2", "--linear-solver", "scipy"]):
            print("run", args, file=sys.stderr)
            assert main([{str(graph)!r}, "--max-iters", "0", *args]) == 0
        print("run small", file=sys.stderr)
        assert main([{str(small)!r}, "--method", "l2"]) == 0
        """
    )
    assert run.returncode == 0, run.stderr
    hints = [line for line in run.stderr.splitlines() if line.startswith(("hint", "run"))]
    assert len(hints) == 5, run.stderr
    assert hints[0] == "run ['--method', 'l2']"
    assert hints[1].startswith("hint: neither rslab nor scikit-sparse is installed") and hints[1].endswith(INSTALL)
    assert hints[2:] == [
        "run ['--method', 'l2', '-q']",
        "run ['--method', 'l2', '--linear-solver', 'scipy']",
        "run small",
    ]
