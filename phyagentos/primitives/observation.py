"""One observation through the robot's own sensors: capture every camera, perceive, keep the frames.

:func:`perceive_now` is what the ``observe`` primitive and the SessionRunner (before and
after the skill) call: it captures every camera sensor the target declares
(``sensors.yaml``), reads proprioception, runs the session's
:class:`~phyagentos.perception.Perceiver` and returns the perceived snapshot of CONTRACT_9
section 3, with the declared regions and obstacles added as ``source: declared``
entities. The RGB frames behind it are saved downscaled (every second pixel, PNG through
OpenCV) under ``evidence/<session>/frames/`` and named in each entity's ``evidence``; the
object point cloud perception clustered goes next to them (``<tag>_cloud.npz``, bounded).

A target without cameras (FrankaKitchen) has no perception: :func:`perceive_now` returns
``None`` and the caller falls back to the target's own observation.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from phyagentos.targets.contract import capabilities_of

from . import planning_world

__all__ = ["has_cameras", "make_perceiver", "perceive_now", "robot_capsules", "observe_record", "save_tracks",
           "save_cloud", "MAX_SAVED_CLOUD_POINTS"]

log = logging.getLogger(__name__)

#: Most points of a perceived cloud kept in the evidence (``frames/<tag>_cloud.npz``).
MAX_SAVED_CLOUD_POINTS = 4000

#: Radius of the capsules masking the arm's links from the point cloud, m (the Panda's
#: links are about 6 cm in radius; 2 cm of margin).
LINK_CAPSULE_RADIUS_M = 0.08


def has_cameras(target) -> bool:
    """True if ``target`` declares camera sensors it can capture."""
    return capabilities_of(target).has_sensor("rgb") and bool(target.camera_names())


def make_perceiver(target, config_path: str | Path | None = None):
    """A fresh :class:`~phyagentos.perception.Perceiver` for one session on ``target``:
    the workspace's ``perception.yaml`` (``config_path``, if it exists), else the target's
    ``perception_config()`` when it has one (LIBERO's worlds), else the defaults,
    and the objects and fixtures the user declared (``target.describe_declared()``; a
    fixture is perceived when it is declared with a look)."""
    from phyagentos.perception import Perceiver, PerceptionConfig  # noqa: PLC0415

    path = Path(config_path) if config_path is not None else None
    if path is not None and path.is_file():
        cfg = PerceptionConfig.from_yaml(path)
    else:  # the parameters that suit the target's world, else the defaults
        cfg = target.perception_config()
        if cfg is None:
            cfg = PerceptionConfig.default()
    declared = target.describe_declared()
    p = Perceiver(cfg, {"objects": declared["objects"], "fixtures": declared.get("fixtures") or []})
    if hasattr(p, "robot_name"):
        p.robot_name = target.ROBOT
    _restore_tracks(p, target.runtime_notes)
    return p


def save_tracks(target, perceiver) -> None:
    """Keep what ``perceiver`` believes (its tracks, the held object, the wrist baseline, the
    fixtures: :meth:`~phyagentos.perception.Perceiver.export_state`) in
    ``target.runtime_notes`` as plain data, so the next session of the run (another process,
    maybe) continues it: a robot remembers what it saw and what it holds. A perceiver without
    tracks keeps nothing."""
    if not hasattr(perceiver, "export_state"):
        return
    target.runtime_notes["perception"] = perceiver.export_state()


def _restore_tracks(perceiver, notes: dict) -> None:
    """Continue ``perceiver`` from what :func:`save_tracks` kept; a layout written by another
    version starts afresh (logged)."""
    saved = notes.get("perception")
    if not saved or not hasattr(perceiver, "restore_state"):
        return
    from phyagentos.perception.errors import PerceptionError  # noqa: PLC0415

    try:
        perceiver.restore_state(saved)
    except PerceptionError as exc:  # the track layout changed: start afresh
        log.warning("perception state not restored (layout changed): %s", exc)


def robot_capsules(target) -> list:
    """Capsules (world frame) around the arm's links from its forward kinematics, for the
    perceiver to mask: one per joint-to-next-joint segment of the arm chain."""
    from phyagentos.perception import RobotCapsule  # noqa: PLC0415

    m, d = target.model, target.data
    anchors = [np.array(d.xanchor[m.joint(n).id]) for n in target.arm_joint_names]
    anchors.append(np.array(target.tcp_pose()[:3, 3]))
    out = []
    for a, b in zip(anchors[:-2], anchors[1:-1]):  # the hand itself is the perceiver's gripper box
        out.append(RobotCapsule(p0=tuple(float(x) for x in a), p1=tuple(float(x) for x in b),
                                radius_m=LINK_CAPSULE_RADIUS_M))
    # a hand the gripper box does not cover (the SO-101's moving jaw) declares its own
    for p0, p1, r in target.hand_capsules():
        out.append(RobotCapsule(p0=tuple(p0), p1=tuple(p1), radius_m=float(r)))
    return out


def _save_frame(frame, path: Path) -> None:
    import cv2  # noqa: PLC0415

    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.ascontiguousarray(frame.rgb[::2, ::2, ::-1]))


def save_cloud(cloud, sensors, path: Path) -> int:
    """Write the perceived object cloud of one observation to ``path`` (``.npz``).

    Args:
        cloud: the perceiver's :attr:`~phyagentos.perception.Perceiver.last_cloud`
            (stage 2: object points above the support plane; world frame).
        sensors: the observation's camera sensor names, in frame order.
        path: the file to write.

    The file holds ``points`` (M, 3) float32 m in the world frame, ``rgb`` (M, 3) uint8,
    ``camera`` (M,) int16 index into ``sensors`` (M,) str; ``M <= MAX_SAVED_CLOUD_POINTS``
    (an even random subset, seeded, when the cloud is larger). Returns M.
    """
    n = len(cloud.points)
    idx = np.arange(n)
    if n > MAX_SAVED_CLOUD_POINTS:
        idx = np.sort(np.random.default_rng(0).choice(n, MAX_SAVED_CLOUD_POINTS, replace=False))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, points=np.asarray(cloud.points[idx], dtype=np.float32),
                        rgb=np.asarray(cloud.rgb[idx], dtype=np.uint8),
                        camera=np.asarray(cloud.camera[idx], dtype=np.int16),
                        sensors=np.asarray(list(sensors), dtype=str))
    return len(idx)


def perceive_now(target, perceiver, *, samples: int = 1, evidence_dir: Path | None = None,
                 evidence_rel: str | None = None, tag: str = "obs") -> dict | None:
    """Capture, perceive and return the perceived snapshot (``None`` without cameras).

    Args:
        samples: observations fused (>= 1); between two, the arm holds still for one
            camera period (0.1 s of target time) so each gets fresh frames.
        evidence_dir, evidence_rel: the bundle directory (absolute, and relative to the
            workspace for the pointers); frames are saved as ``frames/<tag>_<sensor>.png``
            and the perceived object cloud as ``frames/<tag>_cloud.npz`` (:func:`save_cloud`).
        tag: file-name prefix of the saved frames.
    """
    if not has_cameras(target) or perceiver is None:
        return None
    declared = target.describe_declared()
    snap = None
    for k in range(max(1, int(samples))):
        if k:
            target.hold(duration_s=0.1)
        frames = [target.capture(s) for s in target.camera_names()]
        proprio = target.proprioception()
        paths: dict[str, str] = {}
        if evidence_dir is not None and k == max(1, int(samples)) - 1:
            for f in frames:
                name = f"frames/{tag}_{f.sensor}.png"
                _save_frame(f, Path(evidence_dir) / name)
                paths[f.sensor] = f"{evidence_rel}/{name}" if evidence_rel else name
        snap = perceiver.observe(frames, proprio, regions=declared["regions"], obstacles=declared["obstacles"],
                                 robot_capsules=robot_capsules(target), evidence_paths=paths or None)
        cloud = getattr(perceiver, "last_cloud", None)
        if paths and cloud is not None:
            save_cloud(cloud, [f.sensor for f in frames], Path(evidence_dir) / f"frames/{tag}_cloud.npz")
    assert snap is not None
    names = {e["name"] for e in snap.get("entities", [])}
    for r in declared["regions"]:
        if r["name"] not in names:
            snap["entities"].append({"name": r["name"], "kind": "region",
                                     "position": [float(r["center"][0]), float(r["center"][1]), 0.0],
                                     "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                                     "size": [float(r["half_extents"][0]), float(r["half_extents"][1]), 0.0],
                                     "attributes": {"source": "declared"}})
    for ob in declared["obstacles"]:
        if ob["name"] not in names:
            snap["entities"].append({"name": ob["name"], "kind": "obstacle", "position": list(ob["center"]),
                                     "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": list(ob["half_extents"]),
                                     "attributes": {"source": "declared"}})
    snap.setdefault("sim_time_s", snap.get("stamp_s"))
    save_tracks(target, perceiver)
    planning_world.note_observation(target, snap)  # the motion planner's world: what was just seen
    return snap


def observe_record(snapshot: dict) -> dict[str, Any]:
    """The ``observe`` trace fields of CONTRACT_9 section 5: perceived objects (position,
    confidence, position_std_m) and how many unknown clusters were seen."""
    objects: dict[str, Any] = {}
    unknown = 0
    for e in snapshot.get("entities", []):
        if e.get("kind") == "unknown":
            unknown += 1
        if e.get("kind") != "object":
            continue
        a = e.get("attributes") or {}
        objects[e["name"]] = {"position": [round(float(x), 4) for x in e["position"]],
                              "confidence": a.get("confidence"), "position_std_m": a.get("position_std_m")}
    return {"stamp_s": snapshot.get("stamp_s", snapshot.get("sim_time_s")), "objects": objects, "unknown": unknown}
