"""egnc: robust pose-graph optimization with Efficient Graduated Non-Convexity."""

from egnc.errors import EgncError, G2oFormatError, GraphError, SolverError

__version__ = "0.1.0"

__all__ = ["EgncError", "G2oFormatError", "GraphError", "SolverError", "__version__"]
