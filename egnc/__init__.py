"""egnc: robust pose-graph optimization with Efficient Graduated Non-Convexity.

Public API: `solve` a pose graph (or a g2o file) into a `Result`; `read_g2o` / `write_g2o`;
`SolverOptions` and `GncOptions`; the `PoseGraph` container; the `EgncError` hierarchy.
"""

import sys

if sys.version_info < (3, 10):  # noqa: UP036 - pip checks requires-python, a source tree does not
    raise ImportError(f"egnc needs Python 3.10 or newer; this is Python {sys.version.split()[0]}")

from importlib.metadata import PackageNotFoundError, version

from egnc.api import Result, StageReport, marginal_covariances, solve
from egnc.errors import EgncError, EgncWarning, G2oFormatError, GraphError, NumericalError, SolverError
from egnc.gnc import GncOptions
from egnc.graph import PoseGraph
from egnc.io import read_g2o, write_g2o
from egnc.least_squares import SolverOptions

try:
    # pyproject.toml is the one place the version is written; installs record it in the metadata.
    __version__ = version("egnc")
except PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"

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
