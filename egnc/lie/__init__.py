"""Vectorized Lie groups SO(2), SE(2), SO(3), SE(3) on NumPy arrays with batch shape `...`."""

from egnc.lie import se2, se3, so2, so3

__all__ = ["so2", "se2", "so3", "se3"]
