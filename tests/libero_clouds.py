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


def recorded_frames(path):
    """``(frames, proprioception, meta)`` of a recording written by
    ``bench/libero_drawer_refs.py --record``: both cameras' RGB-D frames (depth stored in 0.1 mm
    steps), the arm's proprioception at the start pose (no velocities or efforts) and the JSON
    meta (declared scene, perception configuration, robot capsules, true centres for scoring)."""
    import json  # noqa: PLC0415

    import numpy as np  # noqa: PLC0415

    from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception  # noqa: PLC0415

    z = np.load(path)
    meta = json.loads(str(z["meta"]))
    frames = []
    for k, sensor in enumerate(meta["sensors"]):
        w, h, fx, fy, cx, cy = z[f"K{k}"]
        frames.append(CameraFrame(sensor, meta["frame_ids"][k], float(meta["stamp_s"]),
                                  CameraIntrinsics(int(w), int(h), float(fx), float(fy), float(cx), float(cy)),
                                  z[f"T{k}"], z[f"rgb{k}"], z[f"depth{k}"].astype(np.float32) / 1e4))
    n = len(meta["joint_names"])
    proprio = Proprioception(float(meta["stamp_s"]), tuple(meta["joint_names"]), np.asarray(meta["joint_positions"]),
                             np.zeros(n), np.zeros(n), float(meta["gripper_opening_m"]), 0.0, None, None,
                             np.asarray(meta["tcp_pose"]))
    return frames, proprio, meta
