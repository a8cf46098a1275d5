"""The perception subsystem's error class."""

from __future__ import annotations

from phyagentos.errors import PhyAgentOSError

__all__ = ["PerceptionError"]


class PerceptionError(PhyAgentOSError):
    """A sensor frame, proprioception sample, perception.yaml or declared descriptor is
    malformed, or the pipeline was called with inputs it cannot use."""
