"""The online solver's state to and from a checkpoint file (`egnc.io.checkpoint`'s format).

A checkpoint holds the solver's settings (JSON: its arguments, gauge, update count) and the map's
arrays, its measurement priors' among them (a checkpoint written before priors holds none and
loads as one). The factorized map of `OnlineOptions.decide_at_arrival` is not stored: it is
rebuilt on load from the state it was factorized at (its first poses and edges, and its trusted
edges).
"""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

from egnc.errors import OptionError
from egnc.graph.checks import check_instance
from egnc.io.checkpoint import CHECKPOINT_VERSION, read_checkpoint, write_checkpoint
from egnc.nonlinear.least_squares import SolverOptions
from egnc.online.arrival import ConvergedMap
from egnc.online.options import OnlineOptions, Settings
from egnc.online.report import UpdateLog
from egnc.online.state import MapState
from egnc.robust.gnc import GncOptions

__all__ = ["check_destination", "read_state", "restore_state", "solver_arguments", "write_state"]


def check_destination(path: str | Path, meta: dict | None) -> None:
    """Refuse a `path` that is not a file path and a `meta` that is not a dict (`OptionError`)."""
    check_instance("path", path, (str, os.PathLike), "a file path")
    if not os.fspath(path):
        raise OptionError("path must name a file, got ''")
    check_instance("meta", {} if meta is None else meta, dict)


def write_state(
    path: str | Path,
    meta: dict | None,
    settings: Settings,
    state: MapState,
    log: UpdateLog,
    converged: ConvergedMap | None,
) -> None:
    """Write the solver's whole state to `path` (NumPy `.npz`), atomically, with `meta` (JSON data).

    Raises:
        OptionError: `meta` holds what JSON cannot (nothing is written).
    """
    saved = {
        "version": CHECKPOINT_VERSION,
        "dim": settings.dim,
        "method": settings.method,
        "linear_solver": settings.linear_solver,
        "options": asdict(settings.options),
        "gnc_options": asdict(settings.gnc_options),
        "online_options": asdict(settings.online_options),
        "gauge": state.gauge,
        "has_prior": state.has_prior,
        "steps": log.steps,
        "last_status": log.last_status,
        "converged_poses": None if converged is None else converged.num_poses,
        "meta": {} if meta is None else meta,
        "known_inliers": settings.known_inliers,
    }
    arrays = {
        "vertex_ids": state.vertex_ids,
        "T": state.T,
        "T_initial": state.T_initial,
        "edges": state.edges,
        "measurements": state.measurements,
        "Z_inv": state.Z_inv,
        "information": state.information,
        "robust": state.robust,
        "mu": state.mu,
        "mu_init": state.mu_init,
        "r": state.r,
        "converged_trusted": np.zeros(0, dtype=bool) if converged is None else converged.trusted,
        "update_ms": np.array(log.update_ms),
        "update_iterations": np.array(log.update_iterations, dtype=np.int64),
    }
    priors = state.priors
    if len(priors):  # a map without priors writes the arrays it always did
        arrays.update(
            prior_rows=priors.rows,
            prior_kinds=priors.kinds,
            prior_measurements=priors.measurements,
            prior_information=priors.information,
        )
    try:
        write_checkpoint(Path(path), saved, arrays)
    except (TypeError, ValueError) as error:
        raise OptionError(f"meta must hold only JSON data (dicts, lists, strings, numbers): {error}") from None


def read_state(path: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """The settings and arrays of the checkpoint `path`, checked (`egnc.io.checkpoint.read_checkpoint`)."""
    check_instance("path", path, (str, os.PathLike), "a file path")
    return read_checkpoint(Path(path))


def solver_arguments(saved: dict) -> dict:
    """The arguments of `OnlineSolver` from a checkpoint's settings `saved`.

    Raises:
        TypeError: an option set is not a mapping or names an unknown option.
        EgncError: an option's value is refused.
    """
    return {
        "dim": saved["dim"],
        "method": saved["method"],
        "linear_solver": saved["linear_solver"],
        "options": SolverOptions(**saved["options"]),
        "gnc_options": GncOptions(**saved["gnc_options"]),
        "online_options": OnlineOptions(**saved["online_options"]),
        "known_inliers": saved["known_inliers"],
    }


def restore_state(saved: dict, arrays: dict[str, np.ndarray], state: MapState, log: UpdateLog) -> None:
    """Put a checkpoint's settings `saved` and `arrays` into a new solver's `state` and `log`."""
    state.vertex_ids = arrays["vertex_ids"]
    state.row = {vertex_id: row for row, vertex_id in enumerate(state.vertex_ids.tolist())}
    state.T, state.T_initial = arrays["T"], arrays["T_initial"]
    state.edges, state.measurements = arrays["edges"], arrays["measurements"]
    state.Z_inv, state.information = arrays["Z_inv"], arrays["information"]
    state.robust, state.mu, state.mu_init = arrays["robust"], arrays["mu"], arrays["mu_init"]
    state.loops = np.flatnonzero(state.robust)
    state.r = arrays["r"]
    state.gauge, state.has_prior = saved["gauge"], saved["has_prior"]
    if "prior_rows" in arrays:
        state.priors.append(
            arrays["prior_rows"].astype(np.int64),
            arrays["prior_kinds"].astype(np.int8),
            arrays["prior_measurements"],
            arrays["prior_information"],
        )
    # The priors free the held pose once they pin the map, and only then (`egnc.online.priors`).
    state.gauge_free = not state.has_prior and state.priors.pin_the_map()
    log.update_ms = arrays["update_ms"].tolist()
    log.update_iterations = arrays["update_iterations"].tolist()
    log.steps, log.last_status = saved["steps"], saved["last_status"]
