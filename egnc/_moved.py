"""The old flat module names, kept importable for one release with a `DeprecationWarning`.

egnc's modules moved into packages by capability (`egnc.graph`, `egnc.linalg`, `egnc.nonlinear`,
`egnc.robust`, `egnc.online`, ...; docs/architecture.md). `import egnc.gnc` (or `from egnc.gnc
import GncOptions`) still works: a finder on `sys.meta_path` answers each old name with the module
at its new home, the same module object, after one warning that names the new home.
`egnc.graph` and `egnc.online` kept their names as packages that re-export what they held.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

MOVED = {
    "egnc.arrival": "egnc.online.arrival",
    "egnc.checks": "egnc.graph.checks",
    "egnc.chordal": "egnc.nonlinear.chordal",
    "egnc.connectivity": "egnc.graph.connectivity",
    "egnc.datasets.labels": "egnc.io.labels",
    "egnc.decision": "egnc.robust.decision",
    "egnc.diagnostics": "egnc.robust.diagnostics",
    "egnc.elimination": "egnc.robust.elimination",
    "egnc.factors": "egnc.nonlinear.factors",
    "egnc.gnc": "egnc.robust.gnc",
    "egnc.health": "egnc.graph.health",
    "egnc.index_sets": "egnc.graph.index_sets",
    "egnc.initialize": "egnc.nonlinear.initialize",
    "egnc.io.edges_csv": "egnc.cli.edges_csv",
    "egnc.kernels": "egnc.robust.kernels",
    "egnc.least_squares": "egnc.nonlinear.least_squares",
    "egnc.linear_solvers": "egnc.linalg.linear_solvers",
    "egnc.losses": "egnc.robust.losses",
    "egnc.marginals": "egnc.nonlinear.marginals",
    "egnc.mu_star": "egnc.robust.mu_star",
    "egnc.normal_equations": "egnc.linalg.normal_equations",
    "egnc.region": "egnc.online.region",
    "egnc.regroup": "egnc.robust.regroup",
    "egnc.replay": "egnc.online.replay",
    "egnc.schedules": "egnc.robust.schedules",
    "egnc.starts": "egnc.robust.starts",
    "egnc.step_solver": "egnc.linalg.step_solver",
    "egnc.validity": "egnc.graph.validity",
}
"""Old module name -> its new home. Remove in the release after next."""


class _MovedLoader(importlib.abc.Loader):
    """Loads an old name as the module at its new home (the same object, not a copy)."""

    def __init__(self, new_name: str) -> None:
        self.new_name = new_name
        self.own_spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        warnings.warn(
            f"{spec.name} moved to {self.new_name}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        module = importlib.import_module(self.new_name)
        self.own_spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # The import system has just set the module's __spec__ to the old name's: give it back its own.
        module.__spec__ = self.own_spec


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old flat names of `MOVED` and nothing else."""

    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        new_name = MOVED.get(fullname)
        if new_name is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _MovedLoader(new_name))


def install() -> None:
    """Put the finder on `sys.meta_path` once."""
    if not any(isinstance(finder, MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.append(MovedModuleFinder())
