"""egnc: robust pose-graph optimization with Efficient Graduated Non-Convexity.

Public API: `solve` a pose graph (or a g2o file) into a `Result`; `read_g2o` / `write_g2o`;
`SolverOptions` and `GncOptions`; the `PoseGraph` container; the `EgncError` hierarchy.
"""

# Underscored: the package namespace holds only the public API (`__all__`), not its helpers.
import sys as _sys

if _sys.version_info < (3, 10):  # noqa: UP036 - pip checks requires-python, a source tree does not
    raise ImportError(f"egnc needs Python 3.10 or newer; this is Python {_sys.version.split()[0]}")

from egnc.api import Result, StageReport, marginal_covariances, solve
from egnc.errors import EgncError, EgncWarning, G2oFormatError, GraphError, NumericalError, SolverError
from egnc.gnc import GncOptions
from egnc.graph import PoseGraph
from egnc.io import read_g2o, write_g2o
from egnc.least_squares import SolverOptions


def _installed_version() -> str:
    """The version pip recorded for egnc; pyproject.toml is the one place it is written."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("egnc")
    except PackageNotFoundError:  # imported from a source tree that was never installed
        return "0+unknown"


__version__ = _installed_version()

__all__ = [
    "EgncError",
    "EgncWarning",
    "G2oFormatError",
    "GncOptions",
    "GraphError",
    "NumericalError",
    "PoseGraph",
    "Result",
    "SolverError",
    "SolverOptions",
    "StageReport",
    "__version__",
    "marginal_covariances",
    "read_g2o",
    "solve",
    "write_g2o",
]
