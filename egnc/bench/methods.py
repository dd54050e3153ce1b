"""Method specs of the benchmark grid: `name` or `name[GncOptions field=value,...]`.

Every name in `egnc.robust.schedules.METHODS` may carry `GncOptions` overrides in brackets
(`egnc[threshold=distance]`, `risam[c=2,refine=false]`); the GTSAM baselines (`GTSAM_METHODS`) take
none.
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from dataclasses import dataclass

from egnc.errors import EgncError
from egnc.robust.gnc import GncOptions
from egnc.robust.schedules import METHODS

__all__ = ["GTSAM_METHODS", "MethodSpec", "parse_method", "parse_methods"]

GTSAM_METHODS = ("gtsam-gnc-gm", "gtsam-gnc-tls", "gtsam-lm")
"""Baselines run with GTSAM's Python wheel (the optional `bench` extra) when it is importable."""


@dataclass(frozen=True)
class MethodSpec:
    """One method of the grid.

    Attributes:
        label: the spec as given, e.g. `"egnc[threshold=distance]"`; names the method in the results.
        method: an `egnc.robust.schedules.METHODS` name or one of `GTSAM_METHODS`.
        overrides: `GncOptions` fields to change, as `(name, value)` pairs (egnc methods only).
    """

    label: str
    method: str
    overrides: tuple[tuple[str, object], ...] = ()

    @property
    def is_gtsam(self) -> bool:
        """Whether GTSAM runs this method."""
        return self.method in GTSAM_METHODS

    def gnc_options(self) -> GncOptions:
        """The `GncOptions` with this spec's overrides."""
        overrides: dict[str, typing.Any] = dict(self.overrides)  # each value has its field's type (parse_method)
        return GncOptions(**overrides)


_SPEC = re.compile(r"^\s*([A-Za-z0-9_-]+)\s*(?:\[(.*)\])?\s*$", re.DOTALL)


def parse_method(spec: str) -> MethodSpec:
    """Parse `name` or `name[field=value,...]` into a `MethodSpec`.

    Values are converted to the type of the `GncOptions` field (`none` for an optional field,
    `true`/`false` for a flag, `chordal+regrouped` or `()` for `starts`) and the options are
    validated at once.

    Raises:
        EgncError: unknown method or option, a value of the wrong type, or options GncOptions rejects.
    """
    match = _SPEC.match(spec)
    if not match:
        raise EgncError(f"method {spec!r}: expected NAME or NAME[option=value,...]")
    name, body = match.group(1), match.group(2)
    if name not in METHODS and name not in GTSAM_METHODS:
        raise EgncError(f"unknown method {name!r}: choose one of {', '.join(METHODS + GTSAM_METHODS)}")
    overrides: dict[str, object] = {}
    if body is not None and body.strip():
        if name in GTSAM_METHODS:
            raise EgncError(f"method {spec!r}: GTSAM baselines take no options")
        hints = typing.get_type_hints(GncOptions)
        fields = [f.name for f in dataclasses.fields(GncOptions)]
        for item in body.split(","):
            key, equals, value = (part.strip() for part in item.partition("="))
            if not equals or not key or not value:
                raise EgncError(f"method {spec!r}: option {item.strip()!r} is not of the form name=value")
            if key not in hints:
                raise EgncError(f"method {spec!r}: unknown option {key!r}; GncOptions has {', '.join(fields)}")
            if key in overrides:
                raise EgncError(f"method {spec!r}: option {key!r} given twice")
            overrides[key] = _convert(value, hints[key], f"method {spec!r}: option {key}")
    parsed = MethodSpec(label=spec.strip(), method=name, overrides=tuple(overrides.items()))
    if not parsed.is_gtsam:
        try:
            parsed.gnc_options()
        except EgncError as error:
            raise EgncError(f"method {spec!r}: {error}") from None
    return parsed


def parse_methods(text: str) -> tuple[MethodSpec, ...]:
    """Parse a comma-separated list of specs; commas inside brackets belong to the options."""
    specs, depth, start = [], 0, 0
    for position, char in enumerate(text + ","):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            if text[start:position].strip():
                specs.append(parse_method(text[start:position]))
            start = position + 1
    if depth != 0:
        raise EgncError(f"methods {text!r}: unbalanced brackets")
    if not specs:
        raise EgncError("no method given")
    labels = [spec.label for spec in specs]
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        raise EgncError(f"method {repeated[0]!r} is listed twice")
    return tuple(specs)


def _convert(text: str, kind: object, what: str) -> object:
    """Convert an option value to the annotated type (`float`, `int`, `bool`, `str`, `X | None`,
    a deprecated keyword argument's `InitVar[X]`, or a tuple of names written `a+b`, `()` for none)."""
    if isinstance(kind, dataclasses.InitVar):
        kind = kind.type
    if typing.get_origin(kind) is tuple:
        item = typing.get_args(kind)[0]
        items = [] if text.strip() == "()" else [part.strip() for part in text.split("+")]
        return tuple(_convert(part, item, what) for part in items)
    union = isinstance(kind, types.UnionType) or typing.get_origin(kind) is typing.Union
    options = typing.get_args(kind) if union else (kind,)
    if type(None) in options and text.lower() == "none":
        return None
    if typing.get_origin(kind) is typing.Literal:
        if text in typing.get_args(kind):
            return text
        raise EgncError(f"{what}: {text!r} is not one of {', '.join(map(str, typing.get_args(kind)))}")
    for option in options:
        if option is bool:
            if text.lower() in ("true", "yes", "1"):
                return True
            if text.lower() in ("false", "no", "0"):
                return False
        elif option is int:
            try:
                return int(text)
            except ValueError:
                pass
        elif option is float:
            try:
                return float(text)
            except ValueError:
                pass
        elif option is str:
            return text
    names = " or ".join("none" if option is type(None) else getattr(option, "__name__", "value") for option in options)
    raise EgncError(f"{what}: {text!r} is not a valid {names}")
