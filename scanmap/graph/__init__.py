"""Loop closure: a pose graph behind registration, loops found by place (scan context)
and by proximity, verified by ICP, optimised robustly in a background thread.

Entry point: `LoopCloser` (`add` each registered scan, read `corrected_poses`), set up
by a `LoopClosureConfig`; beneath it `PoseGraph` (GTSAM, Cauchy kernel on loop edges)
and the place descriptor (`describe`, `compare`).
"""

from scanmap.graph.descriptor import PlaceDescriptor, compare, describe
from scanmap.graph.loop_closure import Loop, LoopCloser, LoopClosureConfig
from scanmap.graph.pose_graph import Edge, PoseGraph, planar_information

__all__ = ["Edge", "Loop", "LoopCloser", "LoopClosureConfig", "PlaceDescriptor", "PoseGraph",
           "compare", "describe", "planar_information"]
