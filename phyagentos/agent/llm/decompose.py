"""The grammar side of planning: a request split into per-object clauses before the model is asked.

A 135M model emits one step per answer whatever the request says (measured: every
multi-object request of ``bench/language.py`` failed), so a multi-object request is first
split by rules over its words, and the model is then asked one clause at a time, each
answer constrained to one step (and, for a quantified clause, to the one object the rule
picked): the model still chooses the skill and the destination, the validator still
judges the result.

* a sequence -- ``..., then ...``, ``...; ...``, ``first ..., then ...`` -- gives one clause
  per part, in order (a later ``it`` names the earlier clause's object: resolved by the planner);
* a list after a colon -- ``sort the cubes by size: the large cube in the left bin, the small
  cube in the right bin`` -- gives one clause per item, with the head's verb;
* a quantifier over the scene's objects -- ``all``/``every``/``each``/``both``/``sort``, ``except
  the X``, a count (``two cubes``) -- gives the whole request once per object it covers (all but
  the excepted ones; the first N for a count, in the scene's order), the object fixed.

Anything else is one clause. Each clause is then grounded (:func:`ground`): the object it
moves is fixed when its words before the destination refer to exactly one object (by
colour, size or name), and the destinations offered are those its words after the
destination preposition name (regions, or an object to stack on after ``on``/``onto``);
``by colour``/``matching``/``its colour`` offers the region of the object's own colour.
What a clause leaves open stays open to the model.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

from .world import Entity, World

__all__ = ["Clause", "decompose", "ground"]

_SEQUENCE = re.compile(r"\s*(?:,\s*(?:and\s+)?then\s+|\s+and\s+then\s+|\s+then\s+|;\s*)")
_COUNTS = {"two": 2, "three": 3, "four": 4, "2": 2, "3": 3, "4": 4}
_ALL = {"all", "every", "each", "both", "sort", "everything"}
_VERBS = {"put", "place", "move", "stack", "set", "drop", "pick"}


@dataclass(frozen=True)
class Clause:
    """One part of a request: ``text`` for the model; ``object``: the object the rule fixed (``None``: the
    model chooses); ``destinations``: the destinations offered (schema names: a region, ``on_<object>``;
    ``None``: every destination); ``skills``: the skills offered (``None``: every plan skill), fixed when
    the request's verb says (:mod:`.meaning`: ``hold`` -> ``pick``)."""

    text: str
    object: str | None = None
    destinations: tuple[str, ...] | None = None
    skills: tuple[str, ...] | None = None


def _words(text: str) -> list[str]:
    return re.findall(r"[a-z0-9_]+", text.lower())


def _refers(words: Sequence[str], e: Entity) -> bool:
    parts = set(e.name.split("_")) - {"cube", "block", "box", "object"}
    return bool((e.colour and e.colour in words) or (e.size and e.size in words) or parts & set(words))


def decompose(request: str, world: World) -> list[Clause]:
    """The clauses of ``request`` over ``world``'s objects (see the module docstring)."""
    text = request.strip().rstrip(".")
    low = text.lower()
    parts = [p for p in _SEQUENCE.split(re.sub(r"^first\s+", "", low)) if p.strip()]
    if len(parts) >= 2:
        return [Clause(p.strip()) for p in parts]
    if ":" in low:
        head, tail = low.split(":", 1)
        items = [p.strip() for p in re.split(r",\s*(?:and\s+)?|\s+and\s+", tail) if p.strip()]
        if len(items) >= 2:
            verb = next((w for w in _words(head) if w in _VERBS), "put")
            return [Clause(item if _words(item)[:1] and _words(item)[0] in _VERBS else f"{verb} {item}")
                    for item in items]
    words = _words(low)
    objects = list(world.objects)
    count = next((_COUNTS[w] for w in words if w in _COUNTS), None)
    if "except" in words or "but" in words:
        key = "except" if "except" in words else "but"
        excluded_words = words[words.index(key) + 1:]
        # the excluded phrase ends where the destination starts ("... except the red one in the left bin")
        for stop in ("in", "into", "on", "onto", "to"):
            if stop in excluded_words:
                excluded_words = excluded_words[:excluded_words.index(stop)]
        excluded = [e for e in objects if _refers(excluded_words, e)]
        chosen = [e for e in objects if e not in excluded]
        if excluded and len(chosen) >= 1:
            return [Clause(text, e.name) for e in chosen]
        return [Clause(text)]
    if count is not None and count >= 2 and count <= len(objects):
        return [Clause(text, e.name) for e in objects[:count]]
    if set(words) & _ALL and len(objects) >= 2:
        return [Clause(text, e.name) for e in objects]
    return [Clause(text)]


_PREPOSITIONS = ("in", "into", "on", "onto", "to", "inside")
_STACK = {"on", "onto", "top", "upon"}
_GENERIC = {"cube", "cubes", "block", "blocks", "box", "boxes", "object", "objects", "region", "regions", "bin",
            "bins", "area", "the", "a"}


def _best(words: Sequence[str], entities: Sequence[Entity]) -> list[Entity]:
    """The entities ``words`` refer to most specifically (most matching name parts / colour / size)."""
    ws = set(words)
    scored = []
    for e in entities:
        score = len((set(e.name.split("_")) - _GENERIC) & ws) + (e.colour in ws if e.colour else 0) \
            + (e.size in ws if e.size else 0)
        if score:
            scored.append((score, e))
    top = max((sc for sc, _ in scored), default=0)
    return [e for sc, e in scored if sc == top]


def ground(clause: Clause, world: World) -> Clause:
    """``clause`` with its object fixed and its destinations narrowed where its words say so."""
    words = _words(clause.text)
    cut = next((i for i, w in enumerate(words) if w in _PREPOSITIONS and i > 0), len(words))
    subject, rest = words[:cut], words[cut:]
    obj = clause.object
    if obj is None:
        named = _best(subject, world.objects)
        obj = named[0].name if len(named) == 1 else None
    dests: list[str] = []
    mover = world.get(obj) if obj else None
    if mover is not None and {"colour", "color", "matching"} & set(words):
        dests = [r.name for r in world.regions if r.colour and r.colour == mover.colour]
    if not dests and rest:
        if rest[0] in _STACK or "top" in rest:  # "on the blue cube": a support, not the blue region
            dests = [f"on_{e.name}" for e in _best(rest, world.objects) if e.name != obj]
        if not dests:
            dests = [r.name for r in _best(rest, world.regions)]
    return Clause(clause.text, obj, tuple(dests) or None)
