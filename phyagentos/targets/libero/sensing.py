"""What a LIBERO world lets the Agent plane and the perceiver know: the declared objects
and fixtures (names and BDDL categories), the perception parameters that suit LIBERO's
scenes, and the camera images (visual geoms only) (mixed into
:class:`~phyagentos.targets.libero.LiberoTarget`)."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

__all__ = ["LiberoSensing"]


class LiberoSensing:
    """Declared objects, perception parameters and camera rendering of a LIBERO world."""

    def describe_declared(self) -> dict[str, Any]:
        """What the Agent plane and the perceiver may know (CONTRACT_9 section 3):
        ``objects`` and ``fixtures`` as the scene declares them (objects ``[{name, class,
        shape?, colour?, size_m?, size_range_m?, shapes?, handle_origin_m?, where?}]``; ``where``: the spatial reference the Agent plane
        read from the instruction, never the task's init placement; fixtures ``[{name, class,
        size_m?, place?, knob?, drawers?, compartments?, root?, model_box?, door?, inside?, lean?}]``: a fixture's look,
        measured on its model on generated scenes,
        :mod:`phyagentos.perception.fixtures`), else every BDDL ``:objects`` /
        ``:fixtures`` entry as ``{name, class}`` (names and categories, as a user declares a
        scene); never a pose, region, goal or success signal."""
        keys = ("name", "class", "shape", "colour", "size_m", "size_range_m", "shapes", "handle_origin_m", "where")
        objects = ([{k: o[k] for k in keys if k in o} for o in self._scene.objects] if self._scene.objects
                   else self._problem.declared()["objects"])
        look = ("name", "class", "size_m", "place", "knob", "drawers", "compartments", "root", "model_box", "door",
                "inside", "lean")
        fixtures = ([{k: o[k] for k in look if k in o} for o in self._scene.fixtures]
                    if self._scene.fixtures else self._problem.declared()["fixtures"])
        return {"objects": objects, "fixtures": fixtures, "regions": [], "obstacles": []}

    #: Perception parameters of LIBERO's scenes that differ from the defaults
    #: (``protocol/perception.yaml``), measured on generated scenes (bench/libero_perception.py,
    #: docs/libero.md): LIBERO's objects are printed packages whose labels differ in colour
    #: from their bodies, so a segment is grouped by position (a chromaticity difference
    #: counts for little, eps 1.5 cm joins a woven basket's walls) and an object is not cut
    #: into its label's colours; its colour is the median of its most chromatic third (the
    #: cans' lids are alike, their labels are not); a shape mismatch costs 0.5, not 2: a bottle
    #: with a cap or a carton with a spout is seen as a box in one view and a cylinder in
    #: another (on 30 generated scenes: shape cost 2 -> 0.92 correct, 2 swapped; 0.5 -> 0.98, 0).
    #: Robosuite's Panda fingers are position servos (kp 1000 N/m, commanded closed): they
    #: squeeze what they hold with 1000 N/m times the opening per finger, so the default
    #: 5 N "squeeze" (a force-controlled hand) would call anything under 1 cm across empty --
    #: a bowl held by its wall (4 mm per finger, 4 N: a generated libero_spatial scene); 1 N
    #: is the servo's push at the perceiver's 1 mm minimum opening.
    PERCEPTION_OVERRIDES: dict[str, dict[str, Any]] = {
        "clustering": {"chromaticity_scale": 2.0, "lightness_scale": 10.0, "eps_m": 0.015},
        "shape": {"colour_from": "vivid"},
        "association": {"shape_cost": 0.5},
        "holding": {"min_effort_n": 1.0},
    }

    def perception_config(self):
        """The :class:`~phyagentos.perception.PerceptionConfig` that suits this world when the
        workspace has no ``perception.yaml``: the defaults with :attr:`PERCEPTION_OVERRIDES`,
        the robot base's exclusion disc at ``robot0_base`` (LIBERO's world origin is not the
        base), the support prior at the floor's or table's top and the crop around it."""
        from phyagentos.perception import PerceptionConfig  # noqa: PLC0415

        doc = PerceptionConfig.default().model_dump()
        for section, values in self.PERCEPTION_OVERRIDES.items():
            doc[section] = {**doc[section], **values}
        bx, by = float(self.ROBOT_BASE[0]), float(self.ROBOT_BASE[1])
        doc["workspace"] = {**doc["workspace"], "base_xy_m": (bx, by), "x_m": (bx + 0.15, bx + 1.2),
                            "y_m": (by - 0.6, by + 0.6)}
        doc["table"] = {**doc["table"], "expected_height_m": self._support_top_z()}
        return PerceptionConfig.model_validate(doc)

    def _support_top_z(self) -> float:
        """World z of the top of the support the objects stand on, m: under each object (its
        position at the last reset), the highest top among the support geoms (floor, table)
        there; the median over the objects (the scene's layout, not a pose an Agent reads). Not
        under their mean position: LIBERO-PRO's ``libero_10_with_milk`` keeps its milk carton
        7 m away and 8.6 m up in some init states, and the mean fell off the table: the prior
        was the floor's 0 m, the table's plane was never fitted and nothing was perceived."""
        m, d = self._model, self._data
        boxes = []
        for g in self._support_geoms:
            c, h = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            corners = c + h * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            w = d.geom_xpos[g] + corners @ d.geom_xmat[g].reshape(3, 3).T
            plane = m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE
            boxes.append((w.min(axis=0), w.max(axis=0), float(d.geom_xpos[g][2]) if plane else None))
        places = [d.xpos[b][:2] for b in self._obj_body.values()] or [np.zeros(2)]
        tops = []
        for xy in places:
            under = [top if top is not None else float(hi[2]) for lo, hi, top in boxes
                     if top is not None or (np.all(xy >= lo[:2]) and np.all(xy <= hi[:2]))]
            if under:
                tops.append(max(under))
        return float(np.median(tops)) if tops else 0.0

    @property
    def _capture_option(self) -> mujoco.MjvOption:
        """What a real camera sees: robosuite's visual geoms only (group 1 and up; its
        collision geoms are group 0), no sites."""
        opt = getattr(self, "_cap_opt", None)
        if opt is None:
            opt = self._cap_opt = mujoco.MjvOption()
            opt.sitegroup[:] = 0
            opt.geomgroup[0] = 0
        return opt

    def render(self, camera: str = "agentview", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 image of model camera ``camera`` (default LIBERO's
        ``agentview``; evidence images), visual geoms only (:meth:`_render_scene_option`).

        Raises:
            TargetError: an unknown camera or no OpenGL backend.
        """
        return super().render(camera, width, height, shadows=shadows)

    def _render_scene_option(self) -> mujoco.MjvOption:
        return self._capture_option
