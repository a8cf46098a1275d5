"""The world model of a MuJoCo arm's tabletop scene: entities and relations from the
simulator (:meth:`snapshot`), the privileged ground-truth channel read only by scoring and
tests (:meth:`ground_truth`), the scene record and the declared objects (mixed into
:class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`)."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from phyagentos.geometry import matrix_to_quat as mat_quat

from .common import floats as _floats

log = logging.getLogger(__name__)



class ArmWorldTruth:
    """The scene's world model and the privileged ground-truth channel.

    Mixed into :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`.
    """

    # -- world model of a tabletop scene (truth) -----------------------------------------
    def _robot_entities(self) -> list[dict]:
        tcp = self.tcp_pose()
        opening = self.gripper_opening()
        return [
            {"name": self.ROBOT, "kind": "robot", "position": [float(c) for c in self.ROBOT_BASE],
             "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [0.0, 0.0, 0.0],
             "attributes": {"joint_positions": [round(float(q), 6) for q in self.arm_qpos()],
                            "gripper_opening_m": round(opening, 6)}},
            {"name": "tcp", "kind": "robot", "position": _floats(tcp[:3, 3]), "quat_wxyz": mat_quat(tcp[:3, :3]),
             "size": [0.0, 0.0, 0.0]},
            {"name": "gripper", "kind": "gripper", "position": _floats(tcp[:3, 3]), "quat_wxyz": mat_quat(tcp[:3, :3]),
             "size": [opening, 0.0, 0.0], "attributes": {"opening_m": round(opening, 6)}},
        ]

    def _object_bottom_top(self, name: str) -> tuple[float, float]:
        """(bottom z, top z) of an object's bounding box in the world, metres."""
        T = self.object_pose(name)
        he = np.array(self._scene.object(name).half_extents)
        ext = float(np.abs(T[2, :3]) @ he)
        return float(T[2, 3] - ext), float(T[2, 3] + ext)

    def snapshot(self) -> dict:
        """Simulator world state (ground truth), plain Python types only (YAML/JSON ready).

        Returns ``{"sim_time_s": s, "time": s, "entities": [...], "relations": [...]}``.
        Entities: ``{"name", "kind", "position" (3,) m, "quat_wxyz" (4,), "size" (3,),
        "attributes"}`` with ``size`` the half extents in metres, for the arm (kind
        ``robot``, attributes ``joint_positions`` rad and ``gripper_opening_m``), the tcp
        (``name='tcp'``), the gripper (kind ``gripper``, ``size[0]`` = opening per
        finger), every object (kind ``object``, attributes ``shape``), region (kind
        ``region``) and obstacle (kind ``obstacle``); world frame. Relations are
        ``{"subject", "relation", "object"}``:

        - ``gripper holding X``: X touches both finger pads (simulator contacts);
        - ``X on table``: X rests on the table (bottom within 5 mm of z = 0);
        - ``X on R`` (region): X rests on the table and its footprint overlaps R;
        - ``X inside R``: X rests on the table and its centre is inside R's footprint;
        - ``X on Y`` (object): X's bottom is within 6 mm of Y's top and X's centre lies
          over Y's footprint.

        This is the simulator's truth: it goes to ``ground_truth.yaml`` and tests only.
        """
        self._check_open()
        ents = self._robot_entities()
        for o in self._scene.objects:
            T = self.object_pose(o.name)
            ents.append({"name": o.name, "kind": "object", "position": _floats(T[:3, 3]),
                         "quat_wxyz": mat_quat(T[:3, :3]), "size": [float(h) for h in o.half_extents],
                         "attributes": {"shape": o.shape}})
        for r in self._scene.regions:
            ents.append({"name": r.name, "kind": "region", "position": [float(r.center[0]), float(r.center[1]), 0.0],
                         "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                         "size": [float(r.half_extents[0]), float(r.half_extents[1]), 0.0]})
        for ob in self._scene.obstacles:
            ents.append({"name": ob.name, "kind": "obstacle", "position": [float(c) for c in ob.center],
                         "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [float(h) for h in ob.half_extents]})
        held = set(self.held_objects())
        rel = [{"subject": "gripper", "relation": "holding", "object": n} for n in sorted(held)]
        extents = {o.name: self._object_bottom_top(o.name) for o in self._scene.objects}
        for o in self._scene.objects:
            if o.name in held:
                continue
            xy = self.object_pose(o.name)[:2, 3]
            bottom = extents[o.name][0]
            if abs(bottom) < 0.005:
                rel.append({"subject": o.name, "relation": "on", "object": "table"})
                foot = max(o.half_extents[0], o.half_extents[1])
                for r in self._scene.regions:
                    if r.contains_xy(xy):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
                        rel.append({"subject": o.name, "relation": "inside", "object": r.name})
                    elif r.contains_xy(xy, margin_m=-foot):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
            for other in self._scene.objects:
                if other.name == o.name:
                    continue
                dxy = np.abs(xy - self.object_pose(other.name)[:2, 3])
                if abs(bottom - extents[other.name][1]) < 0.006 and dxy.max() <= max(other.half_extents[:2]) + 1e-3:
                    rel.append({"subject": o.name, "relation": "on", "object": other.name})
        return {"sim_time_s": self.sim_time, "time": self.sim_time, "entities": ents, "relations": rel}

    def ground_truth(self) -> dict[str, Any]:
        """The privileged channel: what the simulator knows and no robot measures.

        Returns (YAML-ready) ``{"stamp_s", "objects": {name: {"position" (3,) m,
        "quat_wxyz", "shape", "half_extents" (3,) m, "mass_kg", "friction", "rgba"}},
        "held": [names touching both fingers], "finger_contacts": {"1": [...], "2": [...]},
        "object_contacts": [[a, b], ...], "relations": [...] (as :meth:`snapshot`)}``.
        Mass and friction are read from the live model (after any randomisation).
        Only benchmark scoring and tests read it (CONTRACT_9 section 2).
        """
        self._check_open()
        m = self._model
        objects: dict[str, Any] = {}
        for o in getattr(self._scene, "objects", ()):
            T = self.object_pose(o.name)
            objects[o.name] = {
                "position": _floats(T[:3, 3]), "quat_wxyz": mat_quat(T[:3, :3]), "shape": o.shape,
                "half_extents": [float(h) for h in o.half_extents],
                "mass_kg": float(m.body_mass[self._obj_body[o.name]]),
                "friction": float(m.geom_friction[self._obj_geom[o.name], 0]),
                "rgba": [float(c) for c in o.rgba],
            }
        left, right = self._finger_contacts()
        snap = self.snapshot()
        return {
            "stamp_s": self.sim_time,
            "objects": objects,
            "held": list(self.held_objects()),
            "finger_contacts": {"1": sorted(self._obj_names[i] for i in left),
                                "2": sorted(self._obj_names[i] for i in right)},
            "object_contacts": self._object_contacts(),
            "relations": snap["relations"],
        }

    def scene_record(self) -> dict[str, Any]:
        """The physical scene this target was built from (YAML-ready; masses, frictions,
        poses and, for a randomised world, the draw): for ``ground_truth.yaml`` only."""
        sc = self._scene
        out = sc.to_dict() if hasattr(sc, "to_dict") else {}
        decl = self._declared_scene
        if decl is not None and decl is not sc and hasattr(decl, "to_dict"):
            out["declared"] = decl.to_dict()
        draw = self.world_draw
        if draw:
            out = {**out, "draw": draw}
        return out

    def benchmark_signals(self) -> dict[str, Any]:
        """The target's own task-success signals (an external benchmark's checker), for
        ``ground_truth.yaml``'s ``benchmark:``; empty for the tabletop targets."""
        return {}

    def describe_declared(self) -> dict[str, Any]:
        """What the user declared (CONTRACT_9 section 3), YAML-ready: ``{"objects": [{name,
        class?, shape, colour_rgb, size_m}], "regions": [...], "obstacles": [...]}``;
        never mass, friction or pose of an object."""
        sc = self._declared_scene or self._scene
        drawn = bool(self.world_draw)
        objs = []
        for o in sc.objects:
            d: dict[str, Any] = {"name": o.name, "colour_rgb": [float(c) for c in o.rgba[:3]]}
            if not drawn:  # a randomised object's shape and size are the world's, not the user's
                d["shape"] = o.shape
                d["size_m"] = [round(2.0 * float(h), 4) for h in o.half_extents]
            if o.cls:
                d["class"] = o.cls
            objs.append(d)
        return {
            "objects": objs,
            "regions": [{"name": r.name, "center": [float(c) for c in r.center],
                         "half_extents": [float(h) for h in r.half_extents]} for r in sc.regions],
            "obstacles": [{"name": ob.name, "center": [float(c) for c in ob.center],
                           "half_extents": [float(h) for h in ob.half_extents]} for ob in sc.obstacles],
        }

