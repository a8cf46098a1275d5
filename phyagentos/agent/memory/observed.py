"""What earlier sessions of a run observed of an object: perceived geometry, a mass
estimated from the wrist load, slips detected from proprioception.

Read from evidence bundles only: perceived snapshots (entities whose
``attributes.source`` is ``perceived``, CONTRACT_9 section 3) and the trace's ``load``
and ``slip`` entries (section 5). Entities without that source mark are not perception
and are ignored here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping

__all__ = ["ObservedObject", "observe_object"]


@dataclass(frozen=True)
class ObservedObject:
    """Observable facts about one object, accumulated over a run's evidence.

    Attributes:
        name: the object.
        size_m: (3,) full extents in m of the latest perceived box fit, or ``None``.
        shape: perceived shape class (box | cylinder | sphere | unknown), or ``None``.
        colour_rgb: perceived mean colour (3,) 0..1, or ``None``.
        mass_estimate_kg: the latest ``load`` entry's estimate, kg, or ``None``.
        slips: ``slip`` entries recorded for it.
        nearest_gap_m: smallest horizontal gap to another perceived entity in the latest
            perceived snapshot showing it, m (negative when touching), or ``None``.
    """

    name: str
    size_m: tuple[float, float, float] | None = None
    shape: str | None = None
    colour_rgb: tuple[float, ...] | None = None
    mass_estimate_kg: float | None = None
    slips: int = 0
    nearest_gap_m: float | None = None


def _perceived(snapshot: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    return {e["name"]: e for e in snapshot.get("entities", []) or ()
            if isinstance(e, Mapping) and (e.get("attributes") or {}).get("source") == "perceived"
            and e.get("kind") in ("object", "unknown")}


def _gap(a: Mapping[str, Any], b: Mapping[str, Any]) -> float:
    (x, y), (ox, oy) = a["position"][:2], b["position"][:2]
    (hx, hy), (ohx, ohy) = a["size"][:2], b["size"][:2]
    return max(abs(ox - x) - hx - ohx, abs(oy - y) - hy - ohy)


def observe_object(bundles: Iterable[Any], name: str | None) -> ObservedObject | None:
    """Fold ``bundles`` (evidence bundles, oldest first) into what was observed of ``name``.

    Returns ``None`` when ``name`` is ``None``.
    """
    if not name:
        return None
    size = shape = colour = mass = gap = None
    slips = 0
    for ev in bundles:
        for snap in (ev.initial, ev.terminal):
            ents = _perceived(snap or {})
            me = ents.get(name)
            if me is None:
                continue
            attrs = me.get("attributes") or {}
            if me.get("size"):
                size = tuple(round(2.0 * float(h), 4) for h in me["size"][:3])
            shape = attrs.get("shape", shape)
            if attrs.get("colour_rgb") is not None:
                colour = tuple(float(c) for c in attrs["colour_rgb"][:3])
            others = [_gap(me, o) for n, o in ents.items() if n != name and o.get("size")]
            gap = min(others) if others else None
        for rec in ev.trace:
            if rec.get("object") != name:
                continue
            if rec.get("kind") == "load" and rec.get("mass_estimate_kg") is not None:
                mass = round(float(rec["mass_estimate_kg"]), 3)
            elif rec.get("kind") == "slip":
                slips += 1
    return ObservedObject(name=name, size_m=size, shape=shape, colour_rgb=colour, mass_estimate_kg=mass,
                          slips=slips, nearest_gap_m=None if gap is None else round(gap, 4))
