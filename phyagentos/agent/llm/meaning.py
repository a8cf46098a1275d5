"""The meaning of a request, read by rules, and the check that a plan accounts for all of it.

A 135M model maps almost any request onto *some* pick-and-place (measured on requests
nobody here wrote: "pick it up and hold it" became a move into a bin, "leave the blocks
where they are" moved one, "the kitchen sink" became a bin). A plan that does something
other than what was asked is worse than a refusal, so before any model call the request
is read into clauses (:func:`read_request`), each with

* a **verb** class: ``move`` (put/place/move/set/drop/bring/sort ... *in* a region),
  ``stack`` (stack ... on, or put ... on/onto another object), ``hold`` (pick up, lift,
  grab, hold ... with no destination), ``push`` (push/shove/nudge ... to a side of a landmark:
  "push the plate to the front of the stove") or ``leave`` (leave ... where it is, don't move,
  do nothing);
* the **objects** it means, resolved on the scene: names, colours, sizes, comparatives and
  superlatives (``the bigger block`` is the one with the largest footprint among those the
  other words allow), pronouns (``it``/``them``: the previous clause's objects) and
  **quantifiers** (``all``/``every``/``each``/``both``/plural nouns, ``all ... except X``,
  counts ``one``/``a``/``two``/``three``);
* the **destination**: a region (by name words and colour), an object to stack on, the
  region of the object's own colour (``matching``/``its colour``), or ``where it is``.

One thing is read past: a word of no declared name between the article and a noun that
names exactly one object (``the wine bottle`` where the only bottle is ``white_bottle_1``:
LIBERO-PRO's replaced objects keep their old words) is **set aside** and said so
(:attr:`Meaning.assumed`); before the article (``pour the wine bottle``), as the noun itself
(``the kettle``), or with two bottles there, it is a problem as before.

What the rules cannot account for is a **problem**, and the planner refuses with it before
any model call: a destination the scene does not have (``the kitchen sink``: its words name
nothing there), a reference that picks no object or several where one is meant (``the
cube`` among three cubes, ``the bigger block`` among equal ones), a count larger than the
scene, a clause with no action the skills can do. A request whose every clause is
``leave`` needs no plan at all.

The clauses then fix, per model call, the object, the skill and the destinations
(:meth:`Meaning.clauses`), and after the model answered :meth:`Meaning.unaccounted` checks
the decoded steps against the clauses: every clause's verb, object, destination and
quantifier must be there, an object to be left must not move, and no step may do what no
clause asked. This is the gate for any model (an endpoint need not honour the schema).

Only English is read (:func:`detect_language`): the grammar rules and the offline model
are English-only, so a request in another language is refused saying which language was
detected, before any model call (docs/agent.md, "Languages").
"""

from __future__ import annotations

import contextvars
import re
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

from phyagentos.untrusted import quote

from .decompose import Clause, decompose
from .phrasing import DANGLING, WHERE_POSSIBLE, normalise
from .world import Entity, World

__all__ = ["Intent", "Meaning", "read_request", "detect_language", "RELATIONS"]

_MOVE = {"put", "place", "move", "set", "drop", "bring", "transfer", "carry", "sort", "relocate", "shift", "throw",
         "toss", "tidy", "slide", "deposit"}
_HOLD = {"hold", "lift", "grab", "grasp", "raise", "pick", "take", "get", "fetch"}
_STACK = {"stack", "pile"}
_LEAVE = {"leave"}
#: along the table with the closed hand, to a side of a landmark ("push the plate to the front of the stove")
_PUSH = {"push", "shove", "nudge"}
_VERBS = _MOVE | _HOLD | _STACK | _LEAVE | _PUSH | {"keep"}
#: the sides of a landmark a destination may name, as the scene camera shows the table: its ``left`` /
#: ``right``, its ``front`` (towards the viewer) and its ``back`` (away from it)
_LANDMARK_SIDES = ("left", "right", "front", "back")
_NEGATION = re.compile(r"\b(do\s+not|don'?t|never)\b")
_PREPOSITIONS = ("into", "in", "onto", "on", "to", "inside", "at")
_STACK_PREPOSITIONS = {"on", "onto"}
_KIND = {"cube", "cubes", "block", "blocks", "box", "boxes", "object", "objects", "thing", "things", "item", "items",
         "piece", "pieces", "brick", "bricks"}
_REGION_KIND = {"region", "regions", "area", "areas", "zone", "zones", "bin", "bins", "spot", "place", "tray",
                "square", "patch", "target", "goal", "trays", "container", "containers", "receptacle", "crate", "tub"}
#: words for a region that are also words for an object ("in the box"): a region only after in/into
_REGION_SYNONYMS = {"box", "boxes"}
#: a part of a fixture -> the fixture it belongs to: "on top of the drawer" is on top of the
#: cabinet whose drawer it is. Only a destination *on* the part reads as the whole ("into the
#: drawer" is its inside, which no region stands for).
_PART_OF = {"drawer": "cabinet", "drawers": "cabinet"}
#: Kinds of thing with a door that is opened and closed as the thing itself ("close the door": LIBERO's
#: microwave, whose closing is the fixture's articulated joint).
_HAS_DOOR = frozenset({"microwave"})
_STOP = {"the", "a", "an", "of", "please", "now", "then", "and", "carefully", "gently", "slowly", "up", "down",
         "that", "this", "these", "those", "which", "is", "are", "there", "too", "also", "just", "only", "again",
         "with", "your", "my", "robot", "arm", "gripper", "hand", "for", "me", "can", "you", "could", "would",
         "kindly", "first", "finally", "next", "after", "by", "top", "side", "its", "their", "own", "same",
         "colour", "color", "matching", "corresponding", "one", "ones", "other", "remaining", "rest", "others",
         "instead", "so", "it", "them", "they", "both", "all", "every", "each", "everything", "anything", "any",
         "some", "holding", "exactly", "precisely", "single"}
_ALL = {"all", "every", "each", "both", "everything", "anything"}
_COUNTS = {"one": 1, "a": 1, "an": 1, "any": 1, "two": 2, "three": 3, "four": 4, "five": 5, "1": 1, "2": 2, "3": 3,
           "4": 4, "5": 5}
_PRONOUNS = {"it", "them", "they", "that", "this", "these", "those"}
_BIGGER = {"bigger", "larger", "biggest", "largest", "taller", "tallest", "heavier", "heaviest"}
_SMALLER = {"smaller", "smallest", "littler", "littlest", "tinier", "tiniest", "shorter", "shortest", "lighter",
            "lightest"}
_SIZE_WORDS = {"large": "large", "big": "large", "huge": "large", "small": "small", "little": "small",
               "tiny": "small"}
_BY_COLOUR = {"matching", "colour", "color", "corresponding"}
_STAY = re.compile(r"\bwhere\s+(it|they|he|she)\s*(is|are|'s|'re|was|were)\b|\bin\s+place\b|\bas\s+(it|they)\s+"
                   r"(is|are|was|were)\b|\balone\b|\bwhere\s+(it|they)\s+(stand|stands|lie|lies|sit|sits)\b|"
                   r"\bas\s+is\b|\buntouched\b|\bundisturbed\b|\b(?:leave|let)\s+(?:it|them|everything|"
                   r"it\s+all|them\s+all)\s+be\b|\b(?:where|as|how)\s+(?:you|i)\s+found\s+(?:it|them)\b|"
                   r"\bthe\s+way\s+(it|they)\s+(is|are|was|were)\b")
_NOTHING = re.compile(r"\b(do\s+nothing|nothing|don'?t\s+do\s+anything|do\s+not\s+do\s+anything|stay\s+still)\b")
_AND_SPLIT = re.compile(r"\s*(?:,\s*and\s+|,\s+|\s+and\s+|\s+but\s+)(?=(?:then\s+)?(?:do\s+not|don'?t|never|turn|"
                        r"switch|open|close|shut|(?:slide|pull|swing)\s+(?:open|shut|closed?)|"
                        + "|".join(sorted(_VERBS)) + r")\b)")
#: "turn on the stove", "switch the stove off": a knob to turn (the verb ``turn_on`` / ``turn_off``).
_TURN = re.compile(r"^(?:please\s+)?(?:turn|switch)\s+(?:(on|off)\s+(.+)|(.+?)\s+(on|off))$")
#: "open the middle drawer of the cabinet", "close the top drawer": a part to slide or swing (the verb
#: ``open`` / ``close``; "shut" is "close").
#: "slide open", "pull open", "push shut" / "push closed": the verb's manner, the same open or close.
_OPEN = re.compile(r"^(?:please\s+)?(?:(?:slide|pull|push|swing)\s+(?=open\b|shut\b|close\b))?(open|close|shut)"
                   r"\s+(?:up\s+)?(.+)$")
#: Words for which of a fixture's drawers (the word before "drawer"), as the drawer's name.
#: "the middle layer of the drawer": a drawer as a level of the chest the word "drawer" stands for.
_LEVEL_WORDS = {"layer", "level", "tier", "row"}
_DRAWER_WORDS = {"top": "top", "upper": "top", "uppermost": "top", "topmost": "top", "middle": "middle",
                 "center": "middle", "centre": "middle", "bottom": "bottom", "lower": "bottom", "lowest": "bottom",
                 "bottommost": "bottom"}
#: "..., and the X in Y" / "... and X on Y" (the article may be dropped: "place white mug on left plate and
#: yellow-white mug on right plate"): a clause whose verb is the one before it
_ELLIPSIS = re.compile(r"\s*(?:,\s*and\s+|\s+and\s+|,\s+)(?=(?:the\s+)?[a-z0-9_][a-z0-9_ -]*?\s+"
                       r"(?:in|into|on|onto|to)\s)")

#: Common words of languages other than English (function words a request cannot avoid).
_LANGUAGES: dict[str, set[str]] = {
    "French": {"le", "la", "les", "du", "des", "dans", "sur", "mets", "mettez", "mettre", "prends", "prenez", "cube",
               "rouge", "bleu", "vert", "jaune", "gauche", "droite", "bac", "boîte", "et", "puis", "avec", "une", "un",
               "pose", "posez", "déplace", "déplacez", "sans", "de", "bloc", "prends", "tiens", "laisse"},
    "Spanish": {"el", "los", "las", "en", "pon", "ponga", "coloca", "mueve", "cubo", "rojo", "azul", "verde",
                "izquierda", "derecha", "caja", "y", "luego", "una", "un", "del", "al", "sobre", "toma", "deja"},
    "German": {"der", "die", "das", "den", "dem", "in", "auf", "lege", "legen", "stelle", "nimm", "würfel", "rote",
               "roten", "blaue", "blauen", "grüne", "links", "rechts", "kiste", "und", "dann", "ein", "eine", "linke",
               "rechte", "linken", "rechten", "halte", "lass",
               "einen", "bitte"},
    "Italian": {"il", "lo", "gli", "nel", "nella", "sul", "sulla", "metti", "prendi", "cubo", "rosso", "blu",
                "sinistra", "destra", "scatola", "e", "poi", "una", "un", "del", "della"},
    "Portuguese": {"o", "os", "as", "no", "na", "coloque", "ponha", "pegue", "cubo", "vermelho", "azul",
                   "esquerda", "direita", "caixa", "e", "depois", "uma", "um", "do", "da"},
    "Dutch": {"de", "het", "een", "in", "op", "leg", "zet", "pak", "kubus", "rode", "blauwe", "links", "rechts",
              "bak", "en", "dan"},
}
_ENGLISH = {"the", "a", "an", "in", "into", "on", "onto", "to", "put", "place", "move", "pick", "up", "and", "then",
            "it", "of", "cube", "block", "bin", "region", "left", "right", "all", "stack", "hold", "leave", "where",
            "red", "blue", "green", "yellow", "them", "each", "except", "with", "is", "are", "take", "box", "cubes",
            "blocks", "one", "two", "please", "lift", "grab", "drop", "set", "bigger", "smaller", "they", "by", "top"}
_SCRIPTS = ((re.compile(r"[\u0400-\u04ff]"), "Cyrillic script"), (re.compile(r"[\u4e00-\u9fff\u3040-\u30ff]"),
            "Chinese/Japanese script"), (re.compile(r"[\u0600-\u06ff]"), "Arabic script"),
            (re.compile(r"[\uac00-\ud7af]"), "Korean script"), (re.compile(r"[\u0370-\u03ff]"), "Greek script"),
            (re.compile(r"[\u0590-\u05ff]"), "Hebrew script"), (re.compile(r"[\u0900-\u097f]"), "Devanagari script"))


#: two words people say for what a declared name writes as one (LIBERO's ``chefmate_8_frypan``: "the frying pan")
_COMPOUNDS = {("frying", "pan"): "frypan", ("fry", "pan"): "frypan"}


class _Word(str):
    """A token that stands for other words than its own: a compound (:data:`_COMPOUNDS`), equal to
    and hashed as the one word the names write (``frypan``), with ``said`` the words it was said
    as (``frying pan``), which messages quote (:func:`_said`)."""

    said: str

    def __new__(cls, word: str, said: str) -> "_Word":
        out = super().__new__(cls, word)
        out.said = said
        return out


def _tokens(text: str) -> list[str]:
    words = re.findall(r"[a-z0-9_]+|[^\W\d_]+", text.lower())
    out: list[str] = []
    for w in words:
        if out and (out[-1], w) in _COMPOUNDS:
            out[-1] = _Word(_COMPOUNDS[(out[-1], w)], f"{_said_word(out[-1])} {w}")
        else:
            out.append(w)
    return out


def _said_word(word: str) -> str:
    return getattr(word, "said", word)


def _said(words) -> str:
    """``words`` (tokens) joined as the request said them: a compound as its own words ("the
    frying pan", not "the frypan")."""
    return " ".join(_said_word(w) for w in words)


def detect_language(text: str, names: Sequence[str] = ()) -> str | None:
    """The language of ``text`` when it is not English (a name such as ``French`` or ``Cyrillic script``),
    else ``None``. Words that are scene names are not counted; a request counts as another language when
    it has a letter outside English's alphabet (accents, another script) together with more words of that
    language than English ones, or at least three such words and more of them than English ones."""
    for pattern, script in _SCRIPTS:
        if pattern.search(text):
            return script
    words = [w for w in _tokens(text) if w not in set(names) and "_" not in w]
    if not words:
        return None
    english = sum(w in _ENGLISH for w in words)
    accented = bool(re.search(r"[à-öø-ÿœ]", text.lower()))
    best, hits = None, 0
    for lang, vocab in _LANGUAGES.items():
        n = sum(w in vocab and w not in _ENGLISH for w in words)
        if n > hits:
            best, hits = lang, n
    if best is not None and hits > english and (hits >= 3 or (accented and hits >= 1)):
        return best
    if accented and english == 0:
        return "a language other than English"
    return None


@dataclass(frozen=True)
class Intent:
    """One clause as read: ``verb`` (``move``/``stack``/``hold``/``push``/``leave``, or ``turn_on``/``turn_off``: the
    knob of the one object named, a declared thing or fixture), ``objects`` it means (in the
    scene's order), ``count`` (a count quantifier: that many of ``objects`` -- the candidates), ``destinations``
    (region names, or one object to stack on; empty for hold/leave), ``by_colour`` (each object to the region
    of its colour), ``excluded`` (objects an ``except`` leaves out: they stay)."""

    text: str
    verb: str
    objects: tuple[str, ...]
    destinations: tuple[str, ...] = ()
    count: int | None = None
    by_colour: bool = False
    excluded: tuple[str, ...] = ()
    #: ``open`` / ``close``: which part of the object ("middle" of "the middle drawer of the cabinet"; None: the
    #: object itself, or a drawer not told apart); ``move``: the drawer of the one destination whose inside the
    #: objects go into ("in the top drawer of the cabinet", "open the top drawer and put the bowl inside"), or its
    #: compartment on the viewer's side ("back" of "in the back compartment of the caddy")
    part: str | None = None
    #: ``open`` / ``close`` / ``move``: the kind of part named ("drawer", or "compartment" for a move; None: the
    #: object itself)
    part_kind: str | None = None
    #: ``move``: set down beside its one destination, on the viewer's ``left`` / ``right`` of it ("to the right
    #: of the plate"), or in ``front`` of it (towards the viewer) / at its ``back``, not on it; ``push``: the side
    #: of its one destination it is pushed to (read only with ``read_request(..., relations=True)``); None: in /
    #: on it
    beside: str | None = None

    def movers(self) -> tuple[str, ...]:
        """The objects the clause's steps act on (a count: the first ``count`` candidates, in the scene's order)."""
        return self.objects[: self.count] if self.count is not None else self.objects


@dataclass
class Meaning:
    """A request as read: its ``intents`` and the ``problems`` the rules could not account for."""

    request: str
    intents: list[Intent] = field(default_factory=list)
    #: (code, message): code ``unknown_object``, ``unknown_destination`` or ``not_understood``
    problems: list[tuple[str, str]] = field(default_factory=list)
    language: str | None = None
    #: the request with ordinary phrasings rewritten into the rules' forms (:func:`.phrasing.normalise`)
    text: str = ""
    #: objects picked out by a spatial relation (``read_request(..., relations=True)``): the declared name the
    #: reader bound the reference to -> ``{"relation": ..., "of": [landmark names], "part": ...}``
    where: dict[str, dict] = field(default_factory=dict)
    #: words the reader set aside, each said in a sentence: a modifier of no declared name before a noun that
    #: names one object ("'the wine bottle': 'wine' names nothing here; read as white_bottle_1, the one bottle")
    assumed: list[str] = field(default_factory=list)

    @property
    def nothing_to_do(self) -> bool:
        """Every clause asks that nothing moves."""
        return bool(self.intents) and all(i.verb == "leave" for i in self.intents)

    def destinations_for(self, intent: Intent, obj: str, world: World) -> tuple[str, ...]:
        if intent.by_colour:
            mover = world.get(obj)
            return tuple(r.name for r in world.regions if mover is not None and r.colour and r.colour == mover.colour)
        if intent.verb == "stack":
            return tuple(f"on_{d}" for d in intent.destinations if d != obj)
        return intent.destinations

    def clauses(self, world: World) -> list[Clause]:
        """One clause per (acting intent, object): object, skill and destinations fixed by the rules."""
        out = []
        for it in self.intents:
            if it.verb == "leave":
                continue
            skills = (("pick",) if it.verb == "hold" else ("turn_knob",) if it.verb in ("turn_on", "turn_off")
                      else ("slide_drawer",) if it.verb in ("open", "close") else ("push",) if it.verb == "push"
                      else ("pick_and_place",))
            for obj in it.movers():
                out.append(Clause(it.text, obj, self.destinations_for(it, obj, world) or None, skills=skills))
        return out

    def unaccounted(self, steps: Sequence, world: World) -> list[str]:
        """What of the request the ``steps`` (``skill``, ``object``, ``destination``) do not account for, and
        what they do that no clause asked (empty: the plan means the request)."""
        out: list[str] = []
        acting = [(it, obj) for it in self.intents if it.verb != "leave" for obj in it.movers()]
        for k, (it, obj) in enumerate(acting):
            step = steps[k] if k < len(steps) else None
            want = self.destinations_for(it, obj, world)
            what = {"hold": f"pick up and hold {obj}", "stack": f"stack {obj} on {' or '.join(it.destinations)}",
                    "turn_on": f"turn {obj} on", "turn_off": f"turn {obj} off",
                    "open": f"open {_part_phrase(it, obj)}", "close": f"close {_part_phrase(it, obj)}",
                    "move": f"move {obj} into {' or '.join(want) if want else 'a region'}",
                    "push": f"push {obj} to the {it.beside} of {' or '.join(want)}"}[it.verb]
            if step is None:
                out.append(f"{quote(it.text)} asks to {what}, and no step does")
                continue
            dest = step.destination
            if step.object != obj and it.count is None:
                out.append(f"{quote(it.text)} asks to {what}; the step moves {step.object}")
            elif it.count is not None and step.object not in it.objects:
                out.append(f"{quote(it.text)} asks for {it.count} of {', '.join(it.objects)}; the step moves "
                           f"{step.object}")
            elif it.verb == "hold" and (step.skill != "pick" or dest is not None or k != len(acting) - 1):
                out.append(f"{quote(it.text)} asks to {what} (a pick, last); the step is {step.skill} of "
                           f"{step.object} to {dest or 'nothing'}")
            elif it.verb == "push" and (step.skill != "push" or dest not in want):
                out.append(f"{quote(it.text)} asks to {what}; the step is {step.skill} of {step.object} to "
                           f"{dest or 'nothing'}")
            elif it.verb == "stack" and (dest is None or f"on_{dest}" not in want):
                out.append(f"{quote(it.text)} asks to {what}; the step puts it {'in ' + dest if dest else 'nowhere'}")
            elif it.verb == "move" and (dest is None or (want and dest not in want)
                                        or (world.get(dest) is not None and world.get(dest).kind != "region")):
                out.append(f"{quote(it.text)} asks to {what}; the step puts it {'on ' + dest if dest else 'nowhere'}")
        for step in steps[len(acting):]:
            out.append(f"the step {step.skill} of {step.object} is asked by no part of the request")
        for it in self.intents:
            if it.count is not None:
                moved = {s.object for s in steps if s.object in it.objects}
                if len(moved) != it.count and not out:
                    out.append(f"{quote(it.text)} asks for {it.count} object(s); the plan moves {len(moved)}")
            stay = list(it.excluded) + (list(it.objects) if it.verb == "leave" else [])
            for obj in stay:
                if any(s.object == obj for s in steps):
                    out.append(f"{quote(it.text)} asks that {obj} stays where it is; a step moves it")
        return list(dict.fromkeys(out))


# -- reading ---------------------------------------------------------------------------------------------


def _parts(request: str, world: World) -> list[str]:
    """The request's clause texts: decompose's sequences and colon lists, then ``..., and <verb> ...`` and
    ``... and the X in Y`` (an elided verb) inside each part."""
    text = request.strip().rstrip(".!")
    split = decompose(text, world)
    texts = list(dict.fromkeys(c.text for c in split)) if len({c.text for c in split}) > 1 else [text]
    out = []
    for t in texts:
        for p in _AND_SPLIT.split(t):
            pieces = [q for q in _ELLIPSIS.split(p) if q and q.strip()]
            # "put both the X and the Y in Z": no destination before the "and", so one clause
            # over a conjunction of objects, not an elided verb
            if len(pieces) > 1 and not set(_tokens(pieces[0])) & set(_PREPOSITIONS):
                pieces = [p]
            # "... and yellow and white mug on the right plate": a later piece with no destination
            # is a conjunction inside the next one's object phrase, not a clause of its own
            joined: list[str] = []
            for i, q in enumerate(pieces):
                if joined and i > 1 and not set(_tokens(joined[-1])) & set(_PREPOSITIONS):
                    joined[-1] = f"{joined[-1]} and {q}"
                else:
                    joined.append(q)
            out += joined
    return [p.strip(" ,;") for p in out if p.strip(" ,;")]


def _colours(world: World) -> set[str]:
    return {e.colour for e in world.objects + world.regions if e.colour}


#: The palette words an object's name may carry (``white_yellow_mug_1``: white, yellow).
_PALETTE = frozenset({"red", "green", "blue", "yellow", "orange", "purple", "white", "black", "grey", "gray"})


#: other words for a word of a declared name (LIBERO-PRO's changed tasks: "put the pan on it" for
#: ``chefmate_8_frypan_1``, "pick up the cup" for ``white_yellow_mug_1``)
_NAME_WORD_ALIASES: Mapping[str, frozenset[str]] = {"frypan": frozenset({"pan", "skillet"}),
                                                    "mug": frozenset({"cup"})}


def _name_parts(e: Entity) -> set[str]:
    parts = set(e.name.split("_")) - _KIND - _REGION_KIND - _STOP - _VERBS - set(_PREPOSITIONS)
    return parts | {alias for p in parts for alias in _NAME_WORD_ALIASES.get(p, ())}


def _name_colours(e: Entity) -> set[str]:
    """The palette words of an entity's name (``white_yellow_mug_1``: white, yellow)."""
    return set(e.name.split("_")) & _PALETTE


def _filter(words: Sequence[str], cands: Sequence[Entity], world: World) -> tuple[list[Entity], list[str]]:
    """The candidates ``words`` (an object phrase) allow, and what in the words matched nothing."""
    ws = list(words)
    named = [e for e in cands if e.name in ws]
    if named:
        return named, []
    out = list(cands)
    misses: list[str] = []
    colours = [w for w in ws if w in _colours(world) or w in {"red", "green", "blue", "yellow", "orange", "purple",
                                                               "white", "black", "grey", "gray"}]
    uncoloured: list[Entity] = []
    if colours:
        # an object of no known colour may be the one meant when the coloured ones that match carry a
        # colour not named ("the white mug" beside a white_yellow_mug and a porcelain mug of no colour word)
        extra = [e for e in out if e.colour in colours and _name_colours(e) - set(colours)]
        uncoloured = [e for e in out if e.colour is None] if extra else []
        out = [e for e in out if e.colour in colours]
        # "the white mug": one that is white and nothing else named before a white-and-yellow one
        exact = [e for e in out if not _name_colours(e) - set(colours)]
        out = exact or out
        if not out:
            misses.append(f"nothing {'/'.join(colours)}")
    parts = [w for w in ws if any(w in _name_parts(e) for e in cands) and w not in colours]
    if parts:
        out = [e for e in out if set(parts) & _name_parts(e)]
        uncoloured = [e for e in uncoloured if set(parts) & _name_parts(e)]
    out += uncoloured
    sizes = [_SIZE_WORDS[w] for w in ws if w in _SIZE_WORDS]
    if sizes and out:
        labelled = [e for e in out if e.size in sizes]
        if labelled:
            out = labelled
        else:
            extreme = max if sizes[0] == "large" else min
            best = extreme(e.size_m for e in out)
            out = [e for e in out if e.size_m == best] if len({e.size_m for e in out}) > 1 else out
            if len(out) > 1:
                misses.append(f"'{[w for w in ws if w in _SIZE_WORDS][0]}': the candidates are the same size")
    if (set(ws) & _BIGGER or set(ws) & _SMALLER) and out:
        extreme = max if set(ws) & _BIGGER else min
        word = next(w for w in ws if w in _BIGGER | _SMALLER)
        if len({round(e.size_m, 4) for e in out}) < 2 and len(out) > 1:
            misses.append(f"'{word}': {', '.join(e.name for e in out)} are the same size")
        else:
            best = extreme(e.size_m for e in out)
            out = [e for e in out if e.size_m == best]
    return out, misses


def _conjunction(words: list[str], world: World) -> tuple[str, ...] | None:
    """The objects of ``the X and the Y`` (``both`` allowed), in the order named, when each
    part refers to exactly one object and no two to the same, and the parts before the last
    are not colours alone joined before one object's name ("the yellow and white mug" is one
    mug, the white_yellow_mug, even beside a yellow mug and a white one; "the yellow mug and the
    white mug" is two); else ``None`` (the phrase is read whole)."""
    groups: list[list[str]] = [[]]
    for w in words:
        if w == "and":
            groups.append([])
        elif w != "both":
            groups[-1].append(w)
    if len(groups) < 2 or not all(groups):
        return None
    # colours joined before one noun ("the yellow and white mug"): one object, when exactly one
    # object's name has every word, though a yellow mug and a white one stand beside it
    content = [w for w in words if w not in _STOP and w not in ("and", "both")]
    if (all(w in _PALETTE for g in groups[:-1] for w in g if w not in _STOP)
            and sum(1 for e in world.objects if set(content) <= _name_parts(e)) == 1):
        return None
    names = []
    for g in groups:
        objs, count, problems = _read_objects(g, world, ())
        if problems or count is not None or len(objs) != 1:
            return None
        names.append(objs[0])
    return tuple(names) if len(set(names)) == len(names) else None


#: What :func:`read_request` set aside while reading (:func:`_set_aside`); None outside a reading.
_ASSUMED: contextvars.ContextVar[list[str] | None] = contextvars.ContextVar("meaning_assumed", default=None)


def _set_aside(words: list[str], unknown: list[str], world: World,
               previous: tuple[str, ...]) -> tuple[str, ...] | None:
    """The one object an object phrase names with its ``unknown`` words set aside, or None.

    Only modifiers are set aside: every unknown word stands after the phrase's last article
    (``the``, ``a``, ``an``) and before its last word, the noun, which is a word of a declared
    name; the phrase asks for one thing (no quantifier, no plural, no conjunction); and the rest
    names exactly one object with no problem. Said in :data:`_ASSUMED`."""
    articles = [i for i, w in enumerate(words) if w in ("the", "a", "an")]
    start = articles[-1] + 1 if articles else 0
    noun = len(words) - 1
    if noun < 1 or words[noun] in unknown or "and" in words or set(words) & (_ALL | set(_COUNTS) - {"a", "an"}):
        return None
    if not all(start <= i < noun for i, w in enumerate(words) if w in unknown):
        return None
    rest = [w for w in words if w not in unknown]
    objects, count, problems = _read_objects(rest, world, previous)
    if problems or count is not None or len(objects) != 1:
        return None
    said = ", ".join(repr(w) for w in unknown)
    note = (f"{quote(_said(words))}: {said} {'names' if len(unknown) == 1 else 'name'} nothing here; read as "
            f"{objects[0]}, the one {_said_word(words[noun])}")
    assumed = _ASSUMED.get()
    if assumed is not None and note not in assumed:
        assumed.append(note)
    return objects


def _read_objects(words: list[str], world: World, previous: tuple[str, ...]) -> tuple[tuple[str, ...], int | None,
                                                                                       list[str]]:
    """(objects, count, problems) of an object phrase; ``count`` is set for a count quantifier."""
    cands = list(world.objects)
    if not words:
        return previous, None, ([] if previous else [("not_understood", "no object is named")])
    content = [w for w in words if w not in _STOP or w in _ALL or w in _COUNTS or w in _PRONOUNS]
    if set(words) & {"it", "them", "they"} and not (set(words) & _ALL) and previous and not any(
            w in _colours(world) or w in _SIZE_WORDS or w in _BIGGER | _SMALLER or w in _KIND for w in words) \
            and set(words) <= _STOP | _PRONOUNS:  # "hold it and shake it": 'shake' is not accounted for
        return previous, None, []
    # "the X and the Y" is both; "the smaller of the X and Y cubes" is one of them (the
    # comparative chooses among the conjunction, below)
    if "and" in words and not set(words) & (_BIGGER | _SMALLER):
        joined = _conjunction(words, world)
        if joined:
            return joined, None, []
    # "both moka pots": a plural of a word of the declared names stands for that word, and for
    # every object it names
    singular = _singulars(words, cands)
    if singular:
        words = [singular.get(w, w) for w in words]
        content = [singular.get(w, w) for w in content]
    count = None
    for i, w in enumerate(words):
        nxt = words[i + 1:i + 3]
        if w in _COUNTS and (set(nxt) & _KIND or i == 0 or (w != "one" and nxt)):
            if w in ("a", "an") and not set(words[i + 1:]) & _KIND:
                continue
            if set(words[:i]) & (_BIGGER | _SMALLER) and "of" in words[:i]:
                # "the smaller of the two blue cubes": the two are what is compared, one is meant
                if (w not in ("a", "an", "one", "any") and len(_filter([x for x in words[i + 1:] if x not in _STOP],
                                                                   cands, world)[0]) != _COUNTS[w]):
                    return (), None, [("not_understood", f"{quote(_said(words))}: the scene does not have "
                                                         f"{w} of them")]
                continue
            count = _COUNTS[w]
            break
    known = (_KIND | _ALL | set(_COUNTS) | _PRONOUNS | _STOP | set(_SIZE_WORDS) | _BIGGER | _SMALLER
             | {"red", "green", "blue", "yellow", "orange", "purple", "white", "black", "grey", "gray"}
             | {p for e in cands for p in e.name.split("_")} | {p for e in cands for p in _name_parts(e)}
             | {e.name for e in cands} | {"by", "colour", "color"})
    unknown = [w for w in content if w not in known]
    if unknown and not singular and (aside := _set_aside(words, unknown, world, previous)) is not None:
        return aside, None, []
    if unknown:
        return (), None, [("unknown_object", f"{quote(_said(words))}: {', '.join(repr(w) for w in unknown)} names "
                                             f"no object of the scene (it has {', '.join(e.name for e in cands)})")]
    found, misses = _filter(content, cands, world)
    plural = (any(w in _KIND and w.endswith(("s", "es")) for w in words) or set(words) & _ALL or "ones" in words
              or bool(singular))
    if misses and not found:
        return (), None, [("unknown_object", f"{quote(_said(words))} refers to no object of the scene "
                                             f"({'; '.join(misses)})")]
    if misses:
        return (), None, [("not_understood", f"{quote(_said(words))}: {'; '.join(misses)}")]
    if not found:
        return (), None, [("unknown_object", f"{quote(_said(words))} refers to no object of the scene")]
    if len(found) > 1 and count is None and not plural:
        # one object meant, several share a word ("the tomato sauce" beside a bbq sauce): the one
        # whose name has every word the phrase names, when exactly one has
        said = {w for w in content if any(w in _name_parts(e) for e in found)}
        whole = [e for e in found if said and said <= _name_parts(e)]
        # not when a colour named may be that of one whose colour is unknown (a porcelain mug, "the white mug")
        if len(whole) == 1 and not (said & _name_colours(whole[0]) and any(e.colour is None for e in found)):
            found = whole
    names = tuple(e.name for e in found)
    if count is not None:
        if count > len(names):
            return (), None, [("not_understood", f"{quote(_said(words))} asks for {count}; the scene has "
                                                 f"{len(names)}: {', '.join(names)}")]
        return names, (count if count < len(names) else None), []
    if "both" in words and len(names) != 2:
        return (), None, [("not_understood", f"{quote(_said(words))}: 'both' names two; the scene has "
                                             f"{len(names)}: {', '.join(names)}")]
    if plural or len(names) == 1:
        return names, None, []
    return (), None, [("not_understood", f"{quote(_said(words))} could be any of {', '.join(names)}: say which")]


def _singulars(words: Sequence[str], cands: Sequence[Entity]) -> dict[str, str]:
    """``{plural: singular}`` for each word of ``words`` that is no word of the candidates'
    names but, less its ``s`` or ``es``, is one (``pots`` -> ``pot`` for ``moka_pot_1``)."""
    parts = {p for e in cands for p in e.name.split("_")}
    out = {}
    for w in words:
        if w in parts or w in _KIND:
            continue
        for cut in ("es", "s"):
            if w.endswith(cut) and len(w) > len(cut) + 1 and w[:-len(cut)] in parts:
                out[w] = w[:-len(cut)]
                break
    return out


def _read_destination(words: list[str], prep: str, world: World, previous: tuple[str, ...],
                      movers: tuple[str, ...]) -> tuple[str, tuple[str, ...], bool, list[str]]:
    """(kind ``region``/``object``, names, by_colour, problems) of a destination phrase after ``prep``."""
    ws = [w for w in words if w not in ("the", "a", "an", "of")]
    if set(ws) & _BY_COLOUR and not (set(ws) & (_colours(world) - {None})):
        return "region", (), True, []
    if prep in _STACK_PREPOSITIONS or "top" in ws:
        others = [e for e in world.objects if e.name not in movers]
        if set(ws) & {"it", "them"} and previous:
            sup = [p for p in previous if p not in movers]
            if len(sup) == 1:
                return "object", (sup[0],), False, []
        objs, misses = _filter([w for w in ws if w not in _STOP], others, world)
        nouns = _KIND | {"one", "ones"}
        mentioned = [w for w in ws if w in nouns or w in _colours(world) or w in _SIZE_WORDS or w in _BIGGER | _SMALLER
                     or any(w in _name_parts(e) or w == e.name for e in others)]
        names_region = any(w in _name_parts(r) or w in _REGION_KIND for r in world.regions for w in ws)
        if mentioned and (set(ws) & nouns or not names_region):
            if len(objs) == 1 and not misses:
                return "object", (objs[0].name,), False, []
            if misses or not objs:
                have = "; ".join(misses) or "it has " + ", ".join(e.name for e in others)
                return "object", (), False, [("unknown_destination", f"stack on {quote(_said(words))}: no such "
                                                                     f"object in the scene ({have})")]
            return "object", (), False, [("not_understood", f"stack on {quote(_said(words))}: could be any of "
                                         f"{', '.join(e.name for e in objs)}: say which")]
    regions = list(world.regions)
    top_of = any(a == "top" and b == "of" for a, b in zip(words, words[1:]))
    if prep in _STACK_PREPOSITIONS or top_of:  # "on top of the drawer": the cabinet it is part of
        ws = [_PART_OF.get(w, w) if any(_PART_OF.get(w) in r.name.split("_") for r in regions) else w for w in ws]
    # where words (left, middle, corner ...) are known only as parts of a region's name: "the middle bin"
    # among a left and a right bin names nothing there
    known = set(_STOP) | _REGION_KIND | _REGION_SYNONYMS | {"inside", "over", "there", "here"}
    known |= {p for r in regions for p in r.name.split("_")} | _colours(world)
    unknown = [w for w in ws if w not in known and w not in _PREPOSITIONS]
    if unknown:
        have = ", ".join(r.name for r in regions) or "no region"
        named = ", ".join(repr(w) for w in unknown)
        return "region", (), False, [("unknown_destination", f"the destination {quote(_said(words))} is not in the "
                                                             f"scene ({named} names nothing there); it has {have}")]
    scored = []
    for r in regions:
        parts = set(r.name.split("_"))
        score = len((parts - _REGION_KIND) & set(ws)) + (1 if r.colour and r.colour in ws else 0)
        generic = parts & _REGION_KIND & set(ws) or ({"region", "regions", "area", "areas", "zone", "container",
                                                      "containers", "box", "boxes", "receptacle"} & set(ws))
        scored.append((score, bool(generic), r))
    colours = [w for w in ws if w in _colours(world)]
    if colours:
        scored = [(s, g, r) for s, g, r in scored if r.colour in colours or set(colours) & set(r.name.split("_"))]
        if not scored:
            return "region", (), False, [("unknown_destination", f"the destination {quote(_said(words))} is not in "
                                         f"the scene (no {'/'.join(colours)} region); it has "
                                         f"{', '.join(r.name for r in regions)}")]
    top = max((s for s, _, _ in scored), default=0)
    if not top and set(ws) & {"it", "them"}:
        return "region", (), False, [("not_understood", f"{quote(_said(words))}: 'it' refers to nothing earlier "
                                                        f"in the request")]
    if not top and not set(ws) & (_REGION_KIND | _REGION_SYNONYMS):
        # "in the gripper", "in there": words that name no region are not any region
        return "region", (), False, [("unknown_destination", f"the destination {quote(_said(words))} names no "
                                                             f"region of the scene; it has "
                                                             f"{', '.join(r.name for r in regions) or 'none'}")]
    if top:
        picked = [r.name for s, _, r in scored if s == top]
    else:
        picked = [r.name for s, g, r in scored if g] or [r.name for _, _, r in scored]
        # "the bin" among two bins names one of them without saying which: ask, do not guess
        # ("a bin", "either bin", "any of the trays" leave the choice to the plan)
        kind_words = set(ws) & (_REGION_KIND | _REGION_SYNONYMS)
        singular = bool(kind_words) and all(not w.endswith("s") for w in kind_words)
        definite = "the" in words and not set(words) & {"a", "an", "any", "either", "whichever", "one", "some"}
        if len(picked) > 1 and singular and definite:
            return "region", (), False, [("not_understood", f"{quote(_said(words))} could be any of "
                                                            f"{', '.join(picked)}: say which")]
    if not picked:
        return "region", (), False, [("unknown_destination", f"the destination {quote(_said(words))}: the scene has "
                                                             f"no region")]
    return "region", tuple(picked), False, []


# -- referring expressions: "the black bowl next to the plate" ----------------------------------------------

#: The spatial relations a referring expression may use (``read_request(..., relations=True)``):
#: ``between`` two landmarks, ``next_to`` one, ``on`` one, ``in`` one (optionally a ``part`` of it such as its
#: top drawer), ``table_center`` (no landmark: the middle of the table the objects stand on), ``left`` /
#: ``right`` (no landmark: the one furthest to the viewer's left / right), ``front`` / ``back`` (no
#: landmark: the one nearest the viewer / furthest from it), ``middle`` (no landmark: of three or more,
#: the one between the others).
RELATIONS = ("between", "next_to", "on", "in", "table_center", "left", "right", "front", "back", "middle")
#: words that name the viewer's side of one of several identical objects ("the left plate", "the
#: black bowl on the left", "the black bowl at the back", "the middle black bowl"), and the relation they
#: stand for: as the scene camera shows the table (the front is nearest it)
_SIDES = {"left": "left", "leftmost": "left", "right": "right", "rightmost": "right",
          "front": "front", "frontmost": "front", "back": "back", "rear": "back", "backmost": "back",
          "middle": "middle"}
#: side words read only where they stand as a side of the object phrase: after its article ("the back black
#: bowl") or in a closing "at / in / on the <side>" ("the black bowl at the back"), never elsewhere ("put the
#: bowl back"); ``middle`` only among three or more identical objects (of two, "in the middle" is the table's)
_DEPTH_SIDES = {"front", "frontmost", "back", "rear", "backmost", "middle"}
#: words that begin a relation after an object phrase, and the relation they begin
_RELATION_START = {"between": "between", "next": "next_to", "beside": "next_to", "near": "next_to",
                   "nearest": "next_to", "closest": "next_to", "by": "next_to", "on": "on", "atop": "on",
                   "upon": "on", "in": "in", "inside": "in", "within": "in", "at": "at", "from": "from"}
#: words of a landmark phrase that name no part of it ("the cookie box": a box of cookies)
_LANDMARK_GENERIC = _KIND | _REGION_KIND | {"box", "boxes", "package", "pack", "carton", "thing"}
_CENTRE = {"center", "centre", "middle"}
_EGOCENTRIC = {"left", "right", "front", "back", "rear", "far", "near", "nearer", "farther", "further", "leftmost",
               "rightmost", "corner", "edge", "end"}
_TABLE = {"table", "tabletop", "counter", "surface"}
#: a destination preposition after a referring expression of a move ("put the bowl next to the plate on the box")
_DEST_PREPOSITIONS = ("into", "onto", "in", "on", "to", "inside")


def _stem(name: str) -> str:
    """A declared name without its instance number: ``akita_black_bowl_2`` -> ``akita_black_bowl``."""
    return re.sub(r"_\d+$", "", name)


def _twins(words: list[str], world: World) -> tuple[str, ...]:
    """The declared objects an object phrase names when it names several *identical* ones (the same
    declared name but for its instance number) and nothing tells them apart; else ``()``."""
    if not words or set(words) & (_ALL | _PRONOUNS | {"two", "three", "four", "five", "ones"}) or any(
            w in _KIND and w.endswith("s") for w in words):
        return ()
    content = [w for w in words if w not in _STOP]
    if not content:
        return ()
    found, misses = _filter(content, list(world.objects), world)
    if misses or len(found) < 2 or len({_stem(e.name) for e in found}) != 1:
        return ()
    return tuple(e.name for e in found)


def _closing_side(words: list[str], k: int) -> bool:
    """Whether the side word ``words[k]`` ends the phrase as ``at / in / on the <side> (side | hand)``."""
    return k >= 2 and words[k - 2] in ("on", "at", "in") and words[k - 1] == "the" and (
        k == len(words) - 1 or words[k + 1:] in (["side"], ["hand"]))


def _side_twins(words: list[str], world: World) -> tuple[str | None, tuple[str, ...]]:
    """``(side, the identical objects)`` when ``words`` name several identical objects with one side word
    among them (``the left plate``, ``the rightmost bowl``, ``the black bowl on the left``, ``the black bowl
    at the back``, ``the middle black bowl`` of three; :data:`_SIDES`, :data:`_DEPTH_SIDES`); else
    ``(None, ())``."""
    sides = [w for w in words if w in _SIDES]
    if len(sides) != 1:
        return None, ()
    k = words.index(sides[0])
    closing = _closing_side(words, k)
    if sides[0] in _DEPTH_SIDES and not (closing or k == 0 or (k == 1 and words[0] in ("the", "a", "an"))):
        return None, ()
    rest = words[:k - 2] if closing else [*words[:k], *words[k + 1:]]
    twins = _twins(rest, world)
    if sides[0] == "middle" and len(twins) < 3:
        return None, ()
    return (_SIDES[sides[0]], twins) if twins else (None, ())


def _matches_part(word: str, parts: set[str]) -> bool:
    return word in parts or f"{word}s" in parts or f"{word}es" in parts or (word.endswith("s") and word[:-1] in parts)


def _landmark(words: list[str], world: World, exclude: Sequence[str]) -> tuple[str | None, list[tuple[str, str]]]:
    """The one declared thing (object or fixture: the world's regions) a landmark phrase names, by the words
    of its declared name (``cookie box`` -> ``cookies_1``: a plural name matches its singular, and words
    such as box or tray may name no part of it); ``(None, problems)`` when it names none or several."""
    content = [w for w in words if w not in _STOP and w not in ("of",)]
    phrase = quote(_said(words))
    if not content:
        return None, [("not_understood", f"{phrase}: the relation names no landmark")]
    if set(content) <= _EGOCENTRIC:
        return None, [("not_understood", f"{phrase}: a place relative to the viewer ({', '.join(content)}) is not "
                                         f"a relation the rules read (between, next to, on, in a declared thing; "
                                         f"the table's centre)")]
    cands = [e for e in world.regions if e.name not in exclude]
    scored = []
    for e in cands:
        # its name's words and their other words (a cup: a mug), and a colour its name implies (a porcelain mug
        # is white: "to the front of the white mug")
        parts = {p for p in e.name.split("_") if not p.isdigit()} | _name_parts(e) | ({e.colour} if e.colour else set())
        specific = [w for w in content if w not in _LANDMARK_GENERIC]
        if not all(_matches_part(w, parts) for w in specific):
            continue
        hits = sum(_matches_part(w, parts) for w in content)
        if hits:
            scored.append((hits, e.name))
    if not scored:
        have = ", ".join(e.name for e in cands) or "nothing"
        return None, [("unknown_destination", f"{phrase} names nothing declared in the scene (it has {have})")]
    top = max(h for h, _ in scored)
    best = [n for h, n in scored if h == top]
    if len(best) > 1:
        return None, [("not_understood", f"{phrase} could be any of {', '.join(best)}: say which")]
    return best[0], []


def _read_relation(words: list[str], world: World, twins: tuple[str, ...]) -> tuple[dict | None,
                                                                                   list[tuple[str, str]]]:
    """``(where, problems)`` of a relation phrase (``next to the plate``, ``between the plate and the
    ramekin``, ``on the cookie box``, ``in the top drawer of the wooden cabinet``, ``from table center``)."""
    phrase = quote(_said(words))
    kind = _RELATION_START[words[0]]
    rest = words[1:]
    if words[0] == "next" or words[0] in ("closest", "nearest"):
        if not rest or rest[0] != "to":
            return None, [("not_understood", f"{phrase}: '{words[0]}' without 'to'")]
        rest = rest[1:]
    if words[0] == "on" and rest[:2] == ["top", "of"]:
        rest = rest[2:]
    if kind in ("at", "from", "in", "on") and set(rest) & _CENTRE and (set(rest) & _TABLE or not [
            w for w in rest if w not in _STOP and w not in _CENTRE and w != "of"]):
        # "from table center", "at the centre of the table", "in the middle of the table"
        extra = [w for w in rest if w not in _STOP and w not in _CENTRE | _TABLE and w != "of"]
        if extra:
            return None, [("not_understood", f"{phrase}: {', '.join(repr(w) for w in extra)} after the table's "
                                              f"centre is not understood")]
        return {"relation": "table_center"}, []
    if kind == "at":
        return None, [("not_understood", f"{phrase}: '{words[0]}' a place other than the table's centre is not a "
                                          f"relation the rules read (between, next to, on, in a declared thing; "
                                          f"the table's centre)")]
    level = next((i for i, w in enumerate(rest) if w in _LEVEL_WORDS and 0 < i and rest[i - 1] in _DRAWER_WORDS
                  and rest[i + 1:i + 2] == ["of"] and set(rest[i + 2:]) & set(_PART_OF.values())), None)
    if kind in ("in", "from") and level is not None:
        # "in the top layer of the wooden cabinet": a level of a chest of drawers is its drawer
        rest = [*rest[:level], "drawer", *rest[level + 1:]]
        words = [words[0], *rest]
    drawer = next((i for i, w in enumerate(rest) if w in _PART_OF), None)
    if kind in ("in", "from") and drawer is not None and "of" not in rest[:drawer]:
        # "in / from the top drawer of the wooden cabinet", "from the top drawer" (of the one
        # thing drawers belong to): a part of the landmark; "from" a drawer is in it
        part_kind, part, owner, why = _split_part(" ".join(words), rest)
        if why:
            return None, why
        name, why = _landmark(owner, world, twins)
        if why and owner == [_PART_OF[rest[drawer]]]:
            return None, [(why[0][0], f"{phrase}: the {rest[drawer]} of no declared thing ({why[0][1]})")]
        if why:
            return None, why
        return {"relation": "in", "of": [name], "part": f"{part} {part_kind}" if part else part_kind}, []
    if kind == "from":  # "lift the bowl from the stove": the one resting on it
        kind = "on"
    if kind == "between":
        groups: list[list[str]] = [[]]
        for w in rest:
            if w == "and":
                groups.append([])
            else:
                groups[-1].append(w)
        if len(groups) != 2 or not all(groups):
            return None, [("not_understood", f"{phrase}: 'between' needs two landmarks (between the X and the Y)")]
        names = []
        for g in groups:
            name, why = _landmark(g, world, twins)
            if why:
                return None, why
            names.append(name)
        if names[0] == names[1]:
            return None, [("not_understood", f"{phrase}: between {names[0]} and itself")]
        return {"relation": "between", "of": names}, []
    part: str | None = None
    if kind == "in" and "of" in rest and [w for w in rest[:rest.index("of")] if w not in _STOP]:
        # "in the top drawer of the wooden cabinet": a part of the landmark
        part = " ".join(w for w in rest[:rest.index("of")] if w not in ("the", "a", "an"))
        rest = rest[rest.index("of") + 1:]
    name, why = _landmark(rest, world, twins)
    if why:
        return None, why
    where: dict = {"relation": kind, "of": [name]}
    if part:
        where["part"] = part
    return where, []


def _beside(words: list[str], prep: str | None, world: World, movers: tuple[str, ...],
            last: str | None = None):
    """``(side, landmark)`` of a destination ``to the left / right / front / back of <landmark>`` (``on the
    right side of``, ``at the left of``, ``in front of``, the possessive ``to the stove's front`` too; side
    one of :data:`_LANDMARK_SIDES`), a problem list when the landmark names nothing declared (or several),
    else None (not such a destination). A side with no landmark (``and the chocolate pudding to the right``)
    is beside ``last``, the thing the clause before set its object on or beside, when there is one (it names
    no other landmark); with none it is no such destination (a place relative to the viewer)."""
    ws = [w for w in words if w != "the"]
    if ws[:1] == ["rear"]:
        ws = ["back", *ws[1:]]
    if ws[-1:] in (["side"], ["hand"]):
        ws = ws[:-1]  # "to the stove's left side", "on the right hand"
    if ws and ws[-1] == "rear":
        ws = [*ws[:-1], "back"]
    if len(ws) >= 3 and ws[-2] == "s" and ws[-1] in _LANDMARK_SIDES:
        ws = [ws[-1], "of", *ws[:-2]]  # "to the stove's front": the front of the stove
    if prep in ("to", "on", "at") and len(ws) == 1 and ws[0] in _LANDMARK_SIDES and last not in (None, *movers):
        return ws[0], last
    if (prep not in ("to", "on", "at") and not (prep == "in" and ws[:1] == ["front"])) or len(ws) < 3 \
            or ws[0] not in _LANDMARK_SIDES:
        return None
    rest = ws[1:]
    if rest[0] in ("side", "hand"):
        rest = rest[1:]
    if not rest or rest[0] != "of" or len(rest) < 2:
        return None
    name, why = _landmark(rest[1:], world, movers)
    return why if why else (ws[0], name)


def _free_twin(twins: tuple[str, ...], bound: Mapping[str, dict], phrase: list[str]):
    """The first of ``twins`` not yet bound to a reference, or the problem list saying none is left."""
    free = [n for n in twins if n not in bound]
    if not free:
        return [("not_understood", f"{quote(_said(phrase))}: every one of {', '.join(twins)} is already picked "
                                   f"out by another part of the request")]
    return free[0]


def _side_reference(body: list[str], world: World, verb: str | None, bound: Mapping[str, dict]):
    """``(object, {"relation": side}, destination words, preposition)`` when the object words of ``body`` (up
    to a move's first destination preposition after a closing ``on the left`` / ``at the back``) name one side
    of several identical objects (``the left bowl``, ``the black bowl on the left``, ``the black bowl at the
    front``, ``the middle black bowl``: :func:`_side_twins`); a problem list when every one of them is bound
    already; else None."""
    end = len(body)
    if verb in _MOVE | _PUSH | _STACK:
        start = 0
        for i, w in enumerate(body):  # skip "on the left (side)", "at the back" of the object phrase itself
            if w in ("on", "at", "in") and body[i + 1:i + 2] == ["the"] and body[i + 2:i + 3] \
                    and body[i + 2] in _SIDES:
                after = i + 3 + (1 if body[i + 3:i + 4] in (["side"], ["hand"]) else 0)
                if after == len(body) or body[after] in _DEST_PREPOSITIONS:
                    start = after
                    break
        end = next((i for i in range(max(start, 1), len(body)) if body[i] in _DEST_PREPOSITIONS), len(body))
    side, twins = _side_twins(body[:end], world)
    if side is None:
        return None
    name = _free_twin(twins, bound, body[:end])
    if isinstance(name, list):
        return name
    dest, prep = (body[end + 1:], body[end]) if end < len(body) else ([], None)
    return name, {"relation": side}, dest, prep


def _reference(body: list[str], world: World, verb: str | None, bound: Mapping[str, dict]):
    """A referring expression at the start of a clause's object words: ``the <words naming several
    identical objects> <relation> <landmark(s)>`` (then, for a move, ``<preposition> <destination>``).

    Returns ``None`` when ``body`` is no such expression (the ordinary reading applies), a list of
    problems when it is one the rules cannot resolve, else ``(object, where, destination words,
    preposition)``: the object is the first of the identical declared names not yet bound to another
    reference (which of two identical names stands for the thing the relation picks out is the reader's
    label; perception decides which physical object that is)."""
    side = _side_reference(body, world, verb, bound)
    if side is not None:
        return side
    k = next((i for i, w in enumerate(body) if w in _RELATION_START and i > 0), None)
    if k is None:
        return None
    twins = _twins(body[:k], world)
    if not twins:
        return None
    rel = body[k:]
    dest: list[str] = []
    prep: str | None = None
    if verb in _MOVE | _PUSH | _STACK:
        # the destination follows the landmark's phrase: its last destination preposition
        skip = 3 if rel[:2] == ["next", "to"] or rel[:3] == ["on", "top", "of"] else 1
        cut = max((i for i, w in enumerate(rel) if i >= skip + 1 and w in _DEST_PREPOSITIONS), default=None)
        if cut is None:  # "put the black bowl on the plate": the preposition is the destination's
            return None
        rel, dest, prep = rel[:cut], rel[cut + 1:], rel[cut]
    where, why = _read_relation(rel, world, twins)
    if why or where is None:
        return why or [("not_understood", f"{quote(_said(rel))}: not a relation the rules read")]
    free = [n for n in twins if n not in bound]
    if not free:
        return [("not_understood", f"{quote(_said(body))}: every one of {', '.join(twins)} is already picked "
                                   f"out by another part of the request")]
    return free[0], where, dest, prep


def read_request(request: str, world: World, *, relations: bool = False) -> Meaning:
    """Read ``request`` over ``world`` (see the module docstring).

    Args:
        request: the request (English).
        world: what it may name.
        relations: also read referring expressions that tell identical objects apart by a spatial
            relation (``the black bowl between the plate and the ramekin``: :data:`RELATIONS`), when
            the words before the relation name several objects with the same declared name but for
            its instance number. The object is bound to one of those names and the relation kept in
            :attr:`Meaning.where` (``{name: {"relation", "of", "part"?}}``) for perception to resolve
            on what it sees; a relation or landmark the rules cannot read is a problem. Off by
            default: a caller that cannot hand the relation on to perception must not ask for it.
    """
    meaning = Meaning(request=request)
    meaning.language = detect_language(request, world.names)
    if meaning.language is not None:
        return meaning
    token = _ASSUMED.set(meaning.assumed)
    try:
        return _read(meaning, request, world, relations)
    finally:
        _ASSUMED.reset(token)


def _read(meaning: Meaning, request: str, world: World, relations: bool) -> Meaning:
    """:func:`read_request`'s reading of ``request`` into ``meaning`` (its language already checked)."""
    text = meaning.text = normalise(request)
    if text == DANGLING:
        meaning.text = request
        meaning.problems.append(("not_understood", f"{quote(request)}: a sequence word ('then', 'after that', "
                                                   f"'once you've ...') with no action after or before it"))
        return meaning
    previous: tuple[str, ...] = ()
    last_open: Intent | None = None  # the clause before opened this (a drawer: "... and put the bowl inside")
    # the drawer the clause before named, ``(thing, level)``: what "close it" after "put the bowl in the bottom
    # drawer" closes (a bowl is not closed)
    last_drawer: tuple[str, str] | None = None
    acted = False  # an earlier clause had a verb of its own (a later one may elide it)
    for part in _parts(text, world):
        just_opened, last_open = last_open, None
        named_drawer, last_drawer = last_drawer, None
        possible = part.endswith(" " + WHERE_POSSIBLE)
        if possible:
            part = part[: -len(WHERE_POSSIBLE) - 1]
        low = part.lower()
        words = _tokens(low)
        opened = _OPEN.match(" ".join(words))
        if opened:  # a drawer (or another part) to open or close: of any declared thing, a fixture too
            intent, problems = _read_open(part, opened.group(1), _tokens(opened.group(2)), world, previous,
                                          named_drawer)
            if problems:
                meaning.problems += problems
                continue
            assert intent is not None
            meaning.intents.append(intent)
            previous, acted = intent.objects, True
            last_open = intent if intent.verb == "open" else None
            if intent.part_kind == "drawer" and intent.part is not None:
                last_drawer = (intent.objects[0], intent.part)
            continue
        turn = _TURN.match(" ".join(words))
        if turn:  # a knob to turn: the thing named is any declared thing, a fixture too
            state = turn.group(1) or turn.group(4)
            named = _tokens(turn.group(2) or turn.group(3))
            things = _things(world)
            objects, count, problems = _read_objects(named, things, previous)
            if not problems and len(objects) != 1:
                problems = [("not_understood", f"{quote(part)}: turn one thing {state} at a time")]
            if problems:
                meaning.problems += problems
                continue
            meaning.intents.append(Intent(part, f"turn_{state}", objects))
            previous, acted = objects, True
            continue
        # "keep holding it": a hold, not a keep
        verbs = [("hold" if w == "keep" and words[i + 1:i + 2] == ["holding"] else w)
                 for i, w in enumerate(words) if w in _VERBS]
        verb_word = verbs[0] if verbs else None
        negated = bool(_NEGATION.search(low))
        if _NOTHING.search(low) and not [w for w in verbs if w not in ("leave", "keep")]:
            meaning.intents.append(Intent(part, "leave", tuple(e.name for e in world.objects)))
            continue
        start = (words.index("keep") + 2 if verbs and verb_word == "hold" and "hold" not in words
                 else words.index(verb_word) + 1 if verb_word else 0)
        if verb_word in ("pick", "take", "lift") and start < len(words) and words[start] == "up":
            start += 1
        body = words[start:]
        stay = _STAY.search(low)
        # "the black bowl next to the plate" (one of two identical bowls): read only when asked for
        ref = (_reference(body, world, verb_word, meaning.where)
               if relations and verb_word in _MOVE | _HOLD | _PUSH | _STACK and not negated and not stay
               else None)
        if isinstance(ref, list):
            meaning.problems += ref
            continue
        # the excepted phrase: from except/but to the next preposition (or the end)
        excluded_words: list[str] = []
        for key in ("except", "but"):
            if key in body and ref is None:
                i = body.index(key)
                j = next((k for k in range(i + 1, len(body)) if body[k] in _PREPOSITIONS), len(body))
                excluded_words = body[i + 1:j]
                body = body[:i] + body[j:]
                break
        # a preposition first ("... and put into the basket"): the object is the previous clause's
        cut = next((i for i, w in enumerate(body) if w in _PREPOSITIONS and (i > 0 or previous)), None)
        if ref is not None:
            ref_object, ref_where, dest_words, prep = ref
            objects, count, problems = (ref_object,), None, []
        else:
            if stay:
                obj_words = [w for w in _tokens(low[:stay.start()])[start:] if w not in ("except", "but")]
                obj_words = [w for w in obj_words if w not in excluded_words]
                dest_words, prep = [], None
            elif cut is None:
                obj_words, dest_words, prep = body, [], None
            else:
                obj_words, dest_words, prep = body[:cut], body[cut + 1:], body[cut]
            obj_words = [w for w in obj_words if w not in ("by", "colour", "color", "size")]
            objects, count, problems = _read_objects(obj_words, world, previous)
        excluded: tuple[str, ...] = ()
        if excluded_words and not problems:
            ex, _, why = _read_objects(excluded_words, world, ())
            problems += [(code, f"except {quote(_said(excluded_words))}: {msg}") for code, msg in why]
            excluded = ex
            objects = tuple(o for o in objects if o not in excluded)
            if not objects and not problems:
                problems.append(("not_understood", f"{quote(part)} excepts every object it names"))
        if problems:
            meaning.problems += problems
            continue
        if stay or negated or verb_word in _LEAVE or (verb_word == "keep" and not dest_words):
            if verb_word == "keep" and not stay and not negated:
                meaning.problems.append(("not_understood", f"{quote(part)}: 'keep' without 'where it is' or a "
                                                           f"destination"))
                continue
            meaning.intents.append(Intent(part, "leave", objects))
            previous = objects
            continue
        kind, dests, by_colour, why = ("region", (), False, [])
        into: str | None = None  # which drawer (or compartment), when the destination is a part's inside
        into_kind = "drawer"
        side, twins = _side_twins(dest_words, world) if relations and dest_words else (None, ())
        dest_where: dict[str, dict] = {}
        last = (meaning.intents[-1].destinations[0] if meaning.intents and meaning.intents[-1].verb in ("move", "stack")
                and len(meaning.intents[-1].destinations) == 1 else None)
        beside = _beside(dest_words, prep, world, objects, last) if relations and dest_words else None
        if beside is not None:  # "to the right of the plate": on the table, on the viewer's right of the plate
            if isinstance(beside, list):
                why = beside
            else:
                dests = (beside[1],)
        elif side is not None:  # "on the left plate": one of two identical plates, the one perception sees left
            bound = {**meaning.where, **({ref[0]: ref[1]} if ref is not None else {})}
            name = _free_twin(tuple(t for t in twins if t not in objects), bound, dest_words)
            if isinstance(name, list):
                why = name
            else:
                dests, dest_where = (name,), {name: {"relation": side}}
                kind = "object" if verb_word in _STACK else kind  # "stack the front bowl on the middle bowl"
        elif (drawer := _into_drawer(part, dest_words, prep, world, previous, just_opened)) is not None:
            # the inside of a drawer ("in the top drawer of the cabinet"; "inside" / "in it" after opening one)
            if isinstance(drawer, list):
                why = drawer
            else:
                dests, into = (drawer[0],), drawer[1]
        elif (room := _into_compartment(part, dest_words, prep, world, previous)) is not None:
            # a compartment of a thing, by the viewer's side ("in the back compartment of the caddy")
            if isinstance(room, list):
                why = room
            else:
                dests, into, into_kind = (room[0],), room[1], "compartment"
        elif dest_words:
            kind, dests, by_colour, why = _read_destination(dest_words, prep, world, previous, objects)
        problems += why
        if into is not None:
            dest_words = dest_words or [prep or "inside"]  # a destination, though no words name it again
        if verb_word is None and (not dest_words or not acted or set(words) & {"is", "are", "was", "were"}):
            # no verb: an elided one ("..., and the blue cube in the right bin") only after a clause that had
            # one; "is the red cube in the left bin?" is a question, not a move
            problems.append(("not_understood", f"{quote(part)}: no action the skills can do (put/place/move ... "
                                               f"in a region, stack ... on an object, pick up/hold, leave ... where "
                                               f"it is)"))
        elif verb_word in _STACK and kind != "object" and not problems:
            problems.append(("not_understood", f"{quote(part)} asks to stack, but names no object to stack on"))
        elif verb_word in _MOVE and not dest_words:
            problems.append(("not_understood", f"{quote(part)} says where to put nothing: no destination"))
        elif verb_word in _PUSH and not isinstance(beside, tuple) and not problems:
            problems.append(("not_understood", f"{quote(part)}: a push goes to a side of one thing (to the left, "
                                               f"right, front or back of it: 'push the plate to the front of the "
                                               f"stove')"))
        verb = ("push" if verb_word in _PUSH else "hold" if not dest_words
                else "stack" if kind == "object" else "move")
        if not problems and verb == "stack" and count is None and len(objects) > 1:
            problems.append(("not_understood", f"{quote(part)} stacks several objects on one: say the order"))
        if not problems and by_colour:
            lacking = [o for o in objects
                       if not meaning.destinations_for(Intent(part, verb, (o,), by_colour=True), o, world)]
            if lacking and possible and len(lacking) < len(objects):
                # "..., if there is one": an object whose colour has no region stays where it is
                excluded += tuple(lacking)
                objects = tuple(o for o in objects if o not in lacking)
                lacking = []
            if lacking:
                problems.append(("unknown_destination", f"{quote(part)}: no region of the colour of "
                                                        f"{', '.join(lacking)}"))
        if problems:
            meaning.problems += problems
            continue
        meaning.intents.append(Intent(part, verb, objects, dests, count, by_colour, excluded,
                                      part=into, part_kind=into_kind if into is not None else None,
                                      beside=beside[0] if isinstance(beside, tuple) else None))
        if into is not None and into_kind == "drawer":
            last_drawer = (dests[0], into)
        if ref is not None:
            meaning.where[ref[0]] = ref[1]
        meaning.where.update(dest_where)
        previous = objects if count is None else objects[:count]
        acted = acted or verb_word is not None
    _settle(meaning)
    return meaning


def _part_phrase(it: Intent, obj: str) -> str:
    """"the middle drawer of wooden_cabinet_1" (or just the object) for a message."""
    if it.part_kind is None:
        return obj
    return f"the {it.part + ' ' if it.part else ''}{it.part_kind} of {obj}"


def _read_open(text: str, verb: str, named: list[str], world: World,
               previous: tuple[str, ...], drawer: tuple[str, str] | None = None
               ) -> tuple[Intent | None, list[tuple[str, str]]]:
    """The ``open`` / ``close`` intent of clause ``text`` whose object phrase is ``named``:
    ``the middle drawer of the cabinet`` names the drawer ``middle`` (:data:`_DRAWER_WORDS`) of
    the one thing ``cabinet`` names (any declared thing, a fixture too); without ``of ...`` the
    drawer is of the one thing its kind belongs to (:data:`_PART_OF`: a cabinet); "the cabinet's
    middle drawer" names its owner before the possessive, and "the middle layer of the drawer"
    (:data:`_LEVEL_WORDS`) takes "drawer" for the chest of drawers; a phrase with no drawer names
    the thing itself. ``drawer``: ``(thing, level)`` of the drawer the clause before named ("put
    the bowl in the bottom drawer of the cabinet"): "it", "that" or "the drawer" then mean that
    drawer ("... and close it": a drawer is what is closed, not the bowl). Returns ``(intent,
    problems)``."""
    state = "close" if verb in ("close", "shut") else "open"
    named, problems = _door_of(text, named, world)
    if problems:
        return None, problems
    if drawer is not None and named and set(named) <= {"it", "that", "the", "drawer", "up"} and (
            set(named) & {"it", "that", "drawer"}):
        return Intent(text, state, (drawer[0],), part=drawer[1], part_kind="drawer"), []
    objects, part, kind, problems = _read_part(text, named, world, previous)
    if not problems and len(objects) != 1:
        problems = [("not_understood", f"{quote(text)}: {state} one thing at a time")]
    if problems:
        return None, problems
    return Intent(text, state, objects, part=part, part_kind=kind), []


def _door_of(text: str, named: list[str], world: World) -> tuple[list[str], list[tuple[str, str]]]:
    """``(words, problems)``: the words naming what is opened or closed when ``named`` (of
    clause ``text``) names a door: a door is its owner's, so "close the door", "close door",
    "shut the microwave's door", "the microwave door" and "close the door of the microwave" close
    the microwave. Whose door: the words after "of", or before a possessive, or a kind with a door
    named before it, else the one declared thing of a kind with a door (:data:`_HAS_DOOR`); none
    or several of those, or other words about the door ("the red door"), is a problem (never
    guessed). Words with no door are returned as they are."""
    if "door" not in named:
        return named, []
    k = named.index("door")
    before, after = named[:k], named[k + 1:]
    if "of" in after:
        return after[after.index("of") + 1:], []
    if "s" in before:
        return before[:before.index("s")], []
    if _HAS_DOOR.intersection(before) and not [w for w in after if w not in _STOP]:
        return before, []  # "the microwave door"
    if [w for w in before + after if w not in _STOP]:
        return named, [("not_understood", f"{quote(text)}: which door is {' '.join(named)!r}? (say the door of "
                                          f"which thing)")]
    owners = sorted(e.name for e in _things(world).objects if _HAS_DOOR.intersection(e.name.split("_")))
    if len(owners) != 1:
        return named, [("unknown_object" if not owners else "not_understood",
                        f"{quote(text)}: 'door' names " + (f"one of {', '.join(owners)}: say which" if owners else
                                                           "no thing of the scene with a door (kinds with one: "
                                                           + ", ".join(sorted(_HAS_DOOR)) + ")"))]
    return [owners[0]], []


def _read_part(text: str, named: list[str], world: World, previous: tuple[str, ...]
               ) -> tuple[tuple[str, ...], str | None, str | None, list[tuple[str, str]]]:
    """``(objects, part, part_kind, problems)`` of the phrase ``named`` (the words of clause
    ``text`` naming a thing or a part of one): ``the middle drawer of the cabinet`` is the
    drawer ``middle`` (:data:`_DRAWER_WORDS`) of the one thing ``cabinet`` names (any declared
    thing, a fixture too); a phrase with no drawer names the thing itself (part and kind None).
    How the words split: :func:`_split_part`."""
    things = _things(world)
    kind, part, owner, problems = _split_part(text, named)
    if kind is None:
        objects, _, problems = _read_objects(named, things, previous)
        return objects, None, None, problems
    if problems:
        return (), None, kind, problems
    objects, _, problems = _read_objects(owner, things, previous)
    return objects, part, ("drawer" if kind in ("drawer", "drawers") else kind), problems


def _split_part(text: str, named: list[str]) -> tuple[str | None, str | None, list[str], list[tuple[str, str]]]:
    """``(kind, part, owner words, problems)`` of the words ``named`` (of clause ``text``) that
    may name a part of a thing: ``kind`` the part word (:data:`_PART_OF`: drawer) or None when
    there is none; ``part`` its level (:data:`_DRAWER_WORDS`: top, middle, bottom) or None; the
    owner the words after "of", or those before a possessive ("the cabinet's middle drawer"),
    else the one thing its kind belongs to (a cabinet); "the middle layer of the drawer"
    (:data:`_LEVEL_WORDS`) takes "drawer" for the chest of drawers. Problems: a level that is
    none of those, or words after the part that are no "of ..."."""
    kind = next((w for w in named if w in _PART_OF), None)
    if kind is None:
        return None, None, [], []
    k = named.index(kind)
    before = [w for w in named[:k] if w not in ("the", "a", "an", "its", "their", "please")]
    owner: list[str] = []
    if "s" in before:  # "the cabinet's middle drawer": the owner before the possessive
        i = before.index("s")
        owner, before = before[:i], before[i + 1:]
    if len(before) == 3 and before[1] in _LEVEL_WORDS and before[2] == "of":
        before = before[:1]  # "the middle layer of the drawer": the drawer stands for the chest of them
    if len(before) > 1 or (before and before[0] not in _DRAWER_WORDS):
        return kind, None, [], [("not_understood", f"{quote(text)}: which {kind} is {' '.join(before)!r}? (say "
                                                   f"top, middle or bottom {kind})")]
    part = _DRAWER_WORDS[before[0]] if before else None
    after = named[k + 1:]
    if "of" not in after and [w for w in after if w not in _STOP]:
        return kind, part, [], [("not_understood", f"{quote(text)}: the {kind} of what? ({' '.join(after)!r} "
                                                   f"after it)")]
    return kind, part, after[after.index("of") + 1:] if "of" in after else owner or [_PART_OF[kind]], []


def _into_drawer(text: str, dest_words: list[str], prep: str | None, world: World, previous: tuple[str, ...],
                 opened: Intent | None) -> tuple[str, str] | list[tuple[str, str]] | None:
    """``(fixture, drawer)`` when a move's destination is the inside of a drawer: "in / into
    the top drawer of the cabinet", or, right after a clause that opened a drawer, "inside",
    "in it", "into it", "in there", "inside the drawer" (that drawer: ``opened``). A list of
    problems when it names a drawer but not which one; ``None`` when the destination is no
    drawer's inside ("on top of the drawer" is the cabinet's top: :data:`_PART_OF`)."""
    if prep not in ("in", "into", "inside"):
        return None
    ws = [w for w in dest_words if w not in ("the", "a", "an")]
    back = opened is not None and opened.part_kind == "drawer" and opened.part is not None
    if back and set(ws) <= {"it", "there", "drawer", "inside", "of"} and not (ws and ws[0] == "of"):
        assert opened is not None and opened.part is not None
        return opened.objects[0], opened.part
    top_of = "top" in ws and ws[ws.index("top") + 1:ws.index("top") + 2] == ["of"]  # "the top of the drawer"
    if not set(ws) & {"drawer", "drawers"} or top_of:
        return None
    objects, part, kind, problems = _read_part(text, dest_words, world, previous)
    if any(code == "unknown_object" for code, _ in problems):
        return None  # no thing with drawers here: the destination names nothing (_read_destination says so)
    if problems:
        return problems
    if len(objects) != 1 or part is None:
        return [("not_understood", f"{quote(text)}: which drawer? (the top, middle or bottom drawer of one thing)")]
    return objects[0], part


#: "the back compartment of the caddy": words for a compartment, and for which one (the viewer's
#: side of the thing it is in: :data:`~phyagentos.geometry.VIEWER_SIDES`).
_COMPARTMENT_WORDS = {"compartment", "compartments", "section", "slot"}
_COMPARTMENT_SIDES = {"back": "back", "rear": "back", "front": "front", "left": "left", "right": "right"}
#: The thing a compartment named without its owner is of, as a drawer's is a cabinet
#: (:data:`_PART_OF`): "place it in the back compartment" is the caddy's, where one is declared.
_COMPARTMENT_OF = "caddy"


def _things(world: World) -> World:
    """``world`` with its regions among its objects (a region's name not already an object's):
    every declared thing a part (a drawer, a compartment) may belong to, fixtures too."""
    names = {o.name for o in world.objects}
    return World(objects=world.objects + tuple(r for r in world.regions if r.name not in names), regions=(),
                 source=world.source)


def _into_compartment(text: str, dest_words: list[str], prep: str | None, world: World, previous: tuple[str, ...]
                      ) -> tuple[str, str] | list[tuple[str, str]] | None:
    """``(thing, side)`` when a move's destination is a compartment of one declared thing (a
    fixture too): "in / into the back compartment of the caddy", "in the caddy's back
    compartment", "in back compartment" (of the one :data:`_COMPARTMENT_OF`), "to the right
    compartment of the caddy" (LIBERO-90's words) (``side`` one of
    :data:`_COMPARTMENT_SIDES`'s values, the viewer's side of the thing it lies on, which is how
    perception names compartments). A list of problems when it names a compartment but not
    which one, or of no one thing; ``None`` when the destination is no compartment."""
    if prep not in ("in", "into", "inside", "to"):
        return None
    ws = [w for w in dest_words if w not in ("the", "a", "an", "its")]
    k = next((i for i, w in enumerate(ws) if w in _COMPARTMENT_WORDS), None)
    if k is None:
        return None
    before, after = ws[:k], ws[k + 1:]
    owner: list[str] = []
    if "s" in before:  # "the caddy's back compartment": the owner before the possessive
        i = before.index("s")
        owner, before = before[:i], before[i + 1:]
    sides = [_COMPARTMENT_SIDES[w] for w in before if w in _COMPARTMENT_SIDES]
    if len(sides) != 1 or len(before) != 1:
        return [("not_understood", f"{quote(text)}: which {ws[k]}? (say the front, back, left or right {ws[k]} "
                                   f"of one thing)")]
    default = not owner and not after  # "place it in the back compartment": of the one caddy
    if default:
        owner = [_COMPARTMENT_OF]
    elif not owner:
        if after[0] != "of" or len(after) < 2:
            return [("not_understood", f"{quote(text)}: the {sides[0]} {ws[k]} of what?")]
        owner = after[1:]
    elif after:
        return [("not_understood", f"{quote(text)}: the {sides[0]} {ws[k]} of {' '.join(owner)}, then "
                                   f"{' '.join(after)!r}?")]
    things = _things(world)
    objects, _, problems = _read_objects(owner, things, previous)
    if default and (problems or len(objects) != 1):
        return [("not_understood", f"{quote(text)}: the {sides[0]} {ws[k]} of what? (no one {_COMPARTMENT_OF} here)")]
    if problems:
        return problems
    if len(objects) != 1:
        return [("not_understood", f"{quote(text)}: the {sides[0]} {ws[k]} of one thing")]
    return objects[0], sides[0]


def _settle(meaning: Meaning) -> None:
    """Join what one action spans: a pick followed by a move of the same object is that move ("pick up the red
    cube and put it in the left bin"); a repeated hold of the same object is one hold ("pick it up and hold it");
    objects a later clause leaves where they are drop out of an earlier quantified clause ("put all cubes in the
    left bin but leave the red one")."""
    intents = meaning.intents
    for i in reversed(range(len(intents))):
        it = intents[i]
        if it.verb == "hold" and any(later.verb in ("move", "stack", "hold") and set(it.movers()) <= set(later.movers())
                                     for later in intents[i + 1:]):
            del intents[i]
    for k, leave in enumerate(intents):
        if leave.verb != "leave":
            continue
        for i, it in enumerate(intents[:k]):
            if it.verb != "leave" and len(it.objects) > 1 and set(leave.objects) & set(it.objects):
                kept = tuple(o for o in it.objects if o not in leave.objects)
                intents[i] = replace(it, objects=kept,
                                     count=it.count if it.count is None or it.count < len(kept) else None,
                                     excluded=it.excluded + tuple(o for o in leave.objects if o in it.objects))
    for leave in [it for it in intents if it.verb == "leave"]:
        both = [o for it in intents if it.verb != "leave" for o in it.movers() if o in leave.objects]
        if both:
            # "pick up the red cube and don't put it down in the left bin": moved and left at once
            meaning.problems.append(("not_understood", f"{quote(leave.text)} asks that {', '.join(both)} stays where "
                                                       f"it is, and another part of the request moves it"))
    holds = [it for it in intents if it.verb == "hold"]
    acting = [it for it in intents if it.verb != "leave"]
    if holds and (len(holds) > 1 or acting[-1] is not holds[0] or len(holds[0].movers()) != 1):
        meaning.problems.append(("not_understood", f"{quote(holds[0].text)}: one arm holds one object, and only as "
                                                   f"the last step"))
