"""Online (incremental) robust optimization: `OnlineSolver`, which graduates each new loop
closure on a region around it, and `replay`, which feeds a whole graph to it pose by pose.

Imports `egnc.api` and below.
"""

from egnc.online.solver import ONLINE_METHODS, OnlineOptions, OnlineSolver, UpdateReport

__all__ = ["ONLINE_METHODS", "OnlineOptions", "OnlineSolver", "UpdateReport"]
