"""Perception (Runtime plane): RGB-D frames + proprioception -> a perceived snapshot.

Issue 9, CONTRACT_9.md sections 1 and 4. The Agent plane never imports this package; it
reads the snapshots the observe primitive writes.
"""

from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception

__all__ = [
    "PerceptionError",
    "CameraIntrinsics",
    "CameraFrame",
    "Proprioception",
]
