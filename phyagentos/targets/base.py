"""The rollout-target contract, under its original names.

:class:`BaseRolloutTarget` is :class:`phyagentos.targets.contract.Target`; new code
imports from :mod:`phyagentos.targets.contract`.
"""

from __future__ import annotations

from .contract import TARGET_KINDS, ExecutionResult, Target, TargetKind

BaseRolloutTarget = Target

__all__ = ["BaseRolloutTarget", "ExecutionResult", "TargetKind", "TARGET_KINDS"]
