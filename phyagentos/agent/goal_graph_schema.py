"""The goal-graph schema as pydantic models: what a goal graph may say, and every message.

:class:`GoalGraphSpec` (the file), :class:`DefaultsSpec` (``defaults``) and
:class:`GoalNodeSpec` (one entry of ``nodes``) validate plain data: unknown keys (with a
did-you-mean and the valid keys), missing keys, node ids, skills and targets (with the
valid choices), params, limits, accept, depends_on, scene, provenance, schedule and
version. ``GoalGraphSpec.model_json_schema()`` exports the schema.

The skills and targets a graph may name come through the validation context::

    GoalGraphSpec.model_validate(data, context={"skills": [...], "targets": [...]})

(without them any name is accepted). Reading YAML, file lines and duplicate keys belong
to :mod:`phyagentos.agent.goal_graph_source`, which maps each error back to its file and
line; dependency cycles to :mod:`phyagentos.agent.goal_graph`.

Every error is a ``goal_graph`` error whose context holds the message ``template`` and
its values, and where the problem sits below the error's ``loc``: ``at`` (a path inside
the value), ``on_key`` (the problem is the key of that path, not its value), ``got`` (a
description of the offending value, of the key when ``got_key``) and ``first_at`` (the
path of an earlier definition, relative to ``loc``). A reader that knows where the data
came from re-renders the template with what it knows better (the YAML text of a scalar,
a line instead of a path).
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    ValidatorFunctionWrapHandler,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from phyagentos.errors import format_choices
from phyagentos.yamlsource import clip, excerpt

__all__ = [
    "SCHEMA_VERSION",
    "NODE_ID_PATTERN",
    "TOP_LEVEL_KEYS",
    "SCHEDULES",
    "REQUIRED_TOP_LEVEL_KEYS",
    "NODE_KEYS",
    "REQUIRED_NODE_KEYS",
    "DEFAULTS_KEYS",
    "ERROR_TYPE",
    "GraphContext",
    "DefaultsSpec",
    "GoalNodeSpec",
    "GoalGraphSpec",
    "describe",
    "render",
    "unknown_key",
]

#: The only goal-graph schema version this module reads.
SCHEMA_VERSION = 1
#: Node ids: lower-case identifiers, so they are safe as file names, Mermaid and session ids.
NODE_ID_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")

TOP_LEVEL_KEYS: tuple[str, ...] = ("version", "name", "description", "defaults", "scene", "nodes", "provenance",
                                   "schedule")
#: ``schedule`` values: ``eager`` submits every ready node at once (the default: nodes on
#: different targets run in parallel); ``file_order`` submits one ready node at a time,
#: the first in file order, when nothing of the run is in flight (one target working
#: through a long graph: a node that became ready early does not run before an earlier
#: node of the file that became ready later).
SCHEDULES: tuple[str, ...] = ("eager", "file_order")
REQUIRED_TOP_LEVEL_KEYS: tuple[str, ...] = ("version", "name", "nodes")
NODE_KEYS: tuple[str, ...] = ("id", "skill", "target", "params", "accept", "depends_on", "limits", "runtime")
# ``target`` and ``skill`` are required but may come from ``defaults``.
REQUIRED_NODE_KEYS: tuple[str, ...] = ("id", "skill", "target", "accept")
DEFAULTS_KEYS: tuple[str, ...] = ("skill", "target", "params", "limits", "runtime")

#: The pydantic error type of every schema problem.
ERROR_TYPE = "goal_graph"

_ACCEPT_HELP = (
    "expected a mapping of predicate name -> arguments "
    "(e.g. {holding: cube}) or a list of single-key mappings (e.g. [{holding: cube}])"
)
_PLACEHOLDER = re.compile(r"\{(\w+)\}")


# --------------------------------------------------------------------------- messages


def describe(value: Any) -> str:
    """How a message names a value: ``a mapping``, ``a list``, ``nothing (null)``, ``the scalar '…'``."""
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    if value is None:
        return "nothing (null)"
    return f"the scalar {excerpt(value if isinstance(value, str) else str(value))}"


def render(template: str, values: Mapping[str, Any]) -> str:
    """``template`` with each ``{name}`` of ``values`` filled in (one pass: filled-in text is never re-read)."""
    return _PLACEHOLDER.sub(lambda m: str(values[m.group(1)]) if m.group(1) in values else m.group(0), template)


def _problem(template: str, *, at: tuple[Any, ...] = (), on_key: bool = False, got_key: bool = False,
             **values: Any) -> PydanticCustomError:
    """A schema error; a ``got`` value is described (:func:`describe`)."""
    if "got" in values:
        values["got"] = describe(values["got"])
    ctx = {**values, "template": template, "at": at, "on_key": on_key, "got_key": got_key}
    return PydanticCustomError(ERROR_TYPE, render(template, ctx), ctx)


def _did_you_mean(word: object, choices: Iterable[str]) -> str:
    if not isinstance(word, str):
        return ""
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _choices(kind: str, choices: Collection[str]) -> str:
    return f"valid {kind}: {format_choices(choices)}" if choices else f"no {kind} are available"


def unknown_key(key: str, what: str, allowed: tuple[str, ...]) -> PydanticCustomError:
    """The error for ``key`` in ``what`` (a mapping whose valid keys are ``allowed``)."""
    return _problem("unknown key {key} in {what}{hint}; valid keys: {keys}", on_key=True, key=excerpt(key),
                    what=what, hint=_did_you_mean(key[:200], allowed), keys=format_choices(allowed))


def _details(error: Mapping[str, Any]) -> InitErrorDetails:
    """A reported error as input for a new :class:`ValidationError` (a validator re-raising it)."""
    ctx = error.get("ctx") or {}
    if error["type"] == ERROR_TYPE:
        return InitErrorDetails(type=PydanticCustomError(ERROR_TYPE, ctx["template"], ctx), loc=error["loc"],
                                input=error.get("input"))
    details = InitErrorDetails(type=error["type"], loc=error["loc"], input=error.get("input"))
    if ctx:
        details["ctx"] = ctx
    return details


def _check_keys(data: dict, errors: list[Any], *, what: str, allowed: tuple[str, ...],
                required: tuple[str, ...]) -> list[Any]:
    """This level's key problems: each unknown key (pydantic's ``extra_forbidden``) with a
    did-you-mean, then missing keys, reported only when no key was unknown (an unknown key
    is usually the misspelt required one, and that message is the more useful)."""
    out: list[Any] = []
    unknown = False
    for error in errors:
        if error["type"] == "missing" and len(error["loc"]) == 1:
            continue  # reported below, all at once
        if error["type"] == "extra_forbidden" and len(error["loc"]) == 1:
            unknown = True
            out.append(InitErrorDetails(type=unknown_key(str(error["loc"][0]), what, allowed),
                                        loc=error["loc"], input=error.get("input")))
        else:
            out.append(_details(error))
    missing = [k for k in required if k not in data]
    if missing and not unknown:
        out.append(InitErrorDetails(type=_problem(
            "{what} is missing required key(s) {missing}; required keys: {required}", what=what,
            missing=format_choices(missing), required=format_choices(required)), loc=(), input=data))
    return out


def _validate_level(cls: type[BaseModel], data: Any, handler: ValidatorFunctionWrapHandler, *, what: str,
                    allowed: tuple[str, ...], required: tuple[str, ...],
                    more: Iterable[InitErrorDetails] = ()) -> Any:
    """Validate one mapping of the schema (graph, defaults or node), then add this level's key
    problems and ``more``; raise them all together."""
    try:
        result, errors = handler(data), []
    except ValidationError as exc:
        result, errors = None, exc.errors()
    details = _check_keys(data, list(errors), what=what, allowed=allowed, required=required) + list(more)
    if details:
        raise ValidationError.from_exception_data(cls.__name__, details)
    return result


# --------------------------------------------------------------------------- context


@dataclass(frozen=True)
class GraphContext:
    """What validating one graph needs beyond its own data (the pydantic validation context).

    ``skills``/``targets``: the names a node may use (``None``: any). ``known_ids``: every
    string id the graph's nodes give (``None``: dependencies are not checked against them).
    ``defaults_keys``: the keys its ``defaults`` give validly; ``defaults_ok``: whether
    ``defaults`` is valid (a node need not repeat a key a broken ``defaults`` may be meant
    to give, so no "missing target" is piled on the defaults' own error).
    """

    skills: frozenset[str] | None = None
    targets: frozenset[str] | None = None
    known_ids: tuple[str, ...] | None = None
    defaults_keys: frozenset[str] = frozenset()
    defaults_ok: bool = True

    @classmethod
    def of(cls, context: Any) -> GraphContext:
        """The context as given (a ``GraphContext``, a mapping with ``skills``/``targets``, or ``None``)."""
        if isinstance(context, GraphContext):
            return context
        context = context if isinstance(context, Mapping) else {}
        skills, targets = context.get("skills"), context.get("targets")
        return cls(skills=frozenset(skills) if skills is not None else None,
                   targets=frozenset(targets) if targets is not None else None)

    def for_graph(self, data: Any) -> GraphContext:
        """This context completed with what ``data`` (a whole graph, unvalidated) says about itself."""
        data = data if isinstance(data, Mapping) else {}
        nodes = data.get("nodes")
        known = tuple(n["id"] for n in nodes if isinstance(n, Mapping) and isinstance(n.get("id"), str)) \
            if isinstance(nodes, list) else ()
        keys: frozenset[str] = frozenset()
        ok = True
        if data.get("defaults") is not None:
            try:
                defaults = DefaultsSpec.model_validate(data["defaults"], context=self)
                keys = frozenset(k for k in DEFAULTS_KEYS if getattr(defaults, k) is not None)
            except ValidationError:
                ok = False
        return GraphContext(skills=self.skills, targets=self.targets, known_ids=known, defaults_keys=keys,
                            defaults_ok=ok)


def _context(info: ValidationInfo) -> GraphContext:
    return GraphContext.of(info.context)


# --------------------------------------------------------------------------- field checks
# Shared by ``defaults`` and nodes; ``prefix`` says which ("defaults: ", "node 'a': ").


def _prefix(cls: type, info: ValidationInfo) -> str:
    if cls is DefaultsSpec:
        return "defaults: "
    node_id = info.data.get("id")
    return f"node {node_id!r}: " if node_id else ""


def _choice(value: Any, what: str, kind: str, valid: frozenset[str] | None, prefix: str) -> str:
    shown = f"; {_choices(kind, valid)}" if valid is not None else ""  # None: any name (no context)
    if not isinstance(value, str):
        raise _problem("{prefix}{what} must be a string, got {got}{valid}", prefix=prefix, what=what, got=value,
                       valid=shown)
    if valid is not None and value not in valid:
        raise _problem("{prefix}unknown {what} {value}{hint}{valid}", prefix=prefix, what=what,
                       value=excerpt(value), hint=_did_you_mean(value[:200], valid), valid=shown)
    return value


def _runtime(value: Any, prefix: str) -> str:
    if not isinstance(value, str) or not value:
        raise _problem("{prefix}runtime must be a SkillRuntime name (e.g. builtin, policy), got {got}",
                       prefix=prefix, got=value)
    return value


def _params(value: Any, prefix: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _problem("{prefix}params must be a mapping of parameter name -> value, got {got}", prefix=prefix,
                       got=value)
    for key in value:
        if not isinstance(key, str):
            raise _problem("{prefix}params keys must be strings, got {got}", at=(key,), on_key=True, got_key=True,
                           prefix=prefix, got=key)
    return value


def _limits(value: Any, prefix: str) -> dict[str, int | float]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _problem("{prefix}limits must be a mapping of limit name -> number "
                       "(e.g. {execution_timeout_s: 120}), got {got}", prefix=prefix, got=value)
    for key, number in value.items():
        if not isinstance(key, str):
            raise _problem("{prefix}limits keys must be strings, got {got}", at=(key,), on_key=True, got_key=True,
                           prefix=prefix, got=key)
        if isinstance(number, bool) or not isinstance(number, (int, float)) or number < 0:
            raise _problem("{prefix}limit {name} must be a non-negative number, got {got}", at=(key,),
                           prefix=prefix, name=repr(key), got=number)
    return value


def _predicate(key: Any) -> bool:
    return isinstance(key, str) and bool(key)


def _accept(value: Any, prefix: str) -> dict[str, Any] | list[dict[str, Any]]:
    if isinstance(value, dict):
        for key in value:
            if not _predicate(key):
                raise _problem("{prefix}accept predicate names must be strings, got {got}; {help}", at=(key,),
                               on_key=True, got_key=True, prefix=prefix, got=key, help=_ACCEPT_HELP)
        return value
    if isinstance(value, list):
        for i, item in enumerate(value):
            if not (isinstance(item, dict) and len(item) == 1 and _predicate(next(iter(item)))):
                raise _problem("{prefix}accept list items must be single-key mappings, got {got}; {help}", at=(i,),
                               prefix=prefix, got=item, help=_ACCEPT_HELP)
        return value
    raise _problem("{prefix}accept has the wrong type: {help}; got {got}", prefix=prefix, help=_ACCEPT_HELP, got=value)


def _depends_on(value: Any, node_id: str | None, known_ids: tuple[str, ...] | None, prefix: str) -> tuple[str, ...]:
    if value is None:
        return ()
    others = [i for i in dict.fromkeys(known_ids or ()) if i != node_id]
    valid = f"valid node ids: {format_choices(others)}" if others else "the graph has no other nodes"
    if not isinstance(value, list):
        raise _problem("{prefix}depends_on must be a list of node ids (e.g. [pick_cube]), got {got}; {valid}",
                       prefix=prefix, got=value, valid=valid)
    first: dict[str, int] = {}
    for i, dep in enumerate(value):
        if not isinstance(dep, str):
            raise _problem("{prefix}depends_on entries must be node ids, got {got}; {valid}", at=(i,),
                           prefix=prefix, got=dep, valid=valid)
        if dep == node_id:
            raise _problem("{prefix}depends on itself; remove {dep} from its depends_on; {valid}", at=(i,),
                           prefix=prefix, dep=repr(dep), valid=valid)
        if known_ids is not None and dep not in known_ids:
            raise _problem("{prefix}depends on unknown node {dep}{hint}; {valid}", at=(i,), prefix=prefix,
                           dep=repr(dep), hint=_did_you_mean(dep, others), valid=valid)
        if dep in first:
            raise _problem("{prefix}depends_on lists {dep} twice (first at {first})", at=(i,),
                           first_at=(first[dep],), prefix=prefix, dep=repr(dep), first=f"depends_on[{first[dep]}]")
        first[dep] = i
    return tuple(value)


class _Choices(BaseModel):
    """The fields ``defaults`` and nodes share, with their checks."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @field_validator("skill", mode="before", check_fields=False)
    @classmethod
    def _skill(cls, value: Any, info: ValidationInfo) -> str:
        return _choice(value, "skill", "skills", _context(info).skills, _prefix(cls, info))

    @field_validator("target", mode="before", check_fields=False)
    @classmethod
    def _target(cls, value: Any, info: ValidationInfo) -> str:
        return _choice(value, "target", "targets", _context(info).targets, _prefix(cls, info))

    @field_validator("runtime", mode="before", check_fields=False)
    @classmethod
    def _runtime(cls, value: Any, info: ValidationInfo) -> str:
        return _runtime(value, _prefix(cls, info))

    @field_validator("params", mode="before", check_fields=False)
    @classmethod
    def _params(cls, value: Any, info: ValidationInfo) -> dict[str, Any]:
        return _params(value, _prefix(cls, info))

    @field_validator("limits", mode="before", check_fields=False)
    @classmethod
    def _limits(cls, value: Any, info: ValidationInfo) -> dict[str, int | float]:
        return _limits(value, _prefix(cls, info))


# --------------------------------------------------------------------------- models


class DefaultsSpec(_Choices):
    """``defaults``: a skill, target, params, limits or runtime every node starts from."""

    skill: str | None = None
    target: str | None = None
    params: dict[str, Any] | None = None
    limits: dict[str, int | float] | None = None
    runtime: str | None = None

    @model_validator(mode="wrap")
    @classmethod
    def _validate(cls, data: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        if isinstance(data, DefaultsSpec):
            return data
        if not isinstance(data, dict):
            raise _problem("defaults must be a mapping with keys from {keys}, got {got}",
                           keys=format_choices(DEFAULTS_KEYS), got=data)
        return _validate_level(cls, data, handler, what="defaults", allowed=DEFAULTS_KEYS, required=())


class GoalNodeSpec(_Choices):
    """One entry of ``nodes``: run ``skill`` on ``target`` and judge it by ``accept``.

    ``skill``, ``target``, ``params``, ``limits`` and ``runtime`` are as written: the
    graph's ``defaults`` are not applied here (``None``: not given).
    """

    id: str = Field(description=f"node id, matching {NODE_ID_PATTERN.pattern}")
    skill: str | None = None
    target: str | None = None
    params: dict[str, Any] = Field(default_factory=dict)
    accept: dict[str, Any] | list[dict[str, Any]] = Field(
        description="predicate name -> arguments, or a list of single-key mappings")
    depends_on: tuple[str, ...] = ()
    limits: dict[str, int | float] = Field(default_factory=dict)
    runtime: str | None = None

    @model_validator(mode="wrap")
    @classmethod
    def _validate(cls, data: Any, handler: ValidatorFunctionWrapHandler, info: ValidationInfo) -> Any:
        if isinstance(data, GoalNodeSpec):
            return data
        if not isinstance(data, dict):
            raise _problem("each entry of nodes must be a mapping with keys {keys}, got {got}",
                           keys=format_choices(NODE_KEYS), got=data)
        context = _context(info)
        required = tuple(k for k in REQUIRED_NODE_KEYS
                         if not (k in context.defaults_keys or (k in DEFAULTS_KEYS and not context.defaults_ok)))
        return _validate_level(cls, data, handler, what="node", allowed=NODE_KEYS, required=required)

    @field_validator("id", mode="before")
    @classmethod
    def _id(cls, value: Any) -> str:
        if isinstance(value, str) and NODE_ID_PATTERN.fullmatch(value):
            return value
        rule = (f": ids must match {NODE_ID_PATTERN.pattern} (lower-case letter, then lower-case letters, digits "
                f"or '_'), e.g. 'pick_cube'")
        if isinstance(value, str):
            raise _problem("invalid node id {shown}" + rule, shown=excerpt(value))
        raise _problem("invalid node id {got}" + rule, got=value)

    @field_validator("accept", mode="before")
    @classmethod
    def _accept(cls, value: Any, info: ValidationInfo) -> dict[str, Any] | list[dict[str, Any]]:
        return _accept(value, _prefix(cls, info))

    @field_validator("depends_on", mode="before")
    @classmethod
    def _depends_on(cls, value: Any, info: ValidationInfo) -> tuple[str, ...]:
        return _depends_on(value, info.data.get("id"), _context(info).known_ids, _prefix(cls, info))


class GoalGraphSpec(BaseModel):
    """A goal graph file: ``version``, ``name`` and ``nodes``, and optionally ``description``,
    ``defaults``, ``scene`` (passed through for the target), ``provenance`` and ``schedule``.

    Dependencies are checked to name nodes of the graph; cycles are not (see
    :func:`phyagentos.agent.dag.find_dependency_cycle`).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    version: Literal[1] = Field(description="schema version; must be 1")
    name: str
    description: str = ""
    defaults: DefaultsSpec = Field(default_factory=DefaultsSpec)
    scene: dict[Any, Any] | None = Field(default=None, description="the initial scene, for the target to read")
    nodes: tuple[GoalNodeSpec, ...]
    provenance: dict[Any, Any] | None = Field(default=None, description="request and model_calls of a planner")
    schedule: Literal["eager", "file_order"] = "eager"

    @model_validator(mode="wrap")
    @classmethod
    def _validate(cls, data: Any, handler: ValidatorFunctionWrapHandler, info: ValidationInfo) -> Any:
        if isinstance(data, GoalGraphSpec):
            return data
        expected = f"expected a mapping with keys {format_choices(TOP_LEVEL_KEYS)}"
        if data is None:
            raise _problem("goal graph is empty; {expected}", expected=expected)
        if not isinstance(data, dict):
            raise _problem("top level must be a mapping, got {got}; {expected}", got=data, expected=expected)
        if not isinstance(info.context, GraphContext) or info.context.known_ids is None:
            return cls.model_validate(data, context=GraphContext.of(info.context).for_graph(data))
        return _validate_level(cls, data, handler, what="goal graph", allowed=TOP_LEVEL_KEYS,
                               required=REQUIRED_TOP_LEVEL_KEYS,
                               more=_duplicate_ids(data.get("nodes")))

    @field_validator("version", mode="before")
    @classmethod
    def _version(cls, value: Any) -> int:
        if isinstance(value, bool) or value != SCHEMA_VERSION:
            raise _problem("unsupported version {value}; valid versions: {valid}", value=repr(value),
                           valid=SCHEMA_VERSION)
        return SCHEMA_VERSION

    @field_validator("name", "description", mode="before")
    @classmethod
    def _text(cls, value: Any, info: ValidationInfo) -> str:
        if info.field_name == "description" and value is None:
            return ""
        if not isinstance(value, str) or not value.strip():
            raise _problem("{what} must be a non-empty string, got {got}", what=info.field_name, got=value)
        return value

    @field_validator("defaults", mode="before")
    @classmethod
    def _defaults(cls, value: Any) -> Any:
        return {} if value is None else value

    @field_validator("scene", mode="before")
    @classmethod
    def _scene(cls, value: Any) -> dict[Any, Any] | None:
        if value is not None and not isinstance(value, dict):
            raise _problem("scene must be a mapping (keys such as 'objects', 'regions', 'obstacles'), got {got}",
                           got=value)
        return value

    @field_validator("nodes", mode="before")
    @classmethod
    def _nodes(cls, value: Any) -> Any:
        if not isinstance(value, list):
            raise _problem("nodes must be a non-empty list of node mappings, got {got}", on_key=value is None,
                           got=value)
        if not value:
            raise _problem("nodes is empty; a goal graph needs at least one node (keys: {keys})", on_key=True,
                           keys=format_choices(NODE_KEYS))
        return value

    @field_validator("provenance", mode="before")
    @classmethod
    def _provenance(cls, value: Any) -> dict[Any, Any] | None:
        from phyagentos.protocol import ModelCallRecord  # noqa: PLC0415

        if value is None:
            return None
        if not isinstance(value, dict):
            raise _problem("provenance must be a mapping (keys such as 'request', 'model_calls'), got {got}",
                           got=value)
        calls = value.get("model_calls", [])
        if not isinstance(calls, list):
            raise _problem("provenance.model_calls must be a list of model call records")
        for i, call in enumerate(calls):
            try:
                ModelCallRecord.model_validate(call)
            except ValueError as exc:
                raise _problem("provenance.model_calls[{i}] is not a model call record: {detail}", i=i,
                               detail=clip(str(exc))) from exc
        return value

    @field_validator("schedule", mode="before")
    @classmethod
    def _schedule(cls, value: Any) -> str:
        if not isinstance(value, str) or value not in SCHEDULES:
            raise _problem("unknown schedule {value}; valid schedules: {valid}", value=repr(value),
                           valid=format_choices(SCHEDULES))
        return value


def _duplicate_ids(nodes: Any) -> list[InitErrorDetails]:
    """A node id given again (each valid id's first node is where it is defined)."""
    if not isinstance(nodes, list):
        return []
    first: dict[str, int] = {}
    out = []
    for i, node in enumerate(nodes):
        node_id = node.get("id") if isinstance(node, dict) else None
        if not (isinstance(node_id, str) and NODE_ID_PATTERN.fullmatch(node_id)):
            continue
        if node_id in first:
            out.append(InitErrorDetails(type=_problem(
                "duplicate node id {id} (first defined at {first}); node ids must be unique", at=(i, "id"),
                first_at=(first[node_id],), id=repr(node_id), first=f"nodes[{first[node_id]}]"),
                loc=("nodes",), input=nodes))
        else:
            first[node_id] = i
    return out
