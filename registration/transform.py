"""The transform between two scanner frames.

:class:`common.rigid.Transform` (one type for the whole code base), re-exported here where registration's callers look
for it.
"""
from common.rigid import Transform, pose_difference

__all__ = ["Transform", "pose_difference"]
