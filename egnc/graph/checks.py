"""Type and range checks of option fields and function arguments, one `OptionError` naming each.

The option dataclasses (`SolverOptions`, `GncOptions`) check every field at construction and the
public functions check their arguments, so a wrong value fails at once with one line instead of a
hang, a wrong "converged" result or an `AttributeError` deep inside the solver. Each check returns
the value as the plain Python type (`bool`, `int`, `float`, `str`), so NumPy scalars are accepted
and stored as Python ones.
"""

from __future__ import annotations

import math
from collections.abc import Collection

import numpy as np

from egnc.errors import EgncError, OptionError, OptionTypeError

INT64_MIN, INT64_MAX = int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max)
"""The range of a vertex id (`PoseGraph.vertex_ids` is int64)."""


def describe(value: object) -> str:
    """A short description of a value for a one-line error message (never a whole array)."""
    if isinstance(value, np.ndarray):
        return f"an array of dtype {value.dtype} and shape {value.shape}"
    text = repr(value)
    return text if len(text) <= 40 and "\n" not in text else f"a {type(value).__name__}"


def check_bool(name: str, value: object) -> bool:
    """`value` as a bool; only `True`, `False` and NumPy bools are accepted (not `"no"`, 0 or None)."""
    if not isinstance(value, (bool, np.bool_)):
        raise OptionTypeError(f"{name} must be True or False, got {describe(value)}")
    return bool(value)


def check_int(name: str, value: object, minimum: int) -> int:
    """`value` as an int `>= minimum`; floats (even `2.0`) and bools are refused."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise OptionTypeError(f"{name} must be an integer, got {describe(value)}")
    if value < minimum:
        raise OptionError(f"{name} must be an integer >= {minimum}, got {describe(value)}")
    return int(value)


def check_float(
    name: str, value: object, low: float, high: float = math.inf, *, open_low: bool = False, open_high: bool = False
) -> float:
    """`value` as a finite float in `[low, high]`, with either end excluded on request.

    Ints are accepted (`1` for `1.0`); bools, strings and None are not. NaN and infinities are
    always refused: every float option is a finite quantity.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise OptionTypeError(f"{name} must be a number, got {describe(value)}")
    number = float(value)
    below = number <= low if open_low else number < low
    above = number >= high if open_high else number > high
    if not math.isfinite(number) or below or above:
        left, right = "(" if open_low else "[", ")" if open_high else "]"
        limits = f"{left}{low:g}, {high:g}{right}" if math.isfinite(high) else f"{left}{low:g}, inf)"
        raise OptionError(f"{name} must be a finite number in {limits}, got {describe(value)}")
    return number


def check_choice(name: str, value: object, choices: Collection[str]) -> str:
    """`value` if it is one of the strings `choices`."""
    if not isinstance(value, str) or value not in choices:
        raise OptionError(f"unknown {name} {describe(value)}: choose one of {', '.join(choices)}")
    return value


def check_instance(name: str, value: object, kind: type | tuple[type, ...], what: str | None = None) -> None:
    """Refuse `value` unless it is a `kind` (e.g. a dict given where `SolverOptions` is expected).

    `what` names the expected kind in the message, with its article (default: the class name).
    """
    if not isinstance(value, kind):
        if what is None:
            names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
            what = f"{'an' if names[0] in 'AEIOUaeiou' else 'a'} {names}"
        raise OptionTypeError(f"{name} must be {what}, got {type(value).__name__}")


def check_callable(name: str, value: object) -> None:
    """Refuse `value` unless it is None or callable (a callback)."""
    if value is not None and not callable(value):
        raise OptionTypeError(f"{name} must be callable or None, got {type(value).__name__}")


def check_vertex_ids(name: str, value: object, error: type[EgncError] = OptionError) -> np.ndarray:
    """`value`, a vertex id or an array-like of them, as an int64 array of its shape, checked before conversion.

    Only integers are ids (Python's and NumPy's; not floats, even `2.0`, nor bools or strings),
    and only those within int64: NumPy would wrap a uint64 `2**64 - 1` to the id -1 and refuse
    a Python `2**63` as "float64". An empty sequence (`[]`, NumPy's float64) is an empty batch.

    Args:
        name: the argument's name, for the message.
        value: what was given.
        error: the class raised (`OptionError` for arguments, `GraphError` for graph entries).

    Raises:
        error: `value` is not integers, or an id is outside int64; the message names it.
    """
    try:
        array = np.asarray(value)
    except (ValueError, OverflowError):  # ragged nesting
        raise error(f"{name} must be integers, got {describe(value)}") from None
    if array.size == 0 and array.dtype.kind in "iuf":
        return array.astype(np.int64)
    if array.dtype.kind == "O":  # Python ints beyond 64 bits, or mixed objects
        items = array.ravel().tolist()
        if not all(isinstance(item, (int, np.integer)) and not isinstance(item, (bool, np.bool_)) for item in items):
            raise error(f"{name} must be integers, got {describe(value)}")
        outside = [int(item) for item in items if not INT64_MIN <= item <= INT64_MAX]
    elif array.dtype.kind in "iu":
        outside = [int(array.max())] if array.dtype.kind == "u" and array.max() > INT64_MAX else []
    else:
        raise error(f"{name} must be integers, got {array.dtype if array.ndim else describe(value)}")
    if outside:
        raise error(f"{name}: {outside[0]} is outside int64 [{INT64_MIN}, {INT64_MAX}], the range of vertex ids")
    return array.astype(np.int64)
