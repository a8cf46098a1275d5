"""ToolRegistry: the Agent's only authority, as typed tools with JSON schemas.

Every tool names its input schema (JSON Schema, ``additionalProperties: false``) and is
called through :meth:`ToolRegistry.call`, which checks the arguments against the
schema, applies the tool policy and returns a JSON-serialisable result or raises
:class:`ToolError`. The in-process Agent and the MCP server (:mod:`phyagentos.app.mcp_server`)
expose the same registry, so an external agent can read the workspace, plan, submit and
signal without touching any target SDK.

Tools: ``read_environment``, ``list_targets``, ``list_skills``, ``list_sessions``,
``read_session``, ``list_runs``, ``read_memory`` (reads); ``plan_request`` and
``submit_goal_graph`` (through the validated path: the same validator and
``Workspace.submit_session`` as ``phyagentos submit``); ``send_signal`` (cancel, pause,
resume, estop, clear_estop); ``query_reach`` (a :class:`~phyagentos.protocol.reach.ReachQuery`
answered by the Runtime's IK, when the composition root wires a reach oracle).

Tool policy: string arguments are screened for injection
(:func:`phyagentos.agent.llm.policy.screen_text`); a hit rejects the call, logged with the
offending text. ``send_signal`` with ``estop`` is always allowed: it is never screened,
never rate-limited and needs no other argument. Submitting needs a ``submit`` callable
from the composition root (the Agent plane does not own the Runtime's skill registry).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from phyagentos.errors import PhyAgentOSError
from phyagentos.protocol import Workspace
from phyagentos.protocol.reach import ReachOracle, ReachQuery
from phyagentos.untrusted import quote

from .llm.policy import screen_text
from .planner import MAX_REQUEST_CHARS
from .skill_catalog import skill_catalog

__all__ = ["Tool", "ToolError", "ToolRegistry"]

logger = logging.getLogger(__name__)

SIGNALS = ("cancel", "pause", "resume", "estop", "clear_estop")
MEMORY_DOCS = {"lessons": "LESSONS", "knowledge": "KNOWLEDGE", "procedures": "SKILL"}


class ToolError(PhyAgentOSError):
    """A tool call was malformed, refused by the tool policy, or failed."""


@dataclass(frozen=True)
class Tool:
    """One tool: ``name``, ``description``, JSON-schema ``input_schema``, its function, and whether the
    injection screen applies (``screened``)."""

    name: str
    description: str
    input_schema: dict[str, Any]
    fn: Callable[..., Any]
    screened: bool = True

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "description": self.description, "input_schema": self.input_schema}


def _name() -> dict[str, Any]:
    return {"type": "string", "maxLength": MAX_NAME_CHARS}


def _obj(props: dict[str, Any] | None = None, required: tuple[str, ...] = ()) -> dict[str, Any]:
    return {"type": "object", "properties": props or {}, "required": list(required), "additionalProperties": False}


#: Longest goal graph accepted as text (characters): the shipped graphs are a few kilobytes.
MAX_GOAL_GRAPH_CHARS = 1024 * 1024
#: Longest identifier argument (session, run, target, object names), characters.
MAX_NAME_CHARS = 128
#: Longest signal reason, characters (as the view's signal buttons).
MAX_REASON_CHARS = 200
#: Deepest nesting of an object or array argument (a scene is four levels deep).
MAX_ARG_DEPTH = 32
#: Most values (strings, numbers, containers) in one call's arguments.
MAX_ARG_NODES = 100_000

_TYPES = {"string": str, "integer": int, "number": (int, float), "boolean": bool, "object": dict, "array": list}


def _check_args(tool: Tool, args: Mapping[str, Any]) -> None:
    schema = tool.input_schema
    props = schema.get("properties", {})
    unknown = set(args) - set(props)
    if unknown:
        raise ToolError(f"{tool.name}: unknown argument(s) {sorted(unknown)}; valid: {sorted(props)}")
    for name in schema.get("required", []):
        if name not in args:
            raise ToolError(f"{tool.name}: missing required argument {name!r}")
        if args[name] is None:
            raise ToolError(f"{tool.name}: required argument {name!r} is null; it must be "
                            f"{props.get(name, {}).get('type', 'given')}")
    _check_shape(tool, args)
    for name, value in args.items():
        spec = props[name]
        py = _TYPES.get(spec.get("type", ""), object)
        wrong_type = value is not None and not isinstance(value, py)
        if wrong_type or (isinstance(value, bool) and spec.get("type") in ("integer", "number")):
            raise ToolError(f"{tool.name}: argument {name!r} must be {spec.get('type')}, got {type(value).__name__}")
        if "enum" in spec and value not in spec["enum"]:
            raise ToolError(f"{tool.name}: argument {name!r} must be one of {spec['enum']}, got {quote(value)}")
        if isinstance(value, str) and "maxLength" in spec and len(value) > spec["maxLength"]:
            raise ToolError(f"{tool.name}: argument {name!r} is {len(value)} characters long, more than the limit "
                            f"of {spec['maxLength']}: {quote(value)}")


def _check_shape(tool: Tool, args: Mapping[str, Any]) -> None:
    """Refuse arguments nested deeper than :data:`MAX_ARG_DEPTH` or holding more than
    :data:`MAX_ARG_NODES` values (walked without recursion), or a non-finite number."""
    stack: list[tuple[Any, int]] = [(v, 1) for v in args.values()]
    nodes = 0
    while stack:
        value, depth = stack.pop()
        nodes += 1
        if nodes > MAX_ARG_NODES:
            raise ToolError(f"{tool.name}: arguments hold more than {MAX_ARG_NODES} values")
        if depth > MAX_ARG_DEPTH:
            raise ToolError(f"{tool.name}: arguments nested deeper than {MAX_ARG_DEPTH} levels")
        if isinstance(value, float) and not math.isfinite(value):
            raise ToolError(f"{tool.name}: a number argument is {value}; numbers must be finite")
        if isinstance(value, Mapping):
            stack.extend((v, depth + 1) for v in value.values())
            stack.extend((k, depth + 1) for k in value.keys())
        elif isinstance(value, (list, tuple)):
            stack.extend((v, depth + 1) for v in value)


def _strings(value: Any) -> list[str]:
    if isinstance(value, str):
        return [value]
    if isinstance(value, Mapping):
        return [s for k, v in value.items() for s in _strings(k) + _strings(v)]
    if isinstance(value, (list, tuple)):
        return [s for v in value for s in _strings(v)]
    return []


class ToolRegistry:
    """The tools over one workspace.

    Args:
        workspace: the protocol workspace.
        submit: ``submit(yaml_text) -> run_id`` validating and registering a goal graph
            (the composition root passes :func:`phyagentos.app.orchestrator.submit_goal_graph`
            wrapped); ``None``: the ``submit_goal_graph`` tool is not offered.
        plan: ``plan(request, scene) -> dict`` (a Goal Planner); ``None``: ``plan_request``
            is not offered.
        issued_by: recorded as the sender of signals.
        reach: the reach oracle (the Runtime's IK through the protocol); ``None``: ``query_reach``
            is not offered.
    """

    def __init__(self, workspace: Workspace, *, submit: Callable[[str], str] | None = None,
                 plan: Callable[[str, dict | None], dict] | None = None, issued_by: str = "agent:tools",
                 reach: ReachOracle | None = None):
        self.workspace = workspace
        self.issued_by = issued_by
        self.rejections: list[dict[str, Any]] = []
        self._tools: dict[str, Tool] = {}
        add = self._add
        add(Tool("read_environment", "What the runtime last perceived (ENVIRONMENT.md): entities with poses, relations.",
                 _obj(), self._read_environment))
        add(Tool("list_targets", "The registered targets (TARGETS.md): kind, capabilities, observations, action space.",
                 _obj(), lambda: self._doc("TARGETS")))
        add(Tool("list_skills", "Skills a goal graph may use, with required (task) and optional (strategy) parameters.",
                 _obj(), self._list_skills))
        add(Tool("list_sessions", "Active sessions (optionally of one run): id, state, node, skill, target.",
                 _obj({"run_id": _name()}), self._list_sessions))
        add(Tool("read_session", "One session's record: state, parameters, attempts, verdicts, evidence.",
                 _obj({"session_id": _name()}, ("session_id",)), self._read_session))
        add(Tool("list_runs", "Active runs (submitted goal graphs not yet finished).", _obj(), self._list_runs))
        add(Tool("read_memory", "Memory documents: verified lessons, knowledge patterns or promoted procedures.",
                 _obj({"kind": {"type": "string", "enum": sorted(MEMORY_DOCS)}}, ("kind",)), self._read_memory))
        add(Tool("send_signal", "Signal the runtime: cancel a session, pause/resume claiming, estop (always "
                                "allowed), clear_estop.",
                 _obj({"kind": {"type": "string", "enum": list(SIGNALS)}, "session_id": _name(),
                       "reason": {"type": "string", "maxLength": MAX_REASON_CHARS}}, ("kind",)), self._send_signal,
                 screened=False))
        if submit is not None:
            self._submit = submit
            add(Tool("submit_goal_graph", "Validate a goal graph (YAML text, docs/goal_graphs.md) and submit it as a "
                                          "run; returns the run id. Invalid graphs are rejected with file:line.",
                     _obj({"goal_graph_yaml": {"type": "string", "maxLength": MAX_GOAL_GRAPH_CHARS}},
                          ("goal_graph_yaml",)), self._submit_graph))
        if plan is not None:
            self._plan = plan
            add(Tool("plan_request", "Plan a natural-language request into a validated goal graph (or a refusal "
                                     "with its reason) on a scene (default: the tabletop scene).",
                     _obj({"request": {"type": "string", "maxLength": MAX_REQUEST_CHARS}, "scene": {"type": "object"}},
                          ("request",)),
                     self._plan_request))
        if reach is not None:
            self._reach = reach
            add(Tool("query_reach", "Can a target's arm reach a pick of an object and/or setting it down on a "
                                    "destination, with objects at the given perceived positions? Answered by the "
                                    "runtime's IK on the target's model: reachable, unreachable or unknown (why).",
                     _obj({"target": _name(), "scene": {"type": "object"},
                           "positions": {"type": "object"}, "pick": _name(),
                           "place": {"type": "array"}}, ("target",)), self._query_reach))

    def _add(self, tool: Tool) -> None:
        self._tools[tool.name] = tool

    # -- registry ------------------------------------------------------------

    def names(self) -> list[str]:
        return list(self._tools)

    def get(self, name: str) -> Tool:
        try:
            return self._tools[name]
        except KeyError:
            raise ToolError(f"unknown tool {name!r}; valid tools: {', '.join(self._tools)}") from None

    def describe(self) -> list[dict[str, Any]]:
        """Name, description and input schema of every tool."""
        return [t.describe() for t in self._tools.values()]

    def call(self, name: str, arguments: Mapping[str, Any] | None = None) -> Any:
        """Call tool ``name`` with ``arguments`` (checked against its schema and the tool policy).

        Raises:
            ToolError: unknown tool, bad arguments, a policy rejection, or the tool failed.
        """
        tool = self.get(name)
        args = dict(arguments or {})
        _check_args(tool, args)
        # an optional argument sent as null (JSON clients do) is an argument not given: its default
        args = {k: v for k, v in args.items() if v is not None}
        if tool.screened:
            findings = [f for text in _strings(args) for f in screen_text(text, source=f"tool {name}")]
            if findings:
                self.rejections.append({"tool": name, "findings": [str(f) for f in findings]})
                raise ToolError(f"{name}: rejected by the tool policy: " + "; ".join(str(f) for f in findings))
        try:
            return tool.fn(**args)
        except ToolError:
            raise
        except PhyAgentOSError as exc:
            raise ToolError(f"{name}: {exc}") from exc

    # -- tools ---------------------------------------------------------------

    def _doc(self, name: str) -> Any:
        return self.workspace.read(name).data.model_dump(mode="json")

    def _read_environment(self) -> Any:
        return self._doc("ENVIRONMENT")

    @staticmethod
    def _list_skills() -> Any:
        return [{"name": s.name, "required": sorted(s.required), "optional": sorted(s.optional)}
                for s in skill_catalog().values()]

    def _list_sessions(self, run_id: str | None = None) -> Any:
        return [{"session_id": sid, "state": state, "run_id": ident.run_id, "node": getattr(ident, "node", None)}
                for sid, state, ident in self.workspace.active_sessions(run_id=run_id)]

    def _read_session(self, session_id: str) -> Any:
        return self.workspace.load_session(session_id).model_dump(mode="json")

    def _list_runs(self) -> Any:
        return [self.workspace.runs.load(r).model_dump(mode="json") for r in self.workspace.runs.active_ids()]

    def _read_memory(self, kind: str) -> Any:
        return self._doc(MEMORY_DOCS[kind])

    def _send_signal(self, kind: str, session_id: str | None = None, reason: str = "") -> Any:
        if kind != "estop":  # e-stop is always allowed: nothing is screened before it goes out
            findings = screen_text(reason, source="tool send_signal") if reason else []
            if findings:
                raise ToolError("send_signal: rejected by the tool policy: " + "; ".join(map(str, findings)))
        sig = self.workspace.send_signal(kind, session_id=session_id, reason=reason, issued_by=self.issued_by)
        return sig.model_dump(mode="json")

    def _submit_graph(self, goal_graph_yaml: str) -> Any:
        return {"run_id": self._submit(goal_graph_yaml)}

    def _plan_request(self, request: str, scene: dict | None = None) -> Any:
        return self._plan(request, scene)

    def _query_reach(self, target: str, scene: dict | None = None, positions: dict | None = None,
                     pick: str | None = None, place: list | None = None) -> Any:
        spec = next((t for t in self.workspace.read("TARGETS").data.targets if t.name == target), None)
        if spec is None:
            names = [t.name for t in self.workspace.read("TARGETS").data.targets]
            raise ToolError(f"query_reach: unknown target {target!r}; valid targets: {', '.join(names)}")
        try:
            query = ReachQuery(target=target, driver=spec.driver, scene=scene or {}, positions=positions or {},
                               pick=pick, place=place)
        except ValueError as exc:
            raise ToolError(f"query_reach: {exc}") from exc
        return self._reach(query).model_dump(mode="json")
