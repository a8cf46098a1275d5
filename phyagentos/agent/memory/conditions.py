"""The conditions a session runs under, and the scope a memory item applies to.

Conditions come only from what a robot's agent can know before execution (issue 9,
part 6): the goal (graph and node), the skill, the target and its embodiment (TARGETS.md
``driver``), the object the skill manipulates as the user *declared* it
(:mod:`phyagentos.agent.declared`: class, shape, colour, approximate size), what earlier
sessions of the run *observed* of it (:class:`~phyagentos.agent.memory.observed.ObservedObject`:
perceived size, shape class and colour, a mass estimated from the wrist load after a lift,
slips detected from proprioception), and *risk factors* derived from those:

==============  ===========================================================================
risk factor     detected when
==============  ===========================================================================
small_object    the narrower horizontal extent (perceived, else declared) is below
                :data:`SMALL_M`
large_object    the wider horizontal extent is above :data:`LARGE_M`
heavy_object    the mass estimated from the wrist load exceeds :data:`HEAVY_KG`
slipped_before  a slip of this object was detected from proprioception earlier in the run
clutter         another perceived entity stands within :data:`CLUTTER_GAP_M` of it
round_object    its shape class (perceived, else declared) is cylinder or sphere
==============  ===========================================================================

A memory item's *scope* is ``{embodiment, skill, object_class, risk_factors}`` (its
identity) and, where known, the object's declared ``category``, ``shape`` and ``size_m``.
Retrieval compares a scope with a session's conditions by similarity
(:mod:`~phyagentos.agent.memory.similarity`): same embodiment, skill, category and shape,
extents within the perception's spread, the item's situational risk factors among the
session's. Without a size on either side the older exact rule holds (:func:`scope_matches`):
equal object class, the item's risk factors a subset of the session's. The object class is
the user's declared ``class`` when given, else ``<shape>-<size band>`` (``box-medium``).

Backward reading: scopes written before this scheme (``box-4x4x4cm``, risk factors named
after simulator disturbances) are migrated when read (:func:`migrate_scope`): the old
class maps onto its size band and the disturbance names, which no robot could observe,
are dropped.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..declared import descriptor
from .observed import ObservedObject

__all__ = ["Conditions", "HEAVY_KG", "SMALL_M", "LARGE_M", "CLUTTER_GAP_M", "OBSERVABLE_RISK_FACTORS",
           "risk_factors", "scope_matches", "scope_identity", "session_conditions", "canonical", "object_class", "size_band",
           "migrate_scope"]

#: Mass estimate above which an object is heavy, kg (the Franka Hand carries 3 kg; at
#: 0.5 kg a 40 N two-finger grip on a friction-0.5 box has a safety factor below 4).
HEAVY_KG = 0.5
#: Narrower horizontal extent below which an object is small, m (a 3 cm object leaves
#: less than 1 cm of finger travel margin on the Franka Hand's 8 cm stroke ends).
SMALL_M = 0.03
#: Wider horizontal extent above which an object is large, m.
LARGE_M = 0.06
CLUTTER_GAP_M = 0.02
OBSERVABLE_RISK_FACTORS = ("small_object", "large_object", "heavy_object", "slipped_before", "clutter",
                           "round_object")
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
        object_class: declared class, else ``<shape>-<size band>`` (``None`` without an object).
        object_properties: observable properties: ``size_m`` (3,) m full extents, ``shape``,
            ``colour``, ``class``, ``mass_estimate_kg``, ``slips_seen``, with ``size_source``
            ``perceived`` or ``declared``.
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
        """The scope a lesson learned under these conditions gets: embodiment, skill, object
        class and risk factors (its identity, :func:`scope_identity`), and where known the
        object's declared ``category``, its ``shape`` and its ``size_m`` (3,) full extents in m
        (perceived, else declared), which retrieval compares by similarity
        (:mod:`~phyagentos.agent.memory.similarity`)."""
        out: dict[str, Any] = {"embodiment": self.embodiment, "skill": self.skill, "object_class": self.object_class,
                               "risk_factors": list(self.risk_factors)}
        props = self.object_properties
        if isinstance(props.get("class"), str):
            out["category"] = props["class"]
        if isinstance(props.get("shape"), str) and props["shape"] != "unknown":
            out["shape"] = props["shape"]
        if isinstance(props.get("size_m"), (list, tuple)) and len(props["size_m"]) == 3:
            out["size_m"] = [float(s) for s in props["size_m"]]
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"goal": self.goal, "skill": self.skill, "target": self.target, "embodiment": self.embodiment,
                "object": self.object, "object_class": self.object_class,
                "object_properties": dict(self.object_properties), "risk_factors": list(self.risk_factors)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Conditions":
        scope = migrate_scope(d)
        return cls(goal=str(d.get("goal", "")), skill=str(d.get("skill", "")), target=str(d.get("target", "")),
                   embodiment=str(d.get("embodiment", "")), object=d.get("object"),
                   object_class=scope.get("object_class"),
                   object_properties=dict(d.get("object_properties") or {}),
                   risk_factors=tuple(sorted(scope.get("risk_factors") or ())))


_OLD_CLASS = re.compile(r"^box-(\d+)x(\d+)x(\d+)cm$")


def size_band(size_m: Any) -> str:
    """``small`` / ``medium`` / ``large`` from (3,) full extents in m, ``unknown`` without a size."""
    if not isinstance(size_m, (list, tuple)) or len(size_m) < 2:
        return "unknown"
    narrow, wide = sorted(float(s) for s in size_m[:2])
    if narrow < SMALL_M:
        return "small"
    if wide > LARGE_M:
        return "large"
    return "medium"


def migrate_scope(scope: Mapping[str, Any]) -> dict[str, Any]:
    """A scope (or conditions mapping) in the current scheme; older ones are migrated
    (see the module docstring). Never raises; unknown values pass through."""
    out = dict(scope)
    cls = out.get("object_class")
    if isinstance(cls, str) and (m := _OLD_CLASS.match(cls)):
        out["object_class"] = f"box-{size_band([int(m.group(1)) / 100.0, int(m.group(2)) / 100.0])}"
    if out.get("risk_factors") is not None:
        out["risk_factors"] = sorted(r for r in out["risk_factors"] if r in OBSERVABLE_RISK_FACTORS)
    return out


def scope_identity(scope: Mapping[str, Any]) -> dict[str, Any]:
    """The keys of ``scope`` that identify a memory item (embodiment, skill, object class,
    risk factors): equal identities merge; the object's category, shape and size are its
    profile, compared by similarity, not part of the identity."""
    scope = migrate_scope(scope)
    return {key: scope.get(key) for key in (*_SCOPE_KEYS, "risk_factors")}


def scope_matches(scope: Mapping[str, Any], conditions: Conditions) -> bool:
    """True when an item of ``scope`` applies under ``conditions`` (see the module docstring)."""
    scope, mine = migrate_scope(scope), migrate_scope(conditions.scope())
    for key in _SCOPE_KEYS:
        if scope.get(key) != mine.get(key):
            return False
    return set(scope.get("risk_factors") or ()) <= set(mine["risk_factors"])


def _properties(declared: Mapping[str, Any] | None, observed: ObservedObject | None) -> dict[str, Any]:
    props: dict[str, Any] = {}
    if declared:
        for key in ("class", "shape", "colour", "size_m"):
            if key in declared:
                props[key] = declared[key]
        if "size_m" in declared:
            props["size_source"] = "declared"
    if observed is not None:
        if observed.size_m is not None:
            props["size_m"] = list(observed.size_m)
            props["size_source"] = "perceived"
        if observed.shape not in (None, "unknown"):
            props["shape"] = observed.shape
        if observed.colour_rgb is not None:
            props["colour"] = list(observed.colour_rgb)
        if observed.mass_estimate_kg is not None:
            props["mass_estimate_kg"] = observed.mass_estimate_kg
        if observed.slips:
            props["slips_seen"] = observed.slips
    return props


def object_class(declared: Mapping[str, Any] | None, observed: ObservedObject | None = None) -> str | None:
    """Declared ``class``, else ``<shape>-<size band>`` from the declared descriptor.

    Only the *declared* shape and size key the class, so the class of an object does not
    change in the middle of a run when perception first sees it (perceived properties go
    into the risk factors instead).
    """
    if declared is None:
        return None
    if isinstance(declared.get("class"), str):
        return declared["class"]
    return f"{declared.get('shape') or 'box'}-{size_band(declared.get('size_m'))}"


def risk_factors(props: Mapping[str, Any], observed: ObservedObject | None = None) -> tuple[str, ...]:
    """Risk factors from observable properties ``props`` (see :func:`session_conditions`)."""
    found: set[str] = set()
    band = size_band(props.get("size_m"))
    if band == "small":
        found.add("small_object")
    elif band == "large":
        found.add("large_object")
    if props.get("shape") in ("cylinder", "sphere"):
        found.add("round_object")
    if float(props.get("mass_estimate_kg") or 0.0) > HEAVY_KG:
        found.add("heavy_object")
    if int(props.get("slips_seen") or 0) > 0:
        found.add("slipped_before")
    if observed is not None and observed.nearest_gap_m is not None and observed.nearest_gap_m < CLUTTER_GAP_M:
        found.add("clutter")
    return tuple(sorted(found))


def session_conditions(*, goal: str, skill: str, target: str, embodiment: str, parameters: Mapping[str, Any],
                       scene: Mapping[str, Any] | None, object_name: str | None = None,
                       observed: ObservedObject | None = None) -> Conditions:
    """Conditions of a session of ``skill`` on ``target`` with ``parameters``.

    Args:
        scene: the goal graph's scene; only the declared descriptors are read
            (:func:`phyagentos.agent.declared.descriptor`).
        object_name: the manipulated object (default: the ``object`` parameter).
        observed: what earlier sessions of the run observed of the object.
    """
    obj = object_name if object_name is not None else parameters.get("object")
    obj = obj if isinstance(obj, str) else None
    if obj is None and skill.startswith("game_"):
        # Game skills act on an item or a creature, not on a scene object: memory is keyed on it.
        subject = parameters.get("item", parameters.get("creature"))
        if isinstance(subject, str):
            return Conditions(goal=goal, skill=skill, target=target, embodiment=embodiment, object=subject,
                              object_class=f"item:{subject}", object_properties={}, risk_factors=())
    declared = descriptor(scene, obj)
    props = _properties(declared, observed) if obj else {}
    return Conditions(goal=goal, skill=skill, target=target, embodiment=embodiment, object=obj,
                      object_class=object_class(declared, observed) if obj else None,
                      object_properties=props, risk_factors=risk_factors(props, observed) if obj else ())
