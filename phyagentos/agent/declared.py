"""What the user declared about the world: the only part of a scene the Agent plane reads.

A goal graph's ``scene`` mapping also configures the simulator (poses, physical
parameters, scripted disturbances, randomisation); none of that is knowledge a robot has.
The Agent plane reads a scene only through :func:`declared_scene`, which keeps:

- per object its *descriptor*: ``name``, optional ``class`` (the user's object class,
  e.g. ``mug``), ``shape`` (box | cylinder | sphere | mesh), ``colour`` (a name, or ``rgba``
  0..1 as written in the scene) and an approximate size ``size_m`` (3,) full extents in
  m (``half_extents`` as written in shipped scenes count as the author's declared size:
  ``size_m = 2 * half_extents``);
- ``regions`` and ``obstacles`` as declared (a known map);
- ``fixtures`` as declared (``[{name, class}]``: the furniture of a scene, e.g. a LIBERO
  task's table, cabinet or stove, named with its category).

An object may also carry ``where`` (``{relation, of, part?}``): which of several identical
objects it is, by a spatial relation the Goal Planner read from the request (``the black
bowl next to the ramekin``); perception resolves it on what it sees.

Poses of objects, their physical parameters and anything else are dropped. The contract
is CONTRACT_9 section 3.
"""

from __future__ import annotations

from typing import Any, Mapping

__all__ = ["DESCRIPTOR_KEYS", "ObjectDescriptor", "declared_scene", "descriptor"]

#: Keys of an object descriptor the Agent may read.
DESCRIPTOR_KEYS = ("name", "class", "shape", "colour", "size_m")

ObjectDescriptor = dict  # name, class, shape, colour, size_m (see module docstring)


def _descriptor(obj: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"name": obj.get("name")}
    if isinstance(obj.get("class"), str):
        out["class"] = obj["class"]
    out["shape"] = str(obj.get("shape") or "box")
    colour = obj.get("colour", obj.get("color"))
    if colour is None and isinstance(obj.get("rgba"), (list, tuple)) and len(obj["rgba"]) >= 3:
        colour = [round(float(c), 3) for c in obj["rgba"][:3]]
    if colour is not None:
        out["colour"] = colour
    size = obj.get("size_m")
    if size is None and isinstance(obj.get("half_extents"), (list, tuple)):
        size = [2.0 * float(h) for h in obj["half_extents"]]
    if isinstance(size, (int, float)):
        size = [float(size)] * 3
    if isinstance(size, (list, tuple)) and len(size) == 3:
        out["size_m"] = [round(float(s), 4) for s in size]
    if isinstance(obj.get("where"), Mapping):
        out["where"] = dict(obj["where"])
    return out


def declared_scene(scene: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """The declared part of ``scene`` (see the module docstring), or ``None`` without a scene.

    Args:
        scene: a goal graph's ``scene`` mapping (objects, regions, obstacles, ...).

    Returns:
        ``{"objects": [descriptor, ...], "regions": [...], "obstacles": [...], "fixtures": [...]}``
        (keys absent from ``scene`` are absent here).
    """
    if not isinstance(scene, Mapping):
        return None
    objects = [_descriptor(o) for o in scene.get("objects") or () if isinstance(o, Mapping) and o.get("name")]
    out: dict[str, Any] = {"objects": objects}
    for key in ("regions", "obstacles", "fixtures"):
        if isinstance(scene.get(key), list):
            out[key] = [dict(r) for r in scene[key] if isinstance(r, Mapping)]
    return out


def descriptor(scene: Mapping[str, Any] | None, name: str | None) -> dict[str, Any] | None:
    """The descriptor of object ``name`` in ``scene`` (declared or raw), or ``None``."""
    if not name:
        return None
    declared = declared_scene(scene) if scene is not None and "objects" in scene else None
    for obj in (declared or {}).get("objects", ()):
        if obj.get("name") == name:
            return obj
    return None
