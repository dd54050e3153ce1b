"""Argument types and arguments shared by the command-line entry points: a bad value is a usage error (exit 2)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type accepting integers `>= minimum`."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}")
        return value

    return parse


def positive_float(text: str) -> float:
    """An argparse type accepting finite numbers `> 0`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def share(text: str) -> float:
    """An argparse type accepting numbers in `[0, 1]`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number from 0 to 1, got {text!r}")
    return value


def add_irl_covariance_order(parser: argparse.ArgumentParser) -> None:
    """Add `--irl-covariance-order` (`egnc.io.read_irl`'s `covariance_order`; None: its default)."""
    parser.add_argument(
        "--irl-covariance-order",
        choices=("gtsam", "g2o"),
        help="order of a 3D IRL log's covariances: gtsam (rx ry rz x y z, riSAM's reader; the default) or g2o"
        " (x y z rx ry rz, what riSAM's g2o-2-irl writes for g2o files such as sphere2500; docs/online.md)",
    )
