"""egnc: robust pose-graph optimization with Efficient Graduated Non-Convexity.

Public API: `solve` a pose graph (or a g2o file) into a `Result`; `read_g2o` / `write_g2o`;
`SolverOptions` and `GncOptions`; the `PoseGraph` container; the `EgncError` hierarchy;
`from_gtsam`, a GTSAM factor graph and its values as a `PoseGraph` (the optional `gtsam` extra).

The names are loaded on first use (PEP 562 module `__getattr__`), so `import egnc` itself
imports neither NumPy nor SciPy: the console scripts (`egnc.cli.launch`) can then catch a Ctrl-C
that arrives while those load, instead of printing a traceback. Submodules (`egnc.io`,
`egnc.api`, ...) are reachable as attributes as before.
"""

# Underscored: the package namespace holds only the public API (`__all__`), not its helpers.
import sys as _sys

if _sys.version_info < (3, 10):  # noqa: UP036 - pip checks requires-python, a source tree does not
    raise ImportError(f"egnc needs Python 3.10 or newer; this is Python {_sys.version.split()[0]}")

import importlib as _importlib
import importlib.util as _importlib_util
import typing as _typing

from egnc import _moved

_moved.install()

if _typing.TYPE_CHECKING:
    from egnc.api import Result, StageReport, marginal_covariances, solve
    from egnc.errors import EgncError, EgncWarning, G2oFormatError, GraphError, NumericalError, SolverError
    from egnc.graph import PoseGraph
    from egnc.interop.gtsam import from_gtsam
    from egnc.io import read_g2o, write_g2o
    from egnc.nonlinear.least_squares import SolverOptions
    from egnc.robust.gnc import GncOptions

_HOMES = {
    "EgncError": "egnc.errors",
    "EgncWarning": "egnc.errors",
    "G2oFormatError": "egnc.errors",
    "GncOptions": "egnc.robust.gnc",
    "GraphError": "egnc.errors",
    "NumericalError": "egnc.errors",
    "PoseGraph": "egnc.graph",
    "Result": "egnc.api",
    "SolverError": "egnc.errors",
    "SolverOptions": "egnc.nonlinear.least_squares",
    "StageReport": "egnc.api",
    "from_gtsam": "egnc.interop.gtsam",
    "marginal_covariances": "egnc.api",
    "read_g2o": "egnc.io",
    "solve": "egnc.api",
    "write_g2o": "egnc.io",
}
"""The module each public name is defined in."""

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
    "from_gtsam",
    "marginal_covariances",
    "read_g2o",
    "solve",
    "write_g2o",
]


def __getattr__(name: str) -> object:
    """Import a public name, the version or a submodule on first use, and keep it."""
    if name in _HOMES:
        value = getattr(_importlib.import_module(_HOMES[name]), name)
    elif name == "__version__":
        value = _installed_version()
    elif not name.startswith("_") and _importlib_util.find_spec(f"{__name__}.{name}") is not None:
        value = _importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


def _installed_version() -> str:
    """The version pip recorded for egnc; pyproject.toml is the one place it is written."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("egnc")
    except PackageNotFoundError:  # imported from a source tree that was never installed
        return "0+unknown"
