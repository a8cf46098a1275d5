"""Perception (Runtime plane): RGB-D frames + proprioception -> a perceived snapshot.

Issue 9, CONTRACT_9.md sections 1, 3 and 4; pipeline and conventions in docs/perception.md.
The Agent plane never imports this package; it reads the snapshots the observe primitive
writes.
"""

from phyagentos.perception.cloud import RobotCapsule
from phyagentos.perception.config import PerceptionConfig
from phyagentos.perception.descriptors import ObjectDescriptor, SpatialReference, descriptors_from_declared
from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception
from phyagentos.perception.perceiver import Perceiver

__all__ = [
    "PerceptionError",
    "CameraIntrinsics",
    "CameraFrame",
    "Proprioception",
    "PerceptionConfig",
    "ObjectDescriptor",
    "SpatialReference",
    "descriptors_from_declared",
    "Perceiver",
    "RobotCapsule",
]
