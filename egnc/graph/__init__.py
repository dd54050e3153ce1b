"""The pose graph and what checks it: the `PoseGraph` container, value and shape checks,
connectivity, sorted index sets and the numerical health of a graph.

Imports only `egnc.lie` and `egnc.errors`.
"""

from egnc.graph.pose_graph import POSE_SIZE, TANGENT_SIZE, PoseGraph, is_dim

__all__ = ["POSE_SIZE", "TANGENT_SIZE", "PoseGraph", "is_dim"]
