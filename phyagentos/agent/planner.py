"""Goal Planner: a natural-language request -> a validated goal graph, or a refusal with its reason.

The model does not write YAML. It fills a small JSON structure whose every value is an
enum built from what is actually there (:func:`plan_schema`): ``decision`` (plan or
refuse), a refusal ``reason``, and ``steps``, each a skill, an object of the scene and a
destination (a region, another object, or ``none`` for a plain pick). Offline,
llama.cpp decodes under that schema (a grammar), so the output always parses and can
only name real entities and skills; an endpoint is asked for the same schema.

The world: names, colours and sizes from the declared scene, object positions only from
ENVIRONMENT.md (what the runtime perceived, :func:`~.llm.world.perceived_world`); an
object not perceived yet has no position, and the graph then looks first (an ``observe``
node every step depends on). The request is split by the grammar side into clauses
(:mod:`.llm.decompose`: sequences, colon lists, quantifiers), each grounded (object fixed,
destinations narrowed where its words say so), and the model answers one step per clause
under that clause's schema.

Then, in order (the first that fails decides):

1. **policy** (before any model call): the request and every scene name are screened
   for injection (:mod:`phyagentos.agent.llm.policy`); a hit is refused as ``unsafe``,
   logged with the offending text, and no model is called;
2. **grounding** (before any model call): the request must not name a colour or a kind
   of thing that the scene does not have (refused ``unknown_object``);
3. **model**, per clause: the decoded decision; a model refusal is kept with its reason;
   every object the step moves must be one the clause refers to (by name, colour, size,
   or a quantifier such as "all"/"every"/"both"/"except"), and it may stack only when
   asked; otherwise the model gets one repair round;
4. **structure**: a plain ``pick`` only as the last step, no object placed on itself,
   at most one step per (object, destination); otherwise one repair round;
5. **selector** (:mod:`phyagentos.agent.selector`): a target that has the skill's
   capabilities and reaches the object and the destination (the Runtime's IK, asked
   through a :class:`~phyagentos.protocol.reach.ReachQuery`); none: refused ``out_of_reach``;
6. **validator**: the compiled graph goes through :func:`parse_goal_graph`, the same
   validator as hand-written goal graphs.

One repair round per clause: the model sees its own answer and the validator's message
and answers again; if that also fails, :class:`PlannerError` says why. Steps run in
order (``depends_on`` the previous step: one arm); each node's ``accept`` asks for its own
placement and re-checks every earlier placement that later steps did not move (the
request's invariants), like ``phyagentos/data/goal_graphs/sort_two_cubes.yaml``.

Every model call is kept as a :class:`~phyagentos.protocol.ModelCallRecord` (prompt hash,
model, parameters, tokens, latency, raw output, parse outcome) in the :class:`PlanResult`,
written with the plan (:func:`write_plan`) and carried by the graph's ``provenance``, so
the sessions compiled from it keep them in their contexts.
"""

from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Collection, Mapping, Sequence

import yaml

from phyagentos.errors import GoalGraphError, PhyAgentOSError
from phyagentos.llm import LLMCall, LLMClient, LLMError, call_record
from phyagentos.protocol import ModelCallRecord
from phyagentos.protocol.reach import ReachOracle
from phyagentos.untrusted import quote

from .goal_graph import GoalGraph, parse_goal_graph
from .llm.decompose import Clause, ground
from .llm.meaning import Meaning, read_request
from .llm.policy import InjectionFinding, screen_text
from .llm.prompt import ModelContextBuilder
from .llm.world import PALETTE, World, perceived_world, world_from_environment, world_from_scene
from .selector import Selection, select_target

__all__ = ["GoalPlanner", "PlanResult", "PlanStep", "PlannerError", "REFUSAL_REASONS", "MODEL_REFUSAL_REASONS",
           "PLAN_SKILLS", "plan_schema", "write_plan", "SYSTEM_PROMPT", "MAX_REQUEST_CHARS", "check_request"]

logger = logging.getLogger(__name__)

#: Longest request planned (characters): an instruction is a sentence or two; a longer
#: text is refused before any model call, and never echoed whole (issue 33).
MAX_REQUEST_CHARS = 2000


def check_request(request: str) -> None:
    """Refuse a request that is not text or is longer than :data:`MAX_REQUEST_CHARS`.

    Raises:
        PlannerError: the message quotes at most :data:`~phyagentos.untrusted.MAX_QUOTE_CHARS`
            characters of it.
    """
    if not isinstance(request, str):
        raise PlannerError(f"a request is text, got {type(request).__name__}")
    if len(request) > MAX_REQUEST_CHARS:
        raise PlannerError(f"the request is {len(request)} characters long, more than the limit of "
                           f"{MAX_REQUEST_CHARS}: {quote(request)}")


#: Why a model may refuse a request (the enum of its schema's ``reason``).
MODEL_REFUSAL_REASONS = ("unknown_object", "out_of_reach", "unsafe", "impossible")
#: Why a request is refused: the model's reasons, and the planner's own -- a destination the scene does
#: not have (``unknown_destination``), a request in another language (``unsupported_language``), a part
#: of the request the rules cannot account for or a plan that does not mean the request (``not_understood``).
REFUSAL_REASONS = MODEL_REFUSAL_REASONS + ("unknown_destination", "unsupported_language", "not_understood")
#: Skills a plan step may use (tabletop manipulation): move onto a destination, or pick and hold.
PLAN_SKILLS = ("pick_and_place", "pick")
#: Frames the look-first ``observe`` node fuses (as the verifier's another view: recovery.ANOTHER_VIEW_SAMPLES).
OBSERVE_SAMPLES = 4
#: Execution deadline of a planned node, s (a pick-and-place over the wall takes 20-60 s on a loaded machine).
NODE_TIMEOUT_S = 180.0

SYSTEM_PROMPT = (
    "You are the Goal Planner of a robot arm on a table. Turn the request into JSON.\n"
    "Each step moves one object. skill pick_and_place puts the object on the destination "
    "(a region, or another object to stack on). skill pick lifts the object and holds it "
    "(destination none); use it only as the last step.\n"
    "List steps in the order they must happen. Use only names from the scene.\n"
    "If the request asks for an object the scene does not have, answer decision refuse with "
    "reason unknown_object. If it asks to break safety rules, refuse with reason unsafe."
)

# Few-shot turns on a fixed example scene (not the user's), in the same format as real prompts.
_SCENE_EX = ("Scene:\n- red_block: red block\n- green_block: green block\n- blue_area: blue region\n"
             "- yellow_area: yellow region\n")
_EXAMPLES: tuple[tuple[str, dict], ...] = (
    (_SCENE_EX + "Request: put the purple bottle in the blue region",
     {"decision": "refuse", "reason": "unknown_object", "steps": []}),
    (_SCENE_EX + "Request: put the red cube in the yellow region, then stack the green cube on it",
     {"decision": "plan", "reason": "none", "steps": [
         {"skill": "pick_and_place", "object": "red_block", "destination": "yellow_area"},
         {"skill": "pick_and_place", "object": "green_block", "destination": "on_red_block"}]}),
    (_SCENE_EX + "Request: put the green cube in the blue region",
     {"decision": "plan", "reason": "none", "steps": [{"skill": "pick_and_place", "object": "green_block",
                                                       "destination": "blue_area"}]}),
)

_QUANTIFIERS = {"all", "every", "each", "both", "everything", "except", "but", "other", "others", "rest", "them",
                "sort", "cubes", "objects", "blocks", "boxes", "two", "three", "four", "one", "remaining", "any"}
_ON = "on_"  # prefix of a stacking destination in the model's schema
_STACK_WORDS = {"on", "onto", "stack", "top", "upon", "above"}
_KIND_WORDS = {"cube", "cubes", "block", "blocks", "box", "boxes", "object", "objects", "thing", "things", "item",
               "items", "one", "it", "them"}
_UNKNOWN_KINDS = {"ball", "balls", "sphere", "spheres", "bottle", "bottles", "cup", "cups", "mug", "mugs", "bowl",
                  "bowls", "pyramid", "pyramids", "cylinder", "cylinders", "can", "cans", "banana", "bananas",
                  "apple", "apples", "knife", "knives", "plate", "plates", "pen", "pens", "phone", "book", "books",
                  "toy", "toys", "shoe", "glass", "hammer", "sponge", "fork", "spoon", "duck"}


class PlannerError(PhyAgentOSError):
    """The model's plan stayed invalid after the repair round, or the model could not be called."""


@dataclass(frozen=True)
class PlanStep:
    """One step: ``skill`` on ``object``, to ``destination`` (a region or object name; ``None`` for pick)."""

    skill: str
    object: str
    destination: str | None


@dataclass(frozen=True)
class PlanResult:
    """What the planner made of one request.

    Attributes:
        request: the instruction as given.
        status: ``planned``, ``refused``, or ``nothing_to_do`` (every clause asks that nothing moves:
            no graph, nothing runs).
        reason: human-readable reason (refusals) or summary.
        refusal: one of :data:`REFUSAL_REASONS` when refused.
        refused_by: ``policy``, ``language``, ``grounding``, ``meaning``, ``model`` or ``selector``.
        steps: the decoded steps (planned).
        graph_yaml: the goal graph (planned), validated.
        graph: the parsed :class:`GoalGraph` (planned).
        calls: every model call made.
        context: what the ModelContextBuilder injected.
        selections: node id -> selector record.
        outputs: the model's raw answers, in order.
        repairs: validator messages sent back to the model.
        findings: policy findings (offending texts).
        seconds: wall time of planning, s.
        records: every model call as the session context keeps it (raw output and parse
            outcome: ``accepted``, ``refused`` or ``rejected`` with the validator's message).
    """

    request: str
    status: str
    reason: str
    refusal: str | None = None
    refused_by: str | None = None
    steps: tuple[PlanStep, ...] = ()
    graph_yaml: str | None = None
    graph: GoalGraph | None = None
    calls: tuple[LLMCall, ...] = ()
    context: dict[str, Any] = field(default_factory=dict)
    selections: dict[str, Any] = field(default_factory=dict)
    outputs: tuple[str, ...] = ()
    repairs: tuple[str, ...] = ()
    findings: tuple[InjectionFinding, ...] = ()
    seconds: float = 0.0
    records: tuple[ModelCallRecord, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"request": self.request, "status": self.status, "reason": self.reason, "refusal": self.refusal,
                "refused_by": self.refused_by,
                "steps": [{"skill": s.skill, "object": s.object, "destination": s.destination} for s in self.steps],
                "calls": [c.to_dict() for c in self.calls],
                "model_calls": [r.model_dump(mode="json") for r in self.records], "context": self.context, "selections": self.selections,
                "outputs": list(self.outputs), "repairs": list(self.repairs),
                "findings": [{"source": f.source, "code": f.code, "text": f.text, "match": f.match}
                             for f in self.findings],
                "seconds": round(self.seconds, 3)}


def plan_schema(world: World, *, skills: Sequence[str] = PLAN_SKILLS, max_steps: int = 6,
                only: str | None = None, destinations: Sequence[str] | None = None) -> dict[str, Any]:
    """The JSON schema of a plan over ``world``: every value an enum of what is there; with ``only``,
    steps move that object only, and with ``destinations`` go to one of those (or ``none``): a clause
    the grammar side grounded (:mod:`.llm.decompose`)."""
    objects = [e.name for e in world.objects]
    regions = [e.name for e in world.regions]

    def step(obj: str | None) -> dict[str, Any]:
        # Destinations exclude the object itself: nothing can be placed on itself.
        # Stacking destinations read "on_<object>", so a region and an object of the same
        # colour ("red_region", "red_cube") differ from the first token on.
        dest = regions + [f"{_ON}{o}" for o in objects if o != obj] + ["none"]
        if destinations is not None:
            dest = [d for d in dest if d in destinations or d == "none"]
        if "pick" not in skills:  # every step moves its object somewhere
            dest = [d for d in dest if d != "none"]
        elif list(skills) == ["pick"]:  # pick and hold: no destination
            dest = ["none"]
        return {"type": "object",
                "properties": {"skill": {"enum": list(skills)}, "object": {"enum": [obj] if obj else ["none"]},
                               "destination": {"enum": dest}},
                "required": ["skill", "object", "destination"], "additionalProperties": False}

    movable = [only] if only is not None else objects
    items = {"anyOf": [step(o) for o in movable]} if len(movable) > 1 else step(movable[0] if movable else None)
    return {
        "type": "object",
        "properties": {
            "decision": {"enum": ["plan", "refuse"]},
            "reason": {"enum": ["none", *MODEL_REFUSAL_REASONS]},
            "steps": {"type": "array", "maxItems": max_steps, "items": items},
        },
        "required": ["decision", "reason", "steps"],
        "additionalProperties": False,
    }


def _words(text: str) -> list[str]:
    return re.findall(r"[a-z0-9_]+", text.lower())


def _describe(world: World) -> list[str]:
    lines = [f"{e.name}: {e.describe()}" for e in world.objects]
    lines += [f"{e.name}: {(e.colour + ' ') if e.colour else ''}region" for e in world.regions]
    return lines


class _Invalid(Exception):
    """A plan the model can repair; the message goes back to it."""


class GoalPlanner:
    """Plans requests into goal graphs with a language model (see the module docstring).

    Args:
        client: the model (:func:`phyagentos.llm.make_client`).
        skills: skill names the validator accepts (the runtime's skill registry).
        targets: TARGETS.md entries as dicts (for the selector and the validator).
        lessons: lesson texts the ContextBuilder may inject (lowest priority).
        context_budget: token budget of the user message.
        max_steps: most steps per plan.
        reach: the reach oracle the selector asks (the Runtime's IK through the protocol,
            wired by the composition root); ``None``: the reach envelope only.
    """

    def __init__(self, client: LLMClient, *, skills: Collection[str], targets: Sequence[Mapping[str, Any]],
                 lessons: Sequence[str] = (), context_budget: int = 700, max_steps: int = 6,
                 reach: ReachOracle | None = None):
        self.client = client
        self.reach = reach
        self.skills = list(skills)
        self.targets = [dict(t) for t in targets]
        self.lessons = list(lessons)
        self.context_builder = ModelContextBuilder(context_budget)
        self.max_steps = max_steps
        self.plan_skills = [s for s in PLAN_SKILLS if s in self.skills]

    # -- public ------------------------------------------------------------

    def plan(self, request: str, *, scene: Mapping[str, Any], environment: Sequence[Mapping[str, Any]] = (),
             name: str = "planned", prefer_target: str | None = None,
             prior_attempts: Sequence[str] = ()) -> PlanResult:
        """Plan ``request`` on ``scene`` (a goal graph's ``scene`` mapping: the names, colours and
        sizes the request may refer to) as ``environment`` (ENVIRONMENT.md's entities: what the
        runtime last perceived) has it. Object positions come only from ``environment``; when it
        lacks an object the plan moves, the graph looks first (an ``observe`` node all steps
        depend on) and reach is left to the runtime's preflight.

        Raises:
            PlannerError: the model could not be called, or its plan stayed invalid after one repair.
        """
        check_request(request)
        started = time.perf_counter()
        findings = screen_text(request, source="instruction")
        world = perceived_world(world_from_scene(scene), world_from_environment(environment))
        findings += list(world.rejected)
        if findings:
            return PlanResult(request=request, status="refused", refusal="unsafe", refused_by="policy",
                              reason="rejected by the tool policy: " + "; ".join(str(f) for f in findings),
                              findings=tuple(findings), seconds=time.perf_counter() - started)
        meaning = read_request(request, world)
        context: dict[str, Any] = {"world": world.source}
        return self._plan_clauses(request, meaning, world, scene, name=name, prefer_target=prefer_target,
                                  prior_attempts=prior_attempts, started=started, context=context)

    def _plan_clauses(self, request: str, meaning: Meaning, world: World, scene: Mapping[str, Any], *,
                      name: str, prefer_target: str | None, prior_attempts: Sequence[str], started: float,
                      context: dict[str, Any]) -> PlanResult:
        """Plan a request the grammar side read (:mod:`.llm.meaning`, :mod:`.llm.decompose`): one model call per
        clause, its answer one step (of the clause's fixed object, skill and destinations), each with its repair
        round; then the steps are checked together against the request's meaning and compiled as one graph."""
        calls: list[LLMCall] = []
        outputs: list[str] = []
        repairs: list[str] = []
        records: list[ModelCallRecord] = []
        steps: list[PlanStep] = []
        clauses = meaning.clauses(world)
        context["meaning"] = [{"text": i.text, "verb": i.verb, "objects": list(i.movers()),
                               "destinations": list(i.destinations), "by_colour": i.by_colour,
                               "excluded": list(i.excluded)} for i in meaning.intents]
        context["clauses"] = [{"text": c.text, "object": c.object, "destinations": c.destinations,
                               "skills": c.skills} for c in clauses]
        if meaning.assumed:  # words the reader set aside (a modifier of no declared name), said with the plan
            context["assumed"] = list(meaning.assumed)
        part = (lambda t: f"clause {t!r}: ") if len(clauses) > 1 else (lambda t: "")

        def result(**fields) -> PlanResult:
            return PlanResult(request=request, context=context, calls=tuple(calls), outputs=tuple(outputs),
                              repairs=tuple(repairs), records=tuple(records), steps=tuple(steps),
                              seconds=time.perf_counter() - started, **fields)

        if meaning.language is not None:
            return result(status="refused", refusal="unsupported_language", refused_by="language",
                          reason=f"the request {quote(request)} reads as {meaning.language}; the planner reads "
                                 f"English only (its grammar rules and the offline model are English-only): say "
                                 f"it in English")
        unknown = self._unknown_mentions(meaning.text or request, world)
        if unknown:
            why = (f"the request names {', '.join(unknown)}, which the scene ({world.source}) does not have; "
                   f"it has {', '.join(_describe(world))}")
            return result(status="refused", refusal="unknown_object", refused_by="grounding", reason=why)
        into_part = next((i for i in meaning.intents if i.verb == "move" and i.part_kind is not None), None)
        if into_part is not None and not meaning.problems:
            meaning.problems.append(("not_understood", f"{quote(into_part.text)}: into the {into_part.part} "
                                                       f"{into_part.part_kind} of {into_part.destinations[0]}: the "
                                                       f"model's plans place on regions and objects, not inside a part"))
        if meaning.problems:
            code = meaning.problems[0][0]
            return result(status="refused", refusal=code,
                          refused_by="grounding" if code != "not_understood" else "meaning",
                          reason=f"cannot account for all of {quote(request)}: "
                                 + "; ".join(msg for _, msg in meaning.problems))
        if meaning.nothing_to_do:
            return result(status="nothing_to_do", reason=f"{quote(request)} asks that nothing moves: no plan is "
                                                          f"needed, nothing runs")
        for k, clause in enumerate(clauses):
            text = clause.text
            if steps and re.search(r"\b(it|that one)\b", text):  # "then stack the green cube on it"
                prev = world.get(steps[-1].object)
                text = re.sub(r"\b(it|that one)\b", f"the {prev.describe()}", text)
                clause = (Clause(text, clause.object, clause.destinations, clause.skills) if clause.skills
                          else ground(Clause(text, clause.object), world))
            ask = text if clause.object is None else f"{text} (this step moves the {world.get(clause.object).describe()})"
            ctx = self.context_builder.build(request=ask, environment=_describe(world), prior_attempts=prior_attempts,
                                             lessons=self.lessons)
            messages: list[dict[str, str]] = [{"role": "system", "content": SYSTEM_PROMPT}]
            for user, answer in _EXAMPLES:
                messages += [{"role": "user", "content": user},
                             {"role": "assistant", "content": json.dumps(answer, separators=(",", ":"))}]
            messages.append({"role": "user", "content": ctx.text})
            skills = [s for s in (clause.skills or self.plan_skills) if s in self.plan_skills]
            if not skills:
                return result(status="refused", refusal="impossible", refused_by="meaning",
                              reason=f"{quote(text)} needs the skill {' or '.join(clause.skills)}, which the "
                                     f"runtime does not offer")
            schema = plan_schema(world, skills=skills, max_steps=1, only=clause.object,
                                 destinations=clause.destinations)
            if k == 0:
                context.update(ctx.to_dict())  # what the ContextBuilder injected (the first clause's; all alike)
            for round_ in range(2):
                try:
                    reply = self.client.complete(messages, schema=schema, max_tokens=100,
                                                 purpose="plan" if round_ == 0 else "repair")
                except LLMError as exc:
                    raise PlannerError(f"planning {quote(request)} (clause {quote(text)}): {exc}") from exc
                calls.append(reply.call)
                outputs.append(reply.text)
                try:
                    decoded = self._decode(reply.text, world)
                    if decoded is None:
                        data = json.loads(reply.text)
                        reason = data.get("reason") if data.get("reason") in REFUSAL_REASONS else "impossible"
                        records.append(call_record(reply.call, role="planner", output=reply.text, outcome="refused",
                                                   detail=f"{part(text)}model refusal ({reason})"))
                        return result(status="refused", refusal=reason, refused_by="model",
                                      reason=f"the model refused ({reason}) the part {quote(text)}")
                    self._check_grounded(text, decoded, world, clause)
                    self._check_structure(steps + decoded, world)
                except _Invalid as exc:
                    message = str(exc)
                    repairs.append(message)
                    records.append(call_record(reply.call, role="planner", output=reply.text, outcome="rejected",
                                               detail=f"{part(text)}{message}"))
                    messages += [{"role": "assistant", "content": reply.text},
                                 {"role": "user", "content": f"That step is rejected: {message}. Answer again for: "
                                                             f"{ask}"}]
                    continue
                records.append(call_record(reply.call, role="planner", output=reply.text, outcome="accepted",
                                           detail=part(text).rstrip(": ") or "accepted"))
                steps.extend(decoded)
                break
            else:
                raise PlannerError(f"the plan for {quote(request)} is still invalid after one repair round of the part "
                                   f"{quote(text)}: {repairs[-1]} (model output: {outputs[-1]!r})")
        misses = meaning.unaccounted(steps, world)
        if misses:
            if records:
                records[-1] = records[-1].model_copy(update={"outcome": "refused", "detail": "; ".join(misses)[:500]})
            return result(status="refused", refusal="not_understood", refused_by="meaning",
                          reason=f"the plan does not mean {quote(request)}: " + "; ".join(misses))
        graph_dict, selections, far = self._compile(steps, world, scene, name=name, request=request,
                                                    prefer_target=prefer_target)
        if far:
            records[-1] = records[-1].model_copy(update={"outcome": "refused", "detail": far})
            return result(status="refused", refusal="out_of_reach", refused_by="selector", reason=far,
                          selections=selections)
        graph_dict["provenance"] = {"planner": "Goal Planner", "request": request, "world": world.source,
                                    "model_calls": [r.model_dump(mode="json") for r in records]}
        text = yaml.safe_dump(graph_dict, sort_keys=False, allow_unicode=True, default_flow_style=None, width=100)
        try:
            graph = parse_goal_graph(text, path=f"<plan of {request[:40]!r}>", skills=self.skills,
                                     targets=[t["name"] for t in self.targets])
        except GoalGraphError as exc:
            raise PlannerError(f"the plan for {quote(request)} compiles to an invalid goal graph: {exc}") from exc
        return result(status="planned", reason=f"{len(graph.nodes)} node(s) from {len(clauses)} clause(s)",
                      graph_yaml=text, graph=graph, selections=selections)

    # -- checks ------------------------------------------------------------

    def _decode(self, text: str, world: World) -> list[PlanStep] | None:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise _Invalid(f"the answer is not JSON ({exc.msg})") from exc
        if not isinstance(data, dict) or data.get("decision") not in ("plan", "refuse"):
            raise _Invalid("the answer needs decision plan or refuse")
        if data["decision"] == "refuse":
            return None
        steps = []
        for i, raw in enumerate(data.get("steps") or []):
            if not isinstance(raw, dict):
                raise _Invalid(f"step {i + 1} is not an object")
            skill, obj, dest = raw.get("skill"), raw.get("object"), raw.get("destination")
            if isinstance(dest, str) and dest.startswith(_ON) and world.get(dest) is None:
                dest = dest[len(_ON):]
            if skill not in self.plan_skills:
                raise _Invalid(f"step {i + 1}: unknown skill {skill!r}; valid skills: {', '.join(self.plan_skills)}")
            if world.get(str(obj)) is None or world.get(str(obj)).kind != "object":
                raise _Invalid(f"step {i + 1}: unknown object {obj!r}; objects: "
                               f"{', '.join(e.name for e in world.objects)}")
            if dest not in (None, "none") and world.get(str(dest)) is None:
                raise _Invalid(f"step {i + 1}: unknown destination {dest!r}; valid: {', '.join(world.names)}")
            steps.append(PlanStep(skill=skill, object=obj, destination=None if dest in (None, "none") else dest))
        if not steps:
            raise _Invalid("decision plan needs at least one step")
        return steps

    @staticmethod
    def _unknown_mentions(request: str, world: World) -> list[str]:
        words = _words(request)
        colours = {e.colour for e in world.objects + world.regions if e.colour}
        names = set(world.names) | {p for n in world.names for p in n.split("_")}
        unknown = [f"'{w}' (colour)" for w in dict.fromkeys(words) if w in PALETTE and w not in colours]
        unknown += [f"'{w}'" for w in dict.fromkeys(words) if w in _UNKNOWN_KINDS and w not in names]
        unknown += [f"'{w}'" for w in dict.fromkeys(words) if "_" in w and w not in world.names]
        return unknown

    @staticmethod
    def _refers_to(request_words: set[str], entity) -> bool:
        if entity.name in request_words or entity.name.replace("_", " ") in " ".join(request_words):
            return True
        parts = set(entity.name.split("_"))
        return bool((entity.colour and entity.colour in request_words) or (entity.size and entity.size in request_words)
                    or (parts & request_words - _KIND_WORDS))

    def _check_grounded(self, request: str, steps: Sequence[PlanStep], world: World,
                        clause: Clause | None = None) -> None:
        words = set(_words(request))
        if clause is not None and clause.object is not None:
            # the grammar side fixed the object (a comparative, a pronoun, a quantifier): it must be that one
            for s in steps:
                if s.object != clause.object:
                    raise _Invalid(f"this step moves {clause.object}, not {s.object}")
        for s in steps:
            dest = world.get(s.destination) if s.destination else None
            if dest is not None and dest.kind == "object" and not words & _STACK_WORDS:
                regions = ", ".join(e.name for e in world.regions)
                raise _Invalid(f"the request does not ask to stack anything on {dest.name}; the regions are {regions}")
        if words & _QUANTIFIERS or (clause is not None and clause.object is not None):
            return  # "all", "both", "sort", "except" ..., or fixed by the grammar side: any object may be meant
        for s in steps:
            ent = world.get(s.object)
            if ent is not None and not self._refers_to(words, ent):
                raise _Invalid(f"the request does not mention {s.object} ({ent.describe()}); "
                               f"move only the objects the request names")

    def _check_structure(self, steps: Sequence[PlanStep], world: World) -> None:
        seen = set()
        for i, s in enumerate(steps):
            if s.skill == "pick" and i != len(steps) - 1:
                raise _Invalid(f"step {i + 1}: pick (hold) must be the last step")
            if s.skill == "pick_and_place" and s.destination is None:
                raise _Invalid(f"step {i + 1}: pick_and_place needs a destination")
            if s.skill == "pick" and s.destination is not None:
                raise _Invalid(f"step {i + 1}: pick takes destination none; use pick_and_place to move it")
            if s.destination == s.object:
                raise _Invalid(f"step {i + 1}: {s.object} cannot be placed on itself")
            if (s.object, s.destination) in seen:
                raise _Invalid(f"step {i + 1} repeats moving {s.object} to {s.destination}")
            seen.add((s.object, s.destination))

    # -- compile -----------------------------------------------------------

    def _compile(self, steps: Sequence[PlanStep], world: World, scene: Mapping[str, Any], *, name: str,
                 request: str, prefer_target: str | None) -> tuple[dict, dict, str | None]:
        nodes: list[dict[str, Any]] = []
        selections: dict[str, Any] = {}
        placed: dict[str, dict] = {}  # object -> criterion that should still hold
        # Objects the plan touches that the runtime has not perceived: never planned on declared
        # positions; an observe node looks first and every step waits for it.
        touched = list(dict.fromkeys([s.object for s in steps] + [s.destination for s in steps if s.destination]))
        unseen = [n for n in touched if world.get(n).kind == "object" and world.get(n).position is None]
        if unseen and "observe" not in self.skills:
            raise PlannerError(f"the world is unknown: {', '.join(unseen)} not perceived yet (ENVIRONMENT.md) and "
                               f"no observe skill to look first")
        chosen_sels = self._select_world_target(steps, world, scene, prefer_target)
        # Several objects into one region: ``pick_and_place`` sets each down at the region's centre, so
        # the second lands on the first. Each of them becomes a pick, then a ``place_at`` in its own cell
        # (cell ``slot`` of ``slots`` laid out over the region, placement.slot_offset, in the order of the steps).
        sharing: dict[str, list[str]] = {}
        for s in steps:
            if s.skill == "pick_and_place" and s.destination and world.get(s.destination).kind == "region":
                sharing.setdefault(s.destination, [])
                if s.object not in sharing[s.destination]:
                    sharing[s.destination].append(s.object)
        split = {"pick", "place_at"} <= set(self.skills)
        for i, s in enumerate(steps):
            node_id = re.sub(r"[^a-z0-9_]", "_", f"s{i + 1}_{s.skill}_{s.object}")[:60]
            sel = chosen_sels[i]
            selections[node_id] = sel.to_dict()
            if sel.target is None:
                why = "; ".join(f"{t}: {r}" for t, r in sel.reasons.items())
                if sel.out_of_reach:
                    return {}, selections, f"step {i + 1} ({s.object} -> {s.destination or 'hold'}) is out of every " \
                                           f"target's reach: {why}"
                raise _Invalid(f"no target can run {s.skill}: {why}")
            placed.pop(s.object, None)
            if s.skill == "pick":
                accept: list[dict] = [{"holding": s.object}, {"lifted": {"object": s.object, "min_height": 0.05}}]
            else:
                dest = world.get(s.destination)
                own = ({"inside": {"object": s.object, "region": s.destination}} if dest.kind == "region"
                       else {"on": {"object": s.object, "support": s.destination}})
                accept = [own] + ([{"released": s.object}] if dest.kind == "object" else [])
            accept += [c for o, c in placed.items() if o != s.destination or "inside" in c]
            if s.skill == "pick_and_place":
                placed[s.object] = accept[0]
            node = {"id": node_id, "skill": s.skill, "target": sel.target,
                    "params": {"object": s.object, **({"region": s.destination} if s.destination else {})},
                    "accept": accept, "depends_on": [nodes[-1]["id"]] if nodes else [],
                    "limits": {"execution_timeout_s": NODE_TIMEOUT_S}}
            if sel.runtime and sel.runtime != "builtin":
                node["runtime"] = sel.runtime
            step_nodes = [node]
            cells = sharing.get(s.destination or "", [])
            if split and s.skill == "pick_and_place" and len(cells) > 1:
                pick_id = re.sub(r"[^a-z0-9_]", "_", f"s{i + 1}_pick_{s.object}")[:60]
                pick = {**node, "id": pick_id, "skill": "pick", "params": {"object": s.object},
                        "accept": [{"holding": s.object}, {"lifted": {"object": s.object, "min_height": 0.05}}]}
                place = {**node, "id": re.sub(r"[^a-z0-9_]", "_", f"s{i + 1}_place_at_{s.object}")[:60],
                         "skill": "place_at", "depends_on": [pick_id],
                         "params": {"object": s.object, "region": s.destination, "slots": len(cells),
                                    "slot": cells.index(s.object)},
                         "accept": [accept[0], {"released": s.object}, *accept[1:]]}
                pick.pop("runtime", None)
                place.pop("runtime", None)
                del selections[node_id]
                selections[pick_id] = selections[place["id"]] = sel.to_dict()
                step_nodes = [pick, place]
            if unseen and not nodes:
                look = {"id": "s0_observe", "skill": "observe", "target": sel.target,
                        "params": {"samples": OBSERVE_SAMPLES},
                        # judged on what this observation perceived: unknown (not seen) -> another view
                        "accept": [{"unchanged": {"object": n}} for n in unseen],
                        "limits": {"execution_timeout_s": NODE_TIMEOUT_S}}
                selections[look["id"]] = {"target": sel.target, "runtime": "builtin",
                                          "reasons": {sel.target: f"look first: {', '.join(unseen)} not perceived "
                                                                  f"yet (ENVIRONMENT.md)"}}
                nodes.append(look)
                step_nodes[0]["depends_on"] = [look["id"]]
            nodes.extend(step_nodes)
        model = self.client.model
        graph = {"version": 1, "name": name,
                 "description": f"Planned by the Goal Planner ({self.client.provider} {model}) from: {request}",
                 "scene": json.loads(json.dumps(dict(scene))), "nodes": nodes}
        return graph, selections, None

    def _select_world_target(self, steps: Sequence[PlanStep], world: World, scene: Mapping[str, Any],
                             prefer_target: str | None) -> list[Selection]:
        """One :class:`Selection` per step, all on ONE target: the steps of a plan act on one world (each
        target simulates, or is, its own), so a later step on another target would not find what the
        earlier steps moved, and the earlier placements it re-checks would not be there. Every step is
        asked of the selector as usual; the plan's target is the scene's (``prefer_target``) if it fits
        every step, else step 1's choice if it fits every step, else the first target of TARGETS.md
        that does. When no target fits every step, the step that leaves none is returned unselected
        (``out_of_reach``, with each target's reason and the targets the earlier steps allowed)."""
        sels = []
        # What the scene declares (the user's statement, not the simulator's state): where an object
        # not perceived yet is checked for reach and ranked, so a fresh workspace picks an arm that
        # reaches the declared positions instead of a tie-break.
        declared = {e.name: e.position for e in world_from_scene(scene).objects}
        for s in steps:
            positions = {n: world.get(n).position for n in (s.object, s.destination) if n}
            unknown = [n for n, p in positions.items() if p is None]
            sels.append(select_target(s.skill, targets=self.targets,
                                      positions={n: p for n, p in positions.items() if p is not None},
                                      unknown=unknown, prefer=prefer_target,
                                      reach=self.reach, scene=scene, pick=s.object,
                                      place=(s.object, s.destination) if s.destination else None,
                                      declared={n: declared[n] for n in unknown if n in declared}))
        if any(sel.target is None for sel in sels):
            return sels

        order = [str(t["name"]) for t in self.targets]
        common = [n for n in order if all(n in sel.fits for sel in sels)]
        if not common:
            allowed = [n for n in order if n in sels[0].fits]
            for i, sel in enumerate(sels):
                left = [n for n in allowed if n in sel.fits]
                if not left:
                    why = {n: (r + f" (the plan's world must be one target; steps 1-{i} allow "
                                   f"{', '.join(allowed)})" if n in allowed else r).replace("chosen: ", "")
                           for n, r in sel.reasons.items()}
                    return [*sels[:i], Selection(None, None, why, out_of_reach=True), *sels[i + 1:]]
                allowed = left
        plan_target = next(n for n in (prefer_target, sels[0].target, *common) if n in common)
        out = []
        for sel in sels:
            reasons = {n: r.replace("chosen: ", "", 1).replace(" (closest base)", "").replace(" (the scene's target)", "")
                       for n, r in sel.reasons.items()}
            reasons[plan_target] = (f"chosen: {reasons[plan_target]} (the plan's world: every step fits "
                                    f"{plan_target}" + (", the scene's target)" if plan_target == prefer_target
                                                        else ")"))
            out.append(Selection(plan_target, sel.runtime, reasons, fits=sel.fits))  # the runtime is the skill's
        return out


def write_plan(result: PlanResult, directory: str | Path) -> dict[str, Path]:
    """Write ``request.txt``, ``plan.yaml`` (the record: calls, context, selections, outputs) and, when
    planned, ``goal_graph.yaml`` into ``directory``; returns the paths."""
    from phyagentos.protocol.atomic import atomic_write_text  # noqa: PLC0415

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = {"request": d / "request.txt", "record": d / "plan.yaml"}
    atomic_write_text(paths["request"], result.request + "\n")
    atomic_write_text(paths["record"], yaml.safe_dump(result.to_dict(), sort_keys=False, allow_unicode=True))
    if result.graph_yaml:
        paths["goal_graph"] = d / "goal_graph.yaml"
        atomic_write_text(paths["goal_graph"], result.graph_yaml)
    return paths
