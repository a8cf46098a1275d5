"""The world a plan is grounded in: named objects and regions with colour, size and position.

Built from the scene the request is about (the goal graph's or ``--scene`` file's
``scene`` mapping, i.e. what the user declared) and from ENVIRONMENT.md (what the runtime
last perceived). A plan uses only *perceived* object positions (:func:`perceived_world`):
a declared object the runtime has not seen yet has no position (``None``), and the Goal
Planner then looks first. Regions are part of the task's definition, so their declared
centres stand. Colours are named from ``rgba`` (nearest of :data:`PALETTE`), sizes
("small"/"large") relative to the scene's other objects. Names that fail the policy
(:mod:`.policy`) are left out and reported in ``rejected``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from .policy import NAME_PATTERN, InjectionFinding, screen_text

__all__ = ["Entity", "World", "PALETTE", "colour_name", "world_from_scene", "world_from_environment",
           "world_from_declared", "perceived_world"]

#: Colour names for rgba values (nearest in RGB).
PALETTE: Mapping[str, tuple[float, float, float]] = {
    "red": (0.8, 0.1, 0.1), "green": (0.1, 0.7, 0.2), "blue": (0.1, 0.2, 0.8), "yellow": (0.9, 0.8, 0.1),
    "orange": (0.95, 0.5, 0.05), "purple": (0.5, 0.1, 0.6), "white": (0.95, 0.95, 0.95), "black": (0.05, 0.05, 0.05),
    "grey": (0.5, 0.5, 0.5),
}


def colour_name(rgba: Sequence[float] | None) -> str | None:
    """Nearest :data:`PALETTE` name of an ``rgba`` (0..1), or ``None``."""
    if not rgba or len(rgba) < 3:
        return None
    return min(PALETTE, key=lambda n: sum((float(a) - b) ** 2 for a, b in zip(rgba[:3], PALETTE[n])))


@dataclass(frozen=True)
class Entity:
    """A named object or region: ``kind`` ``object``/``region``; ``position`` (x, y) in the world frame, m
    (``None``: an object not perceived yet); ``size_m`` the largest horizontal extent (m)."""

    name: str
    kind: str
    position: tuple[float, float] | None
    colour: str | None = None
    size: str | None = None
    size_m: float = 0.0

    def describe(self) -> str:
        words = [w for w in (self.size, self.colour) if w]
        noun = self.name.split("_")[-1] if self.kind == "object" else "region"
        return " ".join(words + [noun])


@dataclass(frozen=True)
class World:
    """The entities a plan may name. ``rejected`` lists names the policy refused."""

    objects: tuple[Entity, ...]
    regions: tuple[Entity, ...]
    source: str
    rejected: tuple[InjectionFinding, ...] = field(default_factory=tuple)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.objects + self.regions)

    def get(self, name: str) -> Entity | None:
        return next((e for e in self.objects + self.regions if e.name == name), None)


def _screen_name(name: Any, source: str, rejected: list) -> bool:
    text = str(name)
    findings = [InjectionFinding(source=f.source, code=f.code, text=text, match=f.match)
                for f in screen_text(text.replace("_", " "), source=source)]
    if not NAME_PATTERN.match(text):
        findings.append(InjectionFinding(source=source, code="invalid_name", text=text, match=text))
    rejected.extend(findings)
    return not findings


def _sizes(objects: list[dict]) -> dict[str, str]:
    extents = {o["name"]: max(o["half_extents"][:2]) for o in objects}
    if len(set(round(v, 4) for v in extents.values())) < 2:
        return {}
    mid = (min(extents.values()) + max(extents.values())) / 2
    return {n: ("large" if v > mid else "small") for n, v in extents.items()}


def world_from_scene(scene: Mapping[str, Any], *, source: str = "scene") -> World:
    """Entities of a goal graph's ``scene`` mapping (objects and regions; obstacles are not goals)."""
    rejected: list[InjectionFinding] = []
    raw_objects = [dict(o) for o in scene.get("objects") or [] if isinstance(o, Mapping)]
    raw_objects = [o for o in raw_objects if _screen_name(o.get("name"), f"{source}: object name", rejected)]
    for o in raw_objects:
        o.setdefault("half_extents", [0.02, 0.02, 0.02])
    sizes = _sizes(raw_objects)
    objects = tuple(Entity(name=o["name"], kind="object", position=(float(o["position"][0]), float(o["position"][1])),
                           colour=colour_name(o.get("rgba")), size=sizes.get(o["name"]),
                           size_m=2 * max(o["half_extents"][:2])) for o in raw_objects)
    regions = []
    for r in scene.get("regions") or []:
        if not isinstance(r, Mapping) or not _screen_name(r.get("name"), f"{source}: region name", rejected):
            continue
        regions.append(Entity(name=r["name"], kind="region", position=(float(r["center"][0]), float(r["center"][1])),
                              colour=colour_name(r.get("rgba")), size_m=2 * max(r.get("half_extents", [0.05, 0.05])[:2])))
    return World(objects=objects, regions=tuple(regions), source=source, rejected=tuple(rejected))


#: Colour words a declared name may carry (``akita_black_bowl_1``: black); "gray" reads as grey.
_NAME_COLOURS = frozenset(PALETTE) | {"gray"}
#: Words of a declared name that say its colour without a colour word: a porcelain mug is white
#: (LIBERO-90, a training suite, calls ``porcelain_mug_1`` "the white mug": task 67).
IMPLIED_COLOURS: Mapping[str, str] = {"porcelain": "white"}


def world_from_declared(objects: Sequence[str], fixtures: Sequence[str] = (), *, source: str = "declared") -> World:
    """A :class:`World` of declared names only (a LIBERO task's objects and fixtures): every
    object is an object a request may move, and every object and fixture a destination (a
    ``region`` of the reader). Colours are the palette words of a name (``akita_black_bowl_1``:
    black), else one a word of it implies (:data:`IMPLIED_COLOURS`: ``porcelain_mug_1``:
    white); no position (nothing perceived when it is read). Used by the LIBERO plan and the
    policy flow's prompt decomposition (:mod:`phyagentos.agent.instruction_steps`)."""

    def entity(name: str, kind: str) -> Entity:
        words = name.split("_")
        colour = next((w for w in words if w in _NAME_COLOURS), None) or next(
            (IMPLIED_COLOURS[w] for w in words if w in IMPLIED_COLOURS), None)
        return Entity(name=name, kind=kind, position=None, colour="grey" if colour == "gray" else colour)

    return World(objects=tuple(entity(n, "object") for n in objects),
                 regions=tuple(entity(n, "region") for n in (*objects, *fixtures)), source=source)


def world_from_environment(entities: Sequence[Mapping[str, Any]], *, source: str = "ENVIRONMENT.md") -> World:
    """Entities of ENVIRONMENT.md (what the runtime last perceived): objects with a pose, regions by kind;
    other kinds (robot, gripper, obstacle) are left out."""
    rejected: list[InjectionFinding] = []
    objects, regions = [], []
    for e in entities:
        name, kind = e.get("name"), e.get("kind", "object")
        pos = (e.get("pose") or {}).get("position") or e.get("position") or e.get("center")
        if kind not in ("object", "region"):  # the robot, its gripper and obstacles are not goals
            continue
        if pos is None or not _screen_name(name, f"{source}: {kind} name", rejected):
            continue
        ent = Entity(name=str(name), kind="region" if kind == "region" else "object",
                     position=(float(pos[0]), float(pos[1])), colour=colour_name(e.get("rgba")))
        (regions if ent.kind == "region" else objects).append(ent)
    return World(objects=tuple(objects), regions=tuple(regions), source=source, rejected=tuple(rejected))


def perceived_world(declared: World, seen: World) -> World:
    """``declared``'s objects with the positions ``seen`` (ENVIRONMENT.md) has for them, ``None``
    for those it has not seen, plus objects seen but not declared; regions as declared."""
    objects = []
    for e in declared.objects:
        hit = seen.get(e.name)
        objects.append(replace(e, position=hit.position if hit is not None and hit.kind == "object" else None))
    names = {e.name for e in declared.objects + declared.regions}
    objects += [e for e in seen.objects if e.name not in names]
    source = f"{declared.source} + {seen.source}" if seen.objects else f"{declared.source} (nothing perceived yet)"
    return World(objects=tuple(objects), regions=declared.regions, source=source,
                 rejected=declared.rejected + seen.rejected)


def distance(a: Entity, b: Entity) -> float:
    return math.hypot(a.position[0] - b.position[0], a.position[1] - b.position[1])
