"""Every deploy-time file of a workspace, checked before anything starts (issue 33).

:func:`check_deploy_files` reads and validates, with their strict schemas (unknown keys,
non-finite numbers and out-of-range values refused, with ``file:line``):

=====================  ===========================================================
``safety.yaml``        :class:`~phyagentos.protocol.SafetyConfig`
``sensors.yaml``       :class:`~phyagentos.protocol.sensors.SensorsConfig`
``perception.yaml``    :class:`~phyagentos.perception.config.PerceptionConfig`
``llm.yaml``           :func:`~phyagentos.llm.load_llm_config` (:class:`~phyagentos.llm.config.LLMFile`)
``fleet.yaml``         :func:`~phyagentos.fleet.config.load_fleet_config`
=====================  ===========================================================

``phyagentos run`` and ``phyagentos submit`` (and the MCP ``submit_goal_graph`` tool) call
it first: a malformed file is reported, never repaired or overwritten, and no target is
built and nothing moves.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check_deploy_files", "DEPLOY_FILES"]

#: The deploy-time files of a workspace (each optional except safety.yaml, which
#: ``Workspace.create`` restores).
DEPLOY_FILES = ("safety.yaml", "sensors.yaml", "perception.yaml", "llm.yaml", "fleet.yaml")


def check_deploy_files(workspace_root: str | os.PathLike[str]) -> None:
    """Validate every deploy-time file present in ``workspace_root``.

    Raises:
        DocumentError: ``safety.yaml``, ``sensors.yaml`` or ``perception.yaml`` is malformed
            (``path:line`` and what is wrong).
        LLMError: ``llm.yaml`` is malformed (``path:line``).
        FleetError: ``fleet.yaml`` is malformed (``path:line``).
        ProtocolError: ``safety.yaml`` is missing or a file is not a regular file.
    """
    from phyagentos.errors import ProtocolError  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.protocol.codec import read_yaml  # noqa: PLC0415
    from phyagentos.protocol.sensors import SENSORS_FILE, SensorsConfig  # noqa: PLC0415

    root = Path(workspace_root)
    try:
        Workspace.open(root).read_safety()
        if (root / SENSORS_FILE).exists():
            read_yaml(root / SENSORS_FILE, SensorsConfig)
        if (root / "perception.yaml").exists():
            from phyagentos.perception.config import PerceptionConfig  # noqa: PLC0415

            PerceptionConfig.from_yaml(root / "perception.yaml")
        if (root / "llm.yaml").exists():
            from phyagentos.llm.config import read_llm_file  # noqa: PLC0415

            read_llm_file(root / "llm.yaml")
        if (root / "fleet.yaml").exists():
            from phyagentos.fleet.config import load_fleet_config  # noqa: PLC0415

            load_fleet_config(root / "fleet.yaml")
    except OSError as exc:  # a FIFO, a device, a link loop: refused, never waited on
        raise ProtocolError(f"deploy-time file not readable: {exc}") from None
