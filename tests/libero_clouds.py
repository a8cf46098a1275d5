"""The perception configuration of LIBERO's recorded clouds (``tests/data/*.npz``), for the
perception tests that read them without building a world."""

from __future__ import annotations

from phyagentos.perception import PerceptionConfig
from phyagentos.targets.libero.sensing import LiberoSensing


def libero_perception_config(table_z: float) -> PerceptionConfig:
    """The defaults with LIBERO's overrides (``LiberoSensing.PERCEPTION_OVERRIDES``) and the
    support prior at ``table_z`` m (the recording's table top), as a LIBERO target makes it."""
    doc = PerceptionConfig.default().model_dump()
    for section, values in LiberoSensing.PERCEPTION_OVERRIDES.items():
        doc[section] = {**doc[section], **values}
    doc["table"] = {**doc["table"], "expected_height_m": table_z}
    return PerceptionConfig.model_validate(doc)
