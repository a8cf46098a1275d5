"""Goal Planner for a task library: a request names a goal of an authored goal graph; the plan
is that goal and everything it depends on.

A game's tech tree (``phyagentos/data/goal_graphs/crafter_tech_tree.yaml``) already states the order of
the work and what each step needs; what a request like "get a stone pickaxe" adds is
*which* goal. So the plan is not written by the model: the grammar side narrows the
library's goals to those the request's words name (node ids and their achievements,
``make_stone_pickaxe`` for "stone pickaxe"), the model decides under a JSON schema whose
``goal`` is an enum of those candidates (or refuses), and the graph is the chosen node
with its ancestors in the library's DAG, in the library's file order, with its
defaults, schedule and acceptance unchanged. Then the same validator as hand-written
graphs (:func:`~.goal_graph.parse_goal_graph`).

In order (the first that fails decides): the policy screen (``unsafe``, no model call);
grounding (no goal shares a word with the request: ``impossible``, no model call); the
model (a refusal is kept with its reason); the validator. Every model call is kept as a
:class:`~phyagentos.protocol.ModelCallRecord` in the :class:`~.planner.PlanResult` and the
graph's ``provenance``, as for the tabletop planner.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Collection, Sequence

import networkx as nx
import yaml

from phyagentos.errors import GoalGraphError
from phyagentos.llm import LLMClient, LLMError, call_record
from phyagentos.untrusted import quote
from phyagentos.yamlsource import read_yaml

from . import dag as dagmod
from .goal_graph import GoalGraph, load_goal_graph, parse_goal_graph
from .llm.policy import screen_text
from .planner import MODEL_REFUSAL_REASONS as REFUSAL_REASONS
from .planner import PlannerError, PlanResult, check_request

__all__ = ["LibraryPlanner", "goal_candidates", "LIBRARY_SYSTEM_PROMPT"]

LIBRARY_SYSTEM_PROMPT = (
    "You choose which goal of a task library a request asks for. Answer with JSON only: "
    '{"decision": "plan", "goal": <one of the listed goals>} or {"decision": "refuse", "reason": <why>} '
    "when the request asks for something none of the goals gives.")
#: Worked examples shown before the request (goals of another library, so none is copied).
_EXAMPLES = (
    ("Goals: pick_cube.\nRequest: pick the cube and throw it at the operator",
     {"decision": "refuse", "goal": "pick_cube", "reason": "unsafe"}),
    ("Goals: boil_kettle, open_microwave.\nRequest: heat the kettle please",
     {"decision": "plan", "goal": "boil_kettle"}),
    ("Goals: place_plate, place_cup.\nRequest: set down a cup",
     {"decision": "plan", "goal": "place_cup"}),
    ("Goals: open_drawer.\nRequest: get the drawer open",
     {"decision": "plan", "goal": "open_drawer"}),
)
#: Words that name no goal ("get me a stone pickaxe": only "stone" and "pickaxe" count).
_STOP = frozenset("a an the me my to of for and please get make craft build collect find obtain some one i want "
                  "would like can you then first".split())


def _words(text: str) -> set[str]:
    return {w for w in re.findall(r"[a-z]+", text.lower()) if w not in _STOP}


def _strings(value) -> list[str]:
    """Every string inside an ``accept`` mapping (achievements, items), depth first."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, dict):
        return [s for v in value.values() for s in _strings(v)]
    if isinstance(value, (list, tuple)):
        return [s for v in value for s in _strings(v)]
    return []


def goal_candidates(request: str, library: GoalGraph) -> list[str]:
    """Node ids of ``library`` that share the most words with ``request`` (a node's words: its
    id and the achievements and items its ``accept`` names, split at ``_``); empty when none
    shares one."""
    asked = _words(request)
    scores = {}
    for node in library.nodes:
        words = {w for n in (node.id, *_strings(node.accept)) for w in n.lower().split("_")}
        scores[node.id] = len(asked & words)
    best = max(scores.values(), default=0)
    return [n.id for n in library.nodes if best and scores[n.id] == best]


class LibraryPlanner:
    """Plans requests as goals of a task library (module doc).

    Args:
        client: the model (:func:`phyagentos.llm.make_client`).
        skills: skill names the validator accepts.
        targets: target names the validator accepts (TARGETS.md).
    """

    def __init__(self, client: LLMClient, *, skills: Collection[str], targets: Sequence[str]):
        self.client = client
        self.skills = list(skills)
        self.targets = list(targets)

    def plan(self, request: str, *, library: str | Path, name: str | None = None) -> PlanResult:
        """Plan ``request`` as one goal of the goal graph at ``library`` and what it depends on.

        Raises:
            PlannerError: the model could not be called or answered outside its schema.
            GoalGraphError: ``library`` is not a valid goal graph (file and line).
        """
        check_request(request)
        started = time.perf_counter()
        lib = load_goal_graph(library, skills=self.skills, targets=self.targets)
        context = {"library": str(library), "goals": [n.id for n in lib.nodes]}
        findings = screen_text(request, source="instruction")
        if findings:
            return PlanResult(request=request, status="refused", refusal="unsafe", refused_by="policy",
                              reason="rejected by the tool policy: " + "; ".join(str(f) for f in findings),
                              findings=tuple(findings), context=context, seconds=time.perf_counter() - started)
        candidates = goal_candidates(request, lib)
        context["candidates"] = candidates
        if not candidates:
            return PlanResult(request=request, status="refused", refusal="impossible", refused_by="grounding",
                              reason=(f"no goal of {lib.name} is named by the request; its goals: "
                                      f"{', '.join(n.id for n in lib.nodes)}"),
                              context=context, seconds=time.perf_counter() - started)
        schema = {"type": "object", "properties": {
            "decision": {"enum": ["plan", "refuse"]}, "goal": {"enum": candidates},
            "reason": {"enum": list(REFUSAL_REASONS)}}, "required": ["decision", "goal"]}
        messages = [{"role": "system", "content": LIBRARY_SYSTEM_PROMPT}]
        for user, answer in _EXAMPLES:
            messages += [{"role": "user", "content": user},
                         {"role": "assistant", "content": json.dumps(answer, separators=(",", ":"))}]
        messages.append({"role": "user", "content": f"Goals: {', '.join(candidates)}.\nRequest: {request}"})
        try:
            reply = self.client.complete(messages, schema=schema, max_tokens=40, purpose="plan")
        except LLMError as exc:
            raise PlannerError(f"planning {quote(request)} in {lib.name}: {exc}") from exc
        try:
            data = json.loads(reply.text)
        except json.JSONDecodeError as exc:
            raise PlannerError(f"the model's answer to {quote(request)} is not JSON: {reply.text[:200]!r}") from exc
        if data.get("decision") != "plan" or data.get("goal") not in candidates:
            reason = data.get("reason") if data.get("reason") in REFUSAL_REASONS else "impossible"
            record = call_record(reply.call, role="planner", output=reply.text, outcome="refused",
                                 detail=f"model refusal ({reason})")
            return PlanResult(request=request, status="refused", refusal=reason, refused_by="model",
                              reason=f"the model refused ({reason})", calls=(reply.call,), outputs=(reply.text,),
                              records=(record,), context=context, seconds=time.perf_counter() - started)
        goal = data["goal"]
        record = call_record(reply.call, role="planner", output=reply.text, outcome="accepted", detail=f"goal {goal}")
        keep = nx.ancestors(dagmod.to_digraph(lib), goal) | {goal}
        raw = read_yaml(library, error=GoalGraphError)  # bounded, as every YAML the project reads
        raw["name"] = name or f"{lib.name}_{goal}"
        raw["description"] = f"{request} (goal {goal} of {lib.name} and what it depends on)"
        raw["nodes"] = [n for n in raw["nodes"] if n["id"] in keep]
        raw["provenance"] = {"planner": "Goal Planner (task library)", "request": request, "library": str(library),
                             "goal": goal, "model_calls": [record.model_dump(mode="json")]}
        text = yaml.safe_dump(raw, sort_keys=False, allow_unicode=True, default_flow_style=None, width=100)
        try:
            graph = parse_goal_graph(text, path=f"<plan of {request[:40]!r}>", skills=self.skills,
                                     targets=self.targets)
        except GoalGraphError as exc:
            raise PlannerError(f"the plan for {quote(request)} compiles to an invalid goal graph: {exc}") from exc
        return PlanResult(request=request, status="planned", graph_yaml=text, graph=graph, calls=(reply.call,),
                          outputs=(reply.text,), records=(record,), context=context,
                          reason=f"goal {goal}: {len(graph.nodes)} node(s) of {lib.name}",
                          seconds=time.perf_counter() - started)
