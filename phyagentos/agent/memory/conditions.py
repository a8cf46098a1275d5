"""The conditions a session runs under, and the scope a memory item applies to.

Conditions come from what the Agent legitimately knows before execution: the goal
(graph and node), the skill, the target and its embodiment (TARGETS.md ``driver``), the
object the skill manipulates with its declared properties (the goal graph's scene), and
*risk factors* detected from that scene:

==============  ===========================================================================
risk factor     detected when
==============  ===========================================================================
heavy_object    the object's declared mass exceeds :data:`HEAVY_KG`
low_friction    its declared friction is below :data:`LOW_FRICTION`
small_object    its narrower horizontal side is below :data:`SMALL_M`
clutter         another object stands within :data:`CLUTTER_GAP_M` of it
<kind>          the scene declares a perturbation of that kind for this object (or for
                every object): ``perception_noise``, ``low_friction``, ``displaced``,
                ``heavy_object`` (:mod:`phyagentos.targets.perturbations`). Only the
                kind is read, never its parameters or seed: the Agent knows *that* the
                cube is slippery, not how slippery, nor what to do about it.
==============  ===========================================================================

A memory item's *scope* is ``{embodiment, skill, object_class, risk_factors}``; it
applies to a session when embodiment, skill and object class are equal and the item's
risk factors are a subset of the session's (:func:`scope_matches`). A lesson learned on
one embodiment or object class is therefore never applied to another.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Mapping

__all__ = ["Conditions", "HEAVY_KG", "LOW_FRICTION", "SMALL_M", "CLUTTER_GAP_M", "risk_factors", "scope_matches",
           "session_conditions", "canonical"]

HEAVY_KG = 0.5
LOW_FRICTION = 0.3
SMALL_M = 0.03
CLUTTER_GAP_M = 0.02
_SCOPE_KEYS = ("embodiment", "skill", "object_class")


def canonical(value: Any) -> str:
    """Stable JSON text of ``value`` (sorted keys), for keys and hashes."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)


@dataclass(frozen=True)
class Conditions:
    """What a session's memory retrieval and consolidation are keyed on.

    Attributes:
        goal: ``<goal graph name>/<node id>``.
        skill, target: the session's skill and target names.
        embodiment: the target's driver (e.g. ``mujoco_franka``).
        object: the manipulated object's name, if any.
        object_class: shape and size, e.g. ``box-4x4x4cm`` (``None`` without an object).
        object_properties: declared ``mass_kg``, ``friction``, ``size_m`` (whatever the
            scene declares).
        risk_factors: sorted risk factor names (see the module docstring).
    """

    goal: str
    skill: str
    target: str
    embodiment: str
    object: str | None = None
    object_class: str | None = None
    object_properties: Mapping[str, Any] = field(default_factory=dict)
    risk_factors: tuple[str, ...] = ()

    def scope(self) -> dict[str, Any]:
        """The scope a lesson or knowledge entry learned under these conditions gets."""
        return {"embodiment": self.embodiment, "skill": self.skill, "object_class": self.object_class,
                "risk_factors": list(self.risk_factors)}

    def to_dict(self) -> dict[str, Any]:
        return {"goal": self.goal, "skill": self.skill, "target": self.target, "embodiment": self.embodiment,
                "object": self.object, "object_class": self.object_class,
                "object_properties": dict(self.object_properties), "risk_factors": list(self.risk_factors)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Conditions":
        return cls(goal=str(d.get("goal", "")), skill=str(d.get("skill", "")), target=str(d.get("target", "")),
                   embodiment=str(d.get("embodiment", "")), object=d.get("object"), object_class=d.get("object_class"),
                   object_properties=dict(d.get("object_properties") or {}),
                   risk_factors=tuple(sorted(d.get("risk_factors") or ())))


def scope_matches(scope: Mapping[str, Any], conditions: Conditions) -> bool:
    """True when an item of ``scope`` applies under ``conditions`` (see the module docstring)."""
    for key in _SCOPE_KEYS:
        if scope.get(key) != getattr(conditions, key):
            return False
    return set(scope.get("risk_factors") or ()) <= set(conditions.risk_factors)


def _object_class(obj: Mapping[str, Any]) -> str:
    he = obj.get("half_extents") or (0.02, 0.02, 0.02)
    w, d = sorted(float(x) * 200.0 for x in he[:2])  # full sizes, cm
    return f"box-{w:.0f}x{d:.0f}x{float(he[2]) * 200.0:.0f}cm"


def risk_factors(scene: Mapping[str, Any] | None, obj: str | None) -> tuple[str, ...]:
    """Risk factors of manipulating ``obj`` in ``scene`` (the goal graph's scene mapping)."""
    if not scene or not obj:
        return ()
    objects = {o.get("name"): o for o in scene.get("objects") or () if isinstance(o, Mapping)}
    me = objects.get(obj)
    found: set[str] = set()
    if me is not None:
        if float(me.get("mass", 0.0)) > HEAVY_KG:
            found.add("heavy_object")
        if "friction" in me and float(me["friction"]) < LOW_FRICTION:
            found.add("low_friction")
        he = me.get("half_extents") or (0.02, 0.02, 0.02)
        if 2.0 * min(float(he[0]), float(he[1])) < SMALL_M:
            found.add("small_object")
        x, y = (me.get("position") or (0.5, 0.0))[:2]
        for name, other in objects.items():
            if name == obj:
                continue
            ox, oy = (other.get("position") or (0.5, 0.0))[:2]
            ohe = other.get("half_extents") or (0.02, 0.02, 0.02)
            gap = max(abs(ox - x) - float(he[0]) - float(ohe[0]), abs(oy - y) - float(he[1]) - float(ohe[1]))
            if gap < CLUTTER_GAP_M:
                found.add("clutter")
    for p in scene.get("perturbations") or ():
        if isinstance(p, Mapping) and isinstance(p.get("kind"), str) and p.get("object") in (None, obj):
            found.add(p["kind"])
    return tuple(sorted(found))


def session_conditions(*, goal: str, skill: str, target: str, embodiment: str, parameters: Mapping[str, Any],
                       scene: Mapping[str, Any] | None, object_name: str | None = None) -> Conditions:
    """Conditions of a session of ``skill`` on ``target`` with ``parameters`` in ``scene``.

    ``object_name`` defaults to the ``object`` parameter.
    """
    obj = object_name if object_name is not None else parameters.get("object")
    obj = obj if isinstance(obj, str) else None
    props: dict[str, Any] = {}
    cls = None
    if obj and scene:
        me = next((o for o in scene.get("objects") or () if isinstance(o, Mapping) and o.get("name") == obj), None)
        if me is not None:
            cls = _object_class(me)
            if "mass" in me:
                props["mass_kg"] = float(me["mass"])
            if "friction" in me:
                props["friction"] = float(me["friction"])
            if "half_extents" in me:
                props["size_m"] = [round(2.0 * float(h), 4) for h in me["half_extents"]]
    if obj is None and skill.startswith("game_"):
        # Game skills act on an item or a creature, not on a scene object: memory is keyed on it.
        subject = parameters.get("item", parameters.get("creature"))
        if isinstance(subject, str):
            obj, cls = subject, f"item:{subject}"
    return Conditions(goal=goal, skill=skill, target=target, embodiment=embodiment, object=obj, object_class=cls,
                      object_properties=props, risk_factors=risk_factors(scene, obj))

