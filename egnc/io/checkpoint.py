"""The online solver's checkpoint file: its settings (JSON) and arrays in one NumPy `.npz` archive.

`write_checkpoint` writes it atomically (the file is complete or untouched). `read_checkpoint`
reads one back and checks it before anything is built from it: an empty, foreign or damaged
file, a missing entry, or arrays whose shapes, types, values or edge indices do not fit
together give one `EgncError` naming the file, not a traceback from NumPy or from a later update.

Since version 2 the settings hold a SHA-256 `digest` of everything else in the file
(`content_digest`): a checkpoint loaded, edited (a measurement, a `robust` flag, an option) and
saved again no longer matches it and is refused, instead of resuming to another map. A version 1
checkpoint (written before the digest) is read without it; `egnc.online.replay` resumes one only
where its graph is the input's.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from egnc.errors import EgncError
from egnc.graph import POSE_SIZE, TANGENT_SIZE
from egnc.graph.index_sets import sorted_unique
from egnc.io.atomic import atomic_binary_file

CHECKPOINT_VERSION = 2
"""Format version written into every checkpoint; `read_checkpoint` reads it and version 1."""

UNDIGESTED_VERSION = 1
"""The version written before checkpoints held a `digest`; still read (module docstring)."""

SETTINGS = (
    "version", "dim", "method", "linear_solver", "options", "gnc_options", "online_options",
    "gauge", "has_prior", "steps", "last_status", "converged_poses", "meta", "digest",
)  # fmt: skip
"""The keys of a checkpoint's settings (a version 1 checkpoint has all but `digest`)."""

OPTIONAL_SETTINGS = {"known_inliers": "odometry"}
"""Settings a checkpoint written before they existed lacks, with the value it was written under."""

PRIOR_ARRAYS = ("prior_rows", "prior_kinds", "prior_measurements", "prior_information")
"""The arrays of the measurement priors (`egnc.online.priors`); a checkpoint without them holds none."""

RIGID_TOLERANCE = 1e-6
"""Largest entry of `R^T R - I` a checkpoint's pose or measurement rotation `R` may have (they are
orthonormal to about 1e-12 after many updates)."""

_ZIP_SIGNATURE = b"PK"
"""The first bytes of every zip archive, and so of every `.npz` file."""


def write_checkpoint(path: Path, settings: dict, arrays: dict[str, np.ndarray]) -> None:
    """Write `settings` (JSON data, with every key of `SETTINGS` but `digest`), their `content_digest`
    and `arrays` to `path`, atomically.

    Raises:
        TypeError, ValueError: `settings` is not JSON data (nothing is written).
        EgncError: the file cannot be written.
    """
    expected = set(SETTINGS) - {"digest"}
    assert expected <= set(settings) <= expected | set(OPTIONAL_SETTINGS), "a checkpoint's settings are SETTINGS"
    text = json.dumps({**settings, "digest": content_digest(settings, arrays)})
    with atomic_binary_file(path) as out:
        np.savez(out, settings=np.array(text), **arrays)  # type: ignore[arg-type]


def read_checkpoint(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """The settings and arrays of the checkpoint at `path`, checked (module docstring).

    Raises:
        EgncError: the file cannot be read, is not an egnc checkpoint of this version, or its
            entries do not fit together (the message names the file and the entry).
    """
    try:
        with path.open("rb") as stream:
            signature = stream.read(len(_ZIP_SIGNATURE))
    except OSError as error:
        raise EgncError(f"{path}: cannot read the checkpoint ({error.strerror or error})") from None
    if signature != _ZIP_SIGNATURE:
        kind = "an empty file" if not signature else "not a NumPy .npz archive"
        raise EgncError(f"{path}: not an egnc checkpoint ({kind})")
    try:
        with np.load(path, allow_pickle=False) as data:
            entries = {name: data[name] for name in data.files}
    except Exception as error:  # noqa: BLE001 - zipfile's, zlib's, NumPy's header parser's: all say damaged
        raise EgncError(f"{path}: damaged checkpoint ({type(error).__name__}: {error})") from None
    if "settings" not in entries:
        raise EgncError(f"{path}: not an egnc checkpoint (no settings)")
    try:
        settings = json.loads(str(entries.pop("settings")))
    except ValueError as error:
        raise EgncError(f"{path}: damaged checkpoint (its settings are not JSON: {error})") from None
    arrays = entries
    if not isinstance(settings, dict):
        raise EgncError(f"{path}: not an egnc checkpoint (its settings are not a JSON object)")
    version = settings.get("version")
    if not _is_int(version) or version not in (UNDIGESTED_VERSION, CHECKPOINT_VERSION):
        raise EgncError(f"{path}: checkpoint version {version}, expected {CHECKPOINT_VERSION}")
    missing = [key for key in SETTINGS if key not in settings and (key != "digest" or version != UNDIGESTED_VERSION)]
    if missing:
        raise EgncError(f"{path}: incomplete checkpoint (settings without {', '.join(missing)})")
    problem = _inconsistency(settings, arrays)
    if problem:
        raise EgncError(f"{path}: inconsistent checkpoint ({problem})")
    if version != UNDIGESTED_VERSION and settings["digest"] != content_digest(settings, arrays):
        raise EgncError(
            f"{path}: the checkpoint's content does not match its digest: it was changed after egnc wrote it;"
            " remove it and replay from the start"
        )
    return {**OPTIONAL_SETTINGS, **settings}, arrays


def content_digest(settings: dict, arrays: dict[str, np.ndarray]) -> str:
    """The SHA-256 (hex) of a checkpoint's `settings` but their `digest` (as sorted JSON) and its
    `arrays` (each name, type, shape and bytes, by name)."""
    digest = hashlib.sha256()
    digest.update(json.dumps({k: v for k, v in settings.items() if k != "digest"}, sort_keys=True).encode())
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"\n{name} {array.dtype.str} {array.shape}\n".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def _inconsistency(settings: dict, arrays: dict[str, np.ndarray]) -> str:
    """What does not fit in a checkpoint's `settings` and `arrays`, or "" where everything does."""
    dim = settings["dim"]
    if isinstance(dim, bool) or dim not in (2, 3):
        return f"dim is {dim!r}, expected 2 or 3"
    n, p, d = dim + 1, POSE_SIZE[dim], TANGENT_SIZE[dim]  # matrix size, measurement and tangent sizes
    present = [name for name in PRIOR_ARRAYS if name in arrays]
    if present and len(present) < len(PRIOR_ARRAYS):
        return f"no {', '.join(name for name in PRIOR_ARRAYS if name not in arrays)}"
    expected = _expected_shapes(0, 0, 0, 0, n, p, d)
    missing = [name for name in (*expected, "converged_trusted") if name not in arrays and name not in PRIOR_ARRAYS]
    if missing:
        return f"no {', '.join(missing)}"
    # The poses, edges, priors and updates are counted by these arrays; the others must agree.
    counted = ("vertex_ids", "edges", "prior_rows", "update_ms")
    scalar = [name for name in counted if name in arrays and not arrays[name].ndim]
    if scalar:
        return f"{scalar[0]} is a single number, expected an array"
    num_poses, num_edges, num_priors, steps = (len(arrays.get(name, ())) for name in counted)
    for name, (shape, kind) in _expected_shapes(num_poses, num_edges, num_priors, steps, n, p, d).items():
        if name not in arrays:  # the priors' arrays of a checkpoint without priors
            continue
        array = arrays[name]
        if array.shape != shape or array.dtype.kind not in kind:
            return f"{name} is {array.dtype} {array.shape}, expected {_kind_name(kind)} {shape}"
    for name in ("T", "T_initial", "measurements", "Z_inv", "information", "mu", "mu_init", "r", "update_ms"):
        if not np.all(np.isfinite(arrays[name])):
            return f"{name} holds a non-finite number"
    for name in ("T", "T_initial", "Z_inv"):
        if not _rigid(arrays[name]):
            return f"{name} holds a matrix that is not a rigid transform"
    if not _positive_definite(arrays["information"]):
        return "information holds a matrix that is not symmetric positive definite"
    if len(sorted_unique(arrays["vertex_ids"])) != num_poses:
        return "vertex_ids repeats an id"
    edges = arrays["edges"]
    if num_edges and (edges.min() < 0 or edges.max() >= num_poses):
        return f"edges name poses outside 0..{num_poses - 1}"
    if num_priors:
        problem = _prior_inconsistency(arrays, num_poses, d)
        if problem:
            return problem
    for name in ("mu", "mu_init"):
        if np.any((arrays[name] < 0.0) | (arrays[name] > 1.0)):
            return f"{name} is outside [0, 1]"
    trusted = arrays["converged_trusted"]
    if trusted.ndim != 1 or trusted.dtype.kind != "b" or len(trusted) > num_edges:
        return f"converged_trusted is {trusted.dtype} {trusted.shape}, expected bool (at most {num_edges},)"
    if not _is_int(settings["steps"]) or settings["steps"] != steps:
        return f"steps is {settings['steps']!r}, expected {steps} (one per entry of update_ms)"
    if not _is_int(settings["last_status"]) or not isinstance(settings["has_prior"], bool):
        return "last_status must be an int and has_prior a bool"
    if not isinstance(settings["meta"], dict):
        return f"meta is {type(settings['meta']).__name__}, expected a JSON object"
    gauge, converged = settings["gauge"], settings["converged_poses"]
    if not _is_int(gauge) or not 0 <= gauge < max(num_poses, 1):
        return f"gauge is {gauge!r}, expected a pose row below {max(num_poses, 1)}"
    if converged is None:
        return "" if not len(trusted) else "converged_trusted is given without converged_poses"
    # The factorized map: the first `converged` poses and the first len(trusted) edges, among them.
    if not _is_int(converged) or not 1 <= converged <= num_poses:
        return f"converged_poses is {converged!r}, expected none or 1 to {num_poses}"
    if not len(trusted) or np.any(edges[: len(trusted)] >= converged):
        return f"converged_trusted's {len(trusted)} edges are not among the first {converged} poses"
    return ""


def _prior_inconsistency(arrays: dict[str, np.ndarray], num_poses: int, d: int) -> str:
    """What does not fit in a checkpoint's measurement priors, or ""."""
    rows, kinds = arrays["prior_rows"], arrays["prior_kinds"]
    if rows.min() < 0 or rows.max() >= num_poses:
        return f"prior_rows name poses outside 0..{num_poses - 1}"
    if np.any((kinds != 0) & (kinds != 1)):
        return "prior_kinds holds a kind other than 0 (pose) and 1 (position)"
    if not np.all(np.isfinite(arrays["prior_measurements"])) or not np.all(np.isfinite(arrays["prior_information"])):
        return "the priors hold a non-finite number"
    return ""


def _expected_shapes(
    num_poses: int, num_edges: int, num_priors: int, steps: int, n: int, p: int, d: int
) -> dict[str, tuple[tuple[int, ...], str]]:
    """Each array's shape and NumPy dtype kinds, for `num_poses` poses, `num_edges` edges,
    `num_priors` measurement priors and `steps` updates; `n`: pose matrix size, `p`: measurement
    vector size, `d`: tangent dimension. The per-factor arrays hold the edges, then the priors."""
    factors = num_edges + num_priors
    return {
        "vertex_ids": ((num_poses,), "iu"),
        "T": ((num_poses, n, n), "f"),
        "T_initial": ((num_poses, n, n), "f"),
        "edges": ((num_edges, 2), "iu"),
        "measurements": ((num_edges, p), "f"),
        "Z_inv": ((num_edges, n, n), "f"),
        "information": ((num_edges, d, d), "f"),
        "robust": ((factors,), "b"),
        "mu": ((factors,), "f"),
        "mu_init": ((factors,), "f"),
        "r": ((factors,), "f"),
        "prior_rows": ((num_priors,), "iu"),
        "prior_kinds": ((num_priors,), "iu"),
        "prior_measurements": ((num_priors, p), "f"),
        "prior_information": ((num_priors, d, d), "f"),
        "update_ms": ((steps,), "f"),
        "update_iterations": ((steps,), "iu"),
    }


def _rigid(matrices: np.ndarray) -> bool:
    """Whether every `(n, n)` homogeneous matrix of `matrices` `(K, n, n)` is a rigid transform:
    bottom row `[0 .. 0 1]`, rotation block orthonormal (to `RIGID_TOLERANCE`) with determinant +1."""
    n = matrices.shape[-1]
    bottom = np.zeros(n)
    bottom[-1] = 1.0
    rotation = matrices[:, : n - 1, : n - 1]
    gram = np.swapaxes(rotation, 1, 2) @ rotation - np.eye(n - 1)
    return bool(
        np.all(matrices[:, n - 1] == bottom)
        and np.all(np.abs(gram) <= RIGID_TOLERANCE)
        and np.all(np.linalg.det(rotation) > 0.0)
    )


def _positive_definite(information: np.ndarray) -> bool:
    """Whether every matrix of `information` `(E, d, d)` is symmetric positive definite."""
    if not np.array_equal(information, np.swapaxes(information, 1, 2)):
        return False
    try:
        np.linalg.cholesky(information)
    except np.linalg.LinAlgError:
        return False
    return True


def _kind_name(kind: str) -> str:
    """The word for NumPy dtype kinds `kind` in a message."""
    return {"iu": "int", "f": "float", "b": "bool"}[kind]


def _is_int(value: object) -> bool:
    """Whether a JSON value is an integer (not a bool, which JSON keeps apart but Python does not)."""
    return isinstance(value, int) and not isinstance(value, bool)
