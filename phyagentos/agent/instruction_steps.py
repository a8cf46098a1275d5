"""A policy's instruction as the Goal Planner's steps, what a failed attempt's evidence leaves of
them, and the prompt of what is left, worded as LIBERO words its instructions.

A vision-language-action policy (``runtime: policy``, skill ``libero_policy``) gets one
``prompt``: the task's instruction (``pick up the alphabet soup and place it in the
basket``). After a failed verdict the policy flow's recovery (:mod:`.recovery`, the policy
ladder) may give the child a *corrected prompt*: only what remains, as the failed attempt's
perceived evidence shows it. This module is that reading, without any model call:

1. **Decompose** (:func:`decompose`): the instruction is read by the Goal Planner's rule
   reader (:func:`~phyagentos.agent.llm.meaning.read_request`, the reader ``phyagentos bench
   libero_*`` plans LIBERO's instructions with) over the *declared* scene, the objects and
   fixtures a goal graph's ``scene`` names (``declared_scene``). Each moved object is a
   ``move`` step (its pick, then its place on the destination), a lone ``pick up`` a
   ``hold``, ``open the top drawer of the cabinet`` an ``open`` and ``turn on the stove`` a
   ``turn_on``; steps keep the instruction's order. Refused (:class:`InstructionNotRead`,
   with the reader's reason) as the LIBERO plan refuses: another verb (close, push, turn
   off), a phrase naming nothing declared or several things, another language.
2. **Progress** (:func:`step_status`): each step's own acceptance (as the LIBERO plan's
   nodes accept them: ``on`` its destination for a move, ``holding`` for a hold,
   ``articulated`` past :data:`OPENED_MIN_FRACTION` / :data:`TURNED_ON_MIN_FRACTION` of the
   travel for a drawer or a knob) is judged by the verifier's own predicates
   (:func:`~phyagentos.agent.criteria.evaluate`, refined by the held-object model) on the
   attempt's perceived snapshots: ``done``; for a move not done, ``held`` when the hand is
   perceived holding its object; else ``todo``. An ``unknown`` judgement counts as not done
   (doing a step again is safer than skipping it).
3. **Prompt** (:func:`remaining_prompt`): the first unfinished step (a move whose object is
   in the hand first: the hand is not free for another) is worded from the instruction's own
   noun phrases and prepositions: ``place the alphabet soup in the basket`` (its object
   held), ``pick up the tomato sauce and place it in the basket`` (not started: the
   libero_object wording of one object of LIBERO-10's ``put both the alphabet soup and the
   tomato sauce in the basket``), ``pick up the black bowl between the plate and the ramekin``
   (a twin keeps the words that tell it apart), ``turn on the stove`` (a fixture step: its
   clause). When that is the prompt the attempt already had (a one-object instruction with
   nothing done), the prompt is the step's first part only: ``pick up the alphabet soup``.

Only the instruction, the declared scene and the perceived evidence (snapshots, trace) are
read: nothing of the simulator's privileged channel, nor the task's goal predicates.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

__all__ = ["InstructionStep", "InstructionNotRead", "decompose", "step_status", "remaining_prompt", "Remaining",
           "same_prompt", "MOVE", "HOLD", "OPEN", "TURN_ON", "DONE", "HELD", "TODO", "OPENED_MIN_FRACTION",
           "TURNED_ON_MIN_FRACTION"]

#: Step actions: a pick and place, a pick and hold, a drawer opened, a knob turned on.
MOVE, HOLD, OPEN, TURN_ON = "move", "hold", "open", "turn_on"
#: Step progress: its acceptance holds; a move's object is in the hand; neither.
DONE, HELD, TODO = "done", "held", "todo"
#: Fraction of a drawer's travel at which it counts as open, and of a knob's at which it counts
#: as on: the LIBERO plan's acceptance of its ``slide_drawer`` / ``turn_knob`` nodes
#: (``phyagentos.bench.libero``: 0.8 of the travel, 1/3 of the knob's range).
OPENED_MIN_FRACTION = 0.8
TURNED_ON_MIN_FRACTION = 1.0 / 3.0

_WORD = re.compile(r"[a-z0-9]+")
#: Words that end a noun phrase's head: the kind word LIBERO adds to a declared name
#: ("the cream cheese box" for ``cream_cheese_1``, "the cookie box" for ``cookies_1``).
_KIND_TAIL = frozenset({"box"})
#: Prepositions a destination follows in LIBERO's instructions ("on top of" is read whole).
_PREPOSITIONS = ("into", "in", "onto", "on", "inside", "to", "at")
#: Verbs after which an object's referring words end ("... the ramekin and place it on the plate").
_MOVE_VERBS = frozenset({"place", "put", "move", "set", "drop", "bring", "transfer", "carry", "stack"})


class InstructionNotRead(ValueError):
    """The instruction was not read into steps; the message says why (the reader's reason)."""


@dataclass(frozen=True)
class InstructionStep:
    """One step of an instruction.

    Attributes:
        action: :data:`MOVE`, :data:`HOLD`, :data:`OPEN` or :data:`TURN_ON`.
        object: the declared name it acts on (a move's and hold's object; the fixture of an
            open or turn on).
        destination: a move's declared destination (object or fixture); an open's drawer as a
            snapshot names it (``wooden_cabinet_1_top_drawer``); else ``None``.
        noun: the object as the instruction words it (``the alphabet soup``).
        reference: the words after the noun that tell a twin apart (``between the plate and
            the ramekin``), else empty.
        where: a move's destination phrase (``in the basket``, ``on top of the cabinet``).
        text: an open's or turn on's clause as the instruction words it (``turn on the stove``).
    """

    action: str
    object: str
    destination: str | None = None
    noun: str = ""
    reference: str = ""
    where: str = ""
    text: str = ""

    @property
    def acquires(self) -> str | None:
        """The object this step puts into the gripper (a move's or hold's), else ``None``."""
        return self.object if self.action in (MOVE, HOLD) else None

    def accept(self) -> list[dict[str, Any]]:
        """The step's acceptance criteria (``accept`` entries :mod:`.criteria` parses)."""
        if self.action == MOVE:
            return [{"on": {"object": self.object, "support": self.destination}}]
        if self.action == HOLD:
            return [{"holding": self.object}]
        if self.action == OPEN:
            return [{"articulated": {"object": self.destination, "min_fraction": OPENED_MIN_FRACTION}}]
        return [{"articulated": {"object": self.object, "min_fraction": TURNED_ON_MIN_FRACTION}}]

    def prompt(self, status: str = TODO) -> str:
        """The step worded as LIBERO words an instruction, for progress ``status``: a move whose
        object is held is its place (``place the alphabet soup in the basket``), else its pick
        and place (``pick up the alphabet soup and place it in the basket``)."""
        named = f"{self.noun} {self.reference}".strip()
        if self.action == MOVE:
            if status == HELD:
                return f"place {self.noun} {self.where}"
            return f"pick up {named} and place it {self.where}"
        if self.action == HOLD:
            return f"pick up {named}"
        return self.text

    def first_part(self) -> str:
        """The step's first part: a move's pick (``pick up the alphabet soup``); the whole
        step for the others."""
        if self.action == MOVE:
            return f"pick up {self.noun} {self.reference}".strip()
        return self.prompt(TODO)


@dataclass(frozen=True)
class Remaining:
    """What is left of an instruction: the ``step`` to do next, its progress ``status``
    (:data:`HELD` or :data:`TODO`) and its ``prompt``; ``progress`` says per step what the
    evidence showed (``alphabet_soup_1 on basket_1: done``)."""

    step: InstructionStep
    status: str
    prompt: str
    progress: str


def _singular(word: str) -> str:
    return word[:-1] if len(word) > 3 and word.endswith("s") else word


def _name_parts(name: str) -> frozenset[str]:
    """The words of a declared name without its instance number, singular
    (``cookies_1`` -> {cookie}); numbers count too (a ``plate_2``'s ``2`` does not)."""
    return frozenset(_singular(w) for w in re.sub(r"_\d+$", "", name).split("_") if w)


def _span(name: str, tokens: Sequence[str], others: Sequence[str] = ()) -> tuple[int, int] | None:
    """The run of ``tokens`` that best names ``name`` (each a word of its name; ``and`` between
    two such words: "the yellow and white mug"; one kind word after it: "cream cheese box"):
    the most words, a word another declared name in ``others`` shares counting half ("the
    rack" names ``wine_rack_1`` better than "the wine" of "the wine bottle"; a twin's identical
    words count whole); the first of the best; ``None`` when no token names it."""
    parts = _name_parts(name)
    shared = {w for other in others if other != name and _name_parts(other) != parts for w in _name_parts(other)}

    def names(i: int) -> bool:
        return 0 <= i < len(tokens) and _singular(tokens[i]) in parts

    def score(i: int, j: int) -> float:
        return sum((0.5 if _singular(tokens[k]) in shared else 1.0) for k in range(i, j) if names(k))

    best: tuple[int, int] | None = None
    i = 0
    while i < len(tokens):
        if not names(i):
            i += 1
            continue
        j = i + 1
        while names(j) or (tokens[j:j + 1] == ["and"] and names(j + 1) and tokens[j + 1] not in tokens[i:j]):
            j += 1 if names(j) else 2
        if j < len(tokens) and tokens[j] in _KIND_TAIL:
            j += 1
        if best is None or score(i, j) > score(*best):
            best = (i, j)
        i = j
    return best


def _noun(name: str, tokens: Sequence[str], others: Sequence[str] = ()) -> str:
    """``name`` as the instruction words it, with its article (``the alphabet soup``); a name
    the instruction does not word: its words (``the flat stove``)."""
    span = _span(name, tokens, others)
    words = tokens[span[0]:span[1]] if span else re.sub(r"_\d+$", "", name).split("_")
    return "the " + " ".join(words)


def _reference(name: str, tokens: Sequence[str], others: Sequence[str] = ()) -> str:
    """The words after ``name``'s noun up to the next verb of moving (``between the plate and the
    ramekin`` in "pick up the black bowl between the plate and the ramekin and place it ...")."""
    span = _span(name, tokens, others)
    if span is None:
        return ""
    out: list[str] = []
    for k in range(span[1], len(tokens)):
        if tokens[k] == "and" and k + 1 < len(tokens) and tokens[k + 1] in _MOVE_VERBS:
            break
        if tokens[k] in _MOVE_VERBS:
            break
        out.append(tokens[k])
    return " ".join(out)


def _preposition(clause: Sequence[str], destination: str, others: Sequence[str] = ()) -> str:
    """The preposition before ``destination`` (its noun, or ``it``) in a clause's words; "on"
    when the clause has none."""
    span = _span(destination, clause, others)
    end = span[0] if span is not None else next((k for k in range(len(clause) - 1, -1, -1)
                                                 if clause[k] in ("it", "them")), len(clause))
    for k in range(end - 1, -1, -1):
        if clause[k] == "of" and k >= 2 and clause[k - 2:k] == ["on", "top"]:
            return "on top of"
        if clause[k] in _PREPOSITIONS:
            return clause[k]
    return "on"


def _names(entries: Any) -> list[str]:
    return [str(e["name"]) for e in entries or () if isinstance(e, Mapping) and isinstance(e.get("name"), str)]


def decompose(instruction: str, declared: Mapping[str, Any] | None) -> tuple[InstructionStep, ...]:
    """The steps of ``instruction`` (module doc, 1).

    Args:
        instruction: the task's instruction as the policy's ``prompt`` gives it.
        declared: the declared scene (:func:`~phyagentos.agent.declared.declared_scene`:
            ``objects`` and ``fixtures``, each ``{name, class?}``).

    Raises:
        InstructionNotRead: nothing declared, another language, the reader's problems (a
            phrase naming nothing declared, or several things), a verb no step does (close,
            push, turn off), an open naming no drawer, or nothing to do.
    """
    from .llm.meaning import read_request  # noqa: PLC0415  (the reader loads its word lists on first use)
    from .llm.world import world_from_declared  # noqa: PLC0415

    objects = _names((declared or {}).get("objects"))
    fixtures = [n for n in _names((declared or {}).get("fixtures")) if n not in objects]
    if not objects:
        raise InstructionNotRead("the scene declares no objects: the instruction's words name nothing to move")
    meaning = read_request(instruction, world_from_declared(objects, fixtures, source="declared"), relations=True)
    if meaning.language is not None:
        raise InstructionNotRead(f"{meaning.language}: the rules read English only")
    if meaning.problems:
        raise InstructionNotRead("; ".join(f"{code}: {msg}" for code, msg in meaning.problems))
    tokens = _WORD.findall(instruction.lower())
    names = [*objects, *fixtures]
    steps: list[InstructionStep] = []
    for intent in meaning.intents:
        clause = _WORD.findall(intent.text.lower())
        if intent.verb == "leave":
            continue
        if intent.verb == "turn_on":
            steps.append(InstructionStep(TURN_ON, intent.objects[0], text=" ".join(clause)))
        elif intent.verb == "open" and intent.part_kind == "drawer" and intent.part:
            fixture = intent.objects[0]
            steps.append(InstructionStep(OPEN, fixture, destination=f"{fixture}_{intent.part}_drawer",
                                         text=" ".join(clause)))
        elif intent.verb in ("move", "stack", "hold"):
            for obj in intent.movers():
                ref = _reference(obj, tokens, names) if obj in meaning.where else ""
                if intent.verb == "hold":
                    steps.append(InstructionStep(HOLD, obj, noun=_noun(obj, tokens, names), reference=ref))
                    continue
                dests = [d for d in intent.destinations if d != obj]
                if intent.beside is not None:
                    raise InstructionNotRead(f"{intent.text!r} sets {obj} down beside {dests[0]}: a step beside a "
                                             f"landmark is not judged here yet")
                if len(dests) != 1:
                    raise InstructionNotRead(f"{intent.text!r} puts {obj} on {len(dests)} destinations: say which one")
                where = f"{_preposition(clause, dests[0], names)} {_noun(dests[0], tokens, names)}"
                if intent.part_kind in ("drawer", "compartment"):  # into a part's inside: its entity is the destination
                    where = f"in the {intent.part} {intent.part_kind} of the {_noun(dests[0], tokens, names)}"
                    dests = [f"{dests[0]}_{intent.part}_{intent.part_kind}"]
                steps.append(InstructionStep(MOVE, obj, destination=dests[0], noun=_noun(obj, tokens, names),
                                             reference=ref, where=where))
        elif intent.verb == "push":
            raise InstructionNotRead(f"{intent.text!r} pushes {intent.objects[0]} beside "
                                     f"{intent.destinations[0]}: a push is not a step here yet")
        else:
            raise InstructionNotRead(f"{intent.text!r}: no step {intent.verb}s here"
                                     + (" (only drawers are opened)" if intent.verb == "open" else ""))
    if not steps:
        raise InstructionNotRead("nothing to do")
    return tuple(steps)


def step_status(steps: Sequence[InstructionStep], evidence: Any) -> list[str]:
    """Each step's progress (module doc, 2) on the perceived snapshots of ``evidence`` (an
    :class:`~phyagentos.agent.verifier.EvidenceBundle`, or anything with ``initial``,
    ``terminal`` and ``trace``): :data:`DONE`, :data:`HELD` or :data:`TODO`."""
    from .criteria import evaluate, parse_criteria  # noqa: PLC0415
    from .held_object import refine  # noqa: PLC0415

    initial = getattr(evidence, "initial", None) or {}
    terminal = getattr(evidence, "terminal", None) or {}

    def holds(accept: list[dict[str, Any]]) -> bool:
        return all(refine(evaluate(c, initial, terminal), evidence).status == "satisfied"
                   for c in parse_criteria(accept, where="instruction step"))

    out = []
    for step in steps:
        if holds(step.accept()):
            out.append(DONE)
        elif step.action == MOVE and holds([{"holding": step.object}]):
            out.append(HELD)
        else:
            out.append(TODO)
    return out


def same_prompt(a: str | None, b: str | None) -> bool:
    """``a`` and ``b`` are one prompt but for case, spacing and punctuation."""
    return a is not None and b is not None and _WORD.findall(a.lower()) == _WORD.findall(b.lower())


def remaining_prompt(steps: Sequence[InstructionStep], statuses: Sequence[str], *,
                     tried: str | None = None) -> Remaining | None:
    """What is left of ``steps`` given their ``statuses`` (module doc, 3), or ``None`` when every
    step is done.

    Args:
        steps: :func:`decompose`'s steps.
        statuses: :func:`step_status` of them (one per step).
        tried: the prompt the failed attempt had: a remaining prompt equal to it is narrowed to
            the step's first part (a pick).
    """
    progress = "; ".join(f"{s.object}" + (f" on {s.destination}" if s.action == MOVE else f" {s.action}")
                         + f": {st}" for s, st in zip(steps, statuses))
    undone = [(s, st) for s, st in zip(steps, statuses) if st != DONE]
    if not undone:
        return None
    step, status = next(((s, st) for s, st in undone if st == HELD), undone[0])
    prompt = step.prompt(status)
    if status == TODO and same_prompt(prompt, tried):
        prompt = step.first_part()
    return Remaining(step=step, status=status, prompt=prompt, progress=progress)
