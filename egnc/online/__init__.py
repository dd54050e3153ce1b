"""Online (incremental) robust optimization: `OnlineSolver`, which graduates each new loop
closure on a region around it, and `replay`, which feeds a whole graph to it pose by pose.

Imports `egnc.api` and below.
"""

from egnc.online.options import ONLINE_METHODS, OnlineOptions
from egnc.online.report import UpdateReport
from egnc.online.solver import OnlineSolver

__all__ = ["ONLINE_METHODS", "OnlineOptions", "OnlineSolver", "UpdateReport"]
