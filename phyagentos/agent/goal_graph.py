"""Goal graphs: YAML files describing a DAG of skill invocations with acceptance criteria.

A goal graph names, per node, which skill to run on which target with which
parameters, how success is judged (``accept``) and which nodes must succeed first
(``depends_on``). The schema is documented for users in ``docs/goal_graphs.md``.

Parsing is strict: unknown keys, unknown skills or targets, bad ids, dangling or
circular dependencies are all :class:`~phyagentos.errors.GoalGraphError` with the file,
the 1-based line of the offending key and the valid choices. The YAML is composed into
a node tree (``yaml.compose``) rather than loaded, so every value keeps its line.

Validation collects every per-key problem and raises the one that comes first in the
file, so fixing errors top to bottom works. Cycles are checked last, once each node is
valid on its own.
"""

from __future__ import annotations

import copy
import difflib
import logging
import re
from collections.abc import Collection, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from phyagentos.agent.dag import find_dependency_cycle, to_digraph
from phyagentos.errors import GoalGraphError, format_choices
from phyagentos.yamlsource import MAX_YAML_CHARS, check_bounds, clip, excerpt

__all__ = [
    "SCHEMA_VERSION",
    "NODE_ID_PATTERN",
    "TOP_LEVEL_KEYS",
    "SCHEDULES",
    "REQUIRED_TOP_LEVEL_KEYS",
    "NODE_KEYS",
    "REQUIRED_NODE_KEYS",
    "DEFAULTS_KEYS",
    "GoalNode",
    "GoalGraph",
    "load_goal_graph",
    "parse_goal_graph",
]

logger = logging.getLogger(__name__)

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

_STR_TAG = "tag:yaml.org,2002:str"
_NULL_TAG = "tag:yaml.org,2002:null"
_ACCEPT_HELP = (
    "expected a mapping of predicate name -> arguments "
    "(e.g. {holding: cube}) or a list of single-key mappings (e.g. [{holding: cube}])"
)


@dataclass(frozen=True)
class GoalNode:
    """One node of a goal graph: run ``skill`` on ``target`` and judge it by ``accept``.

    ``params`` and ``limits`` already include the graph's ``defaults``. ``accept`` is kept
    as written (a mapping, or a list of single-key mappings when a predicate repeats);
    predicate semantics belong to the acceptance-predicate module. ``line`` is the 1-based
    line where the node starts in its file (0 for nodes built in code). Treat the dict
    fields as read-only.
    """

    id: str
    skill: str
    target: str
    params: dict[str, Any] = field(default_factory=dict)
    accept: dict[str, Any] | list[dict[str, Any]] = field(default_factory=dict)
    depends_on: tuple[str, ...] = ()
    limits: dict[str, float] = field(default_factory=dict)
    line: int = 0
    runtime: str = "builtin"  # SkillRuntime (SKILLRUNTIME.md name) the session runs on


@dataclass(frozen=True)
class GoalGraph:
    """A validated, acyclic goal graph; ``nodes`` are in file order.

    ``scene`` is the optional initial scene for the target (objects, regions,
    obstacles), passed through unvalidated for the target to interpret.
    """

    name: str
    description: str
    path: Path | None
    scene: dict[str, Any] | None
    nodes: tuple[GoalNode, ...]
    #: Where the graph came from when a program wrote it (the Goal Planner: ``request``,
    #: ``model_calls`` as ModelCallRecord mappings, which its root sessions' contexts keep).
    provenance: dict[str, Any] | None = None
    #: How ready nodes are submitted (:data:`SCHEDULES`).
    schedule: str = "eager"

    @property
    def node_ids(self) -> tuple[str, ...]:
        """Node ids in file order."""
        return tuple(n.id for n in self.nodes)

    def get_node(self, node_id: str) -> GoalNode:
        """Return the node called ``node_id``; ``KeyError`` listing valid ids otherwise."""
        for node in self.nodes:
            if node.id == node_id:
                return node
        raise KeyError(f"no node {node_id!r} in goal graph {self.name!r}; valid node ids: "
                       f"{format_choices(self.node_ids)}")


def load_goal_graph(
    path: str | Path, *, skills: Collection[str], targets: Collection[str]
) -> GoalGraph:
    """Read and validate the goal graph at ``path``.

    ``skills`` and ``targets`` are the names the runtime offers; a node naming anything
    else is rejected. Raises :class:`GoalGraphError` (with ``path`` and ``line``) for an
    unreadable file or any schema violation.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise GoalGraphError(f"cannot read goal graph: {exc}", path=path) from exc
    return parse_goal_graph(text, path=path, skills=skills, targets=targets)


def parse_goal_graph(
    text: str,
    *,
    path: str | Path | None = None,
    skills: Collection[str],
    targets: Collection[str],
) -> GoalGraph:
    """Validate goal-graph YAML ``text``; ``path`` is only used in messages and the result.

    See :func:`load_goal_graph`.
    """
    graph = _Parser(path=path, skills=skills, targets=targets).parse(text)
    logger.debug("loaded goal graph %r (%d nodes) from %s", graph.name, len(graph.nodes),
                 path or "<text>")
    return graph


# --------------------------------------------------------------------------- internals


class _Invalid(Exception):
    """One validation problem at a YAML node; collected, not raised to callers."""

    def __init__(self, node: yaml.Node | None, message: str):
        super().__init__(message)
        mark = node.start_mark if node is not None else None
        self.line = mark.line + 1 if mark is not None else 1
        self.column = mark.column if mark is not None else 0
        self.message = message


def _did_you_mean(word: object, choices: Iterable[str]) -> str:
    if not isinstance(word, str):
        return ""
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _choices(kind: str, choices: Collection[str]) -> str:
    return f"valid {kind}: {format_choices(choices)}" if choices else f"no {kind} are available"


def _kind(node: yaml.Node) -> str:
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    if node.tag == _NULL_TAG:
        return "nothing (null)"
    return f"the scalar {excerpt(node.value)}"


def _is_null(node: yaml.Node) -> bool:
    return isinstance(node, yaml.ScalarNode) and node.tag == _NULL_TAG


def _str_scalar(node: yaml.Node) -> str | None:
    """Return the text of a plain string scalar, else ``None`` (numbers, null, containers)."""
    if isinstance(node, yaml.ScalarNode) and node.tag == _STR_TAG:
        return node.value
    return None


def _predicate_name(node: yaml.Node) -> None:
    """YAML 1.1 reads a plain ``on`` as the boolean true; as an accept key it can only be
    the predicate ``on`` (``accept: {on: {object: a, support: b}}``), so it is kept as
    the string the user wrote."""
    if isinstance(node, yaml.ScalarNode) and node.style is None and node.value in ("on", "On", "ON"):
        node.tag = _STR_TAG


class _Parser:
    """Single-use validator: turns one YAML text into a :class:`GoalGraph` or raises."""

    def __init__(self, *, path: str | Path | None, skills: Collection[str],
                 targets: Collection[str]):
        self.path = path
        self.skills = frozenset(skills)
        self.targets = frozenset(targets)
        self.problems: list[_Invalid] = []
        self._constructor = yaml.constructor.SafeConstructor()

    # -- plumbing

    def _error(self, message: str, line: int | None) -> GoalGraphError:
        return GoalGraphError(message, path=self.path, line=line)

    def _check(self, func, *args):
        """Run a validation step, recording (not raising) its problem; ``None`` on failure."""
        try:
            return func(*args)
        except _Invalid as problem:
            self.problems.append(problem)
            return None

    def _value(self, node: yaml.Node) -> Any:
        """Construct plain Python data from ``node`` after rejecting duplicate keys inside it."""
        self._reject_duplicate_keys(node, set())
        try:
            # Deep copy: YAML aliases would otherwise share one object between nodes.
            return copy.deepcopy(self._constructor.construct_object(node, deep=True))
        except yaml.MarkedYAMLError as exc:
            problem = _Invalid(node, f"cannot read value: {exc.problem or exc}")
            if exc.problem_mark is not None:
                problem.line, problem.column = exc.problem_mark.line + 1, exc.problem_mark.column
            raise problem from exc

    def _reject_duplicate_keys(self, node: yaml.Node, seen: set[int]) -> None:
        if id(node) in seen:  # recursive alias; the constructor handles it
            return
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[tuple[str, str], yaml.Node] = {}
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    ident = (key.tag, key.value)
                    if ident in first:
                        raise _Invalid(key, f"duplicate key {key.value!r} (first defined at "
                                            f"line {first[ident].start_mark.line + 1})")
                    first[ident] = key
                self._reject_duplicate_keys(value, seen)
        elif isinstance(node, yaml.SequenceNode):
            for item in node.value:
                self._reject_duplicate_keys(item, seen)

    def _entries(self, node: yaml.MappingNode, *, what: str, allowed: tuple[str, ...],
                 required: tuple[str, ...]) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        """Return key -> (key node, value node) for a schema mapping, recording key problems.

        Missing keys are only reported when no key was unknown: an unknown key is
        usually the misspelt required one, and that message is the more useful.
        """
        entries: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        unknown = False
        for key_node, value_node in node.value:
            key = _str_scalar(key_node)
            if key is None or key not in allowed:
                unknown = True
                shown = key if key is not None else getattr(key_node, "value", "?")
                self.problems.append(_Invalid(
                    key_node,
                    f"unknown key {excerpt(shown)} in {what}{_did_you_mean(str(shown)[:200], allowed)}; "
                    f"valid keys: {format_choices(allowed)}"))
            elif key in entries:
                self.problems.append(_Invalid(
                    key_node, f"duplicate key {key!r} in {what} (first defined at line "
                              f"{entries[key][0].start_mark.line + 1})"))
            else:
                entries[key] = (key_node, value_node)
        missing = [k for k in required if k not in entries]
        if missing and not unknown:
            self.problems.append(_Invalid(
                node, f"{what} is missing required key(s) {format_choices(missing)}; "
                      f"required keys: {format_choices(required)}"))
        return entries

    # -- leaf validators (raise _Invalid)

    def _string(self, node: yaml.Node, what: str) -> str:
        text = _str_scalar(node)
        if text is None or not text.strip():
            raise _Invalid(node, f"{what} must be a non-empty string, got {_kind(node)}")
        return text

    def _node_id(self, node: yaml.Node) -> str:
        text = _str_scalar(node)
        if text is None or not NODE_ID_PATTERN.fullmatch(text):
            shown = excerpt(text) if text is not None else _kind(node)
            raise _Invalid(node, f"invalid node id {shown}: ids must match "
                                 f"{NODE_ID_PATTERN.pattern} (lower-case letter, then "
                                 f"lower-case letters, digits or '_'), e.g. 'pick_cube'")
        return text

    def _choice(self, node: yaml.Node, what: str, kind: str, valid: frozenset[str],
                context: str) -> str:
        text = _str_scalar(node)
        if text is None:
            raise _Invalid(node, f"{context}{what} must be a string, got {_kind(node)}; "
                                 f"{_choices(kind, valid)}")
        if text not in valid:
            raise _Invalid(node, f"{context}unknown {what} {excerpt(text)}{_did_you_mean(text[:200], valid)}; "
                                 f"{_choices(kind, valid)}")
        return text

    def _skill(self, node: yaml.Node, context: str = "") -> str:
        return self._choice(node, "skill", "skills", self.skills, context)

    def _target(self, node: yaml.Node, context: str = "") -> str:
        return self._choice(node, "target", "targets", self.targets, context)

    def _runtime(self, node: yaml.Node, context: str = "") -> str:
        value = _str_scalar(node)
        if not value:
            raise _Invalid(node, f"{context}runtime must be a SkillRuntime name (e.g. builtin, policy), got {_kind(node)}")
        return value

    def _params(self, node: yaml.Node, context: str = "") -> dict[str, Any]:
        if _is_null(node):
            return {}
        if not isinstance(node, yaml.MappingNode):
            raise _Invalid(node, f"{context}params must be a mapping of parameter name -> "
                                 f"value, got {_kind(node)}")
        for key, _ in node.value:
            if _str_scalar(key) is None:
                raise _Invalid(key, f"{context}params keys must be strings, got {_kind(key)}")
        return self._value(node)

    def _limits(self, node: yaml.Node, context: str = "") -> dict[str, float]:
        if _is_null(node):
            return {}
        if not isinstance(node, yaml.MappingNode):
            raise _Invalid(node, f"{context}limits must be a mapping of limit name -> number "
                                 f"(e.g. {{execution_timeout_s: 120}}), got {_kind(node)}")
        limits = {}
        for key, value in node.value:
            name = _str_scalar(key)
            if name is None:
                raise _Invalid(key, f"{context}limits keys must be strings, got {_kind(key)}")
            number = self._value(value)
            if isinstance(number, bool) or not isinstance(number, (int, float)) or number < 0:
                raise _Invalid(value, f"{context}limit {name!r} must be a non-negative number, "
                                      f"got {_kind(value)}")
            limits[name] = number
        return limits

    def _accept(self, node: yaml.Node, context: str) -> dict[str, Any] | list[dict[str, Any]]:
        if isinstance(node, yaml.MappingNode):
            for key, _ in node.value:
                _predicate_name(key)
                if not _str_scalar(key):
                    raise _Invalid(key, f"{context}accept predicate names must be strings, "
                                        f"got {_kind(key)}; {_ACCEPT_HELP}")
            return self._value(node)
        if isinstance(node, yaml.SequenceNode):
            for item in node.value:
                if isinstance(item, yaml.MappingNode) and len(item.value) == 1:
                    _predicate_name(item.value[0][0])
                if not (isinstance(item, yaml.MappingNode) and len(item.value) == 1
                        and _str_scalar(item.value[0][0])):
                    raise _Invalid(item, f"{context}accept list items must be single-key "
                                         f"mappings, got {_kind(item)}; {_ACCEPT_HELP}")
            return self._value(node)
        raise _Invalid(node, f"{context}accept has the wrong type: {_ACCEPT_HELP}; "
                             f"got {_kind(node)}")

    # -- sections

    def parse(self, text: str) -> GoalGraph:
        root = self._compose(text)
        top = self._entries(root, what="goal graph", allowed=TOP_LEVEL_KEYS,
                            required=REQUIRED_TOP_LEVEL_KEYS)

        if "version" in top:
            self._check(self._version, top["version"][1])
        name = self._check(self._string, top["name"][1], "name") if "name" in top else None
        description = ""
        if "description" in top and not _is_null(top["description"][1]):
            description = self._check(self._string, top["description"][1], "description") or ""
        scene = self._check(self._scene, top["scene"][1]) if "scene" in top else None
        provenance = self._check(self._provenance, top["provenance"][1]) if "provenance" in top else None
        schedule = self._check(self._schedule, top["schedule"][1]) if "schedule" in top else None
        defaults_ok = True
        defaults: dict[str, Any] = {}
        if "defaults" in top:
            before = len(self.problems)
            defaults = self._defaults(top["defaults"][1])
            defaults_ok = len(self.problems) == before
        specs = self._nodes(top["nodes"], defaults, defaults_ok) if "nodes" in top else []

        if self.problems:
            first = min(self.problems, key=lambda p: (p.line, p.column))
            raise self._error(first.message, first.line)

        nodes = tuple(GoalNode(**spec) for spec, _dep_lines in specs)
        graph = GoalGraph(name=name, description=description,
                          path=Path(self.path) if self.path is not None else None,
                          scene=scene, nodes=nodes, provenance=provenance, schedule=schedule or "eager")
        self._reject_cycles(graph, {spec["id"]: lines for spec, lines in specs})
        return graph

    def _compose(self, text: str) -> yaml.MappingNode:
        try:
            root = yaml.compose(text, Loader=yaml.SafeLoader) if len(text) <= MAX_YAML_CHARS else None
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            context = f" ({exc.context})" if exc.context else ""
            raise self._error(f"YAML syntax error: {clip(str(exc.problem or exc))}{context}",
                              mark.line + 1 if mark is not None else None) from exc
        except yaml.YAMLError as exc:
            raise self._error(f"YAML syntax error: {clip(str(exc))}", None) from exc
        if len(text) > MAX_YAML_CHARS:
            raise self._error(f"goal graph of {len(text)} characters is longer than the limit of "
                              f"{MAX_YAML_CHARS}", 1)
        if "&" in text:  # without an anchor there is no alias to expand
            check_bounds(root, path=self.path, error=GoalGraphError)
        expected = f"expected a mapping with keys {format_choices(TOP_LEVEL_KEYS)}"
        if root is None:
            raise self._error(f"goal graph is empty; {expected}", 1)
        if not isinstance(root, yaml.MappingNode):
            raise self._error(f"top level must be a mapping, got {_kind(root)}; {expected}",
                              root.start_mark.line + 1)
        return root

    def _version(self, node: yaml.Node) -> None:
        value = self._value(node)
        if isinstance(value, bool) or value != SCHEMA_VERSION:
            raise _Invalid(node, f"unsupported version {value!r}; valid versions: "
                                 f"{SCHEMA_VERSION}")

    def _scene(self, node: yaml.Node) -> dict[str, Any] | None:
        if _is_null(node):
            return None
        if not isinstance(node, yaml.MappingNode):
            raise _Invalid(node, f"scene must be a mapping (keys such as 'objects', "
                                 f"'regions', 'obstacles'), got {_kind(node)}")
        return self._value(node)

    def _schedule(self, node: yaml.Node) -> str:
        value = self._value(node)
        if value not in SCHEDULES:
            raise _Invalid(node, f"unknown schedule {value!r}; valid schedules: {format_choices(SCHEDULES)}")
        return value

    def _provenance(self, node: yaml.Node) -> dict[str, Any] | None:
        from phyagentos.protocol import ModelCallRecord  # noqa: PLC0415

        if _is_null(node):
            return None
        if not isinstance(node, yaml.MappingNode):
            raise _Invalid(node, f"provenance must be a mapping (keys such as 'request', 'model_calls'), "
                                 f"got {_kind(node)}")
        value = self._value(node)
        calls = value.get("model_calls", [])
        if not isinstance(calls, list):
            raise _Invalid(node, "provenance.model_calls must be a list of model call records")
        for i, call in enumerate(calls):
            try:
                ModelCallRecord.model_validate(call)
            except ValueError as exc:
                raise _Invalid(node, f"provenance.model_calls[{i}] is not a model call record: "
                                     f"{clip(str(exc))}") from exc
        return value

    def _defaults(self, node: yaml.Node) -> dict[str, Any]:
        if _is_null(node):
            return {}
        if not isinstance(node, yaml.MappingNode):
            self.problems.append(_Invalid(node, f"defaults must be a mapping with keys from "
                                                f"{format_choices(DEFAULTS_KEYS)}, got "
                                                f"{_kind(node)}"))
            return {}
        entries = self._entries(node, what="defaults", allowed=DEFAULTS_KEYS, required=())
        validators = {"skill": self._skill, "target": self._target,
                      "params": self._params, "limits": self._limits, "runtime": self._runtime}
        defaults = {}
        for key, (_key_node, value_node) in entries.items():
            value = self._check(validators[key], value_node, "defaults: ")
            if value is not None:
                defaults[key] = value
        return defaults

    def _nodes(self, entry: tuple[yaml.Node, yaml.Node], defaults: dict[str, Any],
               defaults_ok: bool) -> list[tuple[dict[str, Any], dict[str, int]]]:
        key_node, seq = entry
        if not isinstance(seq, yaml.SequenceNode):
            self.problems.append(_Invalid(seq if not _is_null(seq) else key_node,
                                          f"nodes must be a non-empty list of node mappings, "
                                          f"got {_kind(seq)}"))
            return []
        if not seq.value:
            self.problems.append(_Invalid(key_node, "nodes is empty; a goal graph needs at "
                                                    "least one node (keys: "
                                                    f"{format_choices(NODE_KEYS)})"))
            return []
        # Dependencies may point forward in the file, so learn every id first.
        known_ids = []
        for item in seq.value:
            if isinstance(item, yaml.MappingNode):
                for k, v in item.value:
                    if _str_scalar(k) == "id" and _str_scalar(v) is not None:
                        known_ids.append(v.value)
        first_line: dict[str, int] = {}
        specs = []
        for item in seq.value:
            spec = self._node(item, defaults, defaults_ok, known_ids, first_line)
            if spec is not None:
                specs.append(spec)
        return specs

    def _node(self, item: yaml.Node, defaults: dict[str, Any], defaults_ok: bool,
              known_ids: list[str], first_line: dict[str, int]
              ) -> tuple[dict[str, Any], dict[str, int]] | None:
        """Validate one node; return (GoalNode kwargs, dependency -> line) or ``None``."""
        if not isinstance(item, yaml.MappingNode):
            self.problems.append(_Invalid(item, f"each entry of nodes must be a mapping with "
                                                f"keys {format_choices(NODE_KEYS)}, got "
                                                f"{_kind(item)}"))
            return None
        before = len(self.problems)
        # A default skill/target satisfies the required key (a broken defaults section
        # already has its own error, so do not pile "missing target" on top of it).
        required = tuple(k for k in REQUIRED_NODE_KEYS
                         if not (k in defaults or (k in DEFAULTS_KEYS and not defaults_ok)))
        entries = self._entries(item, what="node", allowed=NODE_KEYS, required=required)
        line = item.start_mark.line + 1

        node_id = None
        if "id" in entries:
            node_id = self._check(self._node_id, entries["id"][1])
            if node_id is not None:
                if node_id in first_line:
                    self.problems.append(_Invalid(
                        entries["id"][1], f"duplicate node id {node_id!r} (first defined at "
                                          f"line {first_line[node_id]}); node ids must be "
                                          f"unique"))
                else:
                    first_line[node_id] = line
        context = f"node {node_id!r}: " if node_id else ""

        spec: dict[str, Any] = {
            "id": node_id,
            "skill": defaults.get("skill"),
            "target": defaults.get("target"),
            "params": copy.deepcopy(defaults.get("params", {})),
            "accept": {},
            "depends_on": (),
            "limits": copy.deepcopy(defaults.get("limits", {})),
            "line": line,
            "runtime": defaults.get("runtime", "builtin"),
        }
        dep_lines: dict[str, int] = {}
        for key, (_key_node, value_node) in entries.items():
            if key == "id":
                continue
            if key == "skill":
                spec["skill"] = self._check(self._skill, value_node, context)
            elif key == "target":
                spec["target"] = self._check(self._target, value_node, context)
            elif key == "params":
                # Node params override defaults key by key rather than replacing them.
                spec["params"].update(self._check(self._params, value_node, context) or {})
            elif key == "limits":
                spec["limits"].update(self._check(self._limits, value_node, context) or {})
            elif key == "runtime":
                spec["runtime"] = self._check(self._runtime, value_node, context)
            elif key == "accept":
                spec["accept"] = self._check(self._accept, value_node, context)
            elif key == "depends_on":
                deps = self._check(self._depends_on, value_node, node_id, known_ids, context)
                if deps is not None:
                    spec["depends_on"] = tuple(deps)
                    dep_lines = deps
        return (spec, dep_lines) if len(self.problems) == before else None

    def _depends_on(self, node: yaml.Node, node_id: str | None, known_ids: list[str],
                    context: str) -> dict[str, int]:
        """Return dependency id -> 1-based line (insertion ordered)."""
        if _is_null(node):
            return {}
        others = [i for i in dict.fromkeys(known_ids) if i != node_id]
        valid = (f"valid node ids: {format_choices(others)}" if others
                 else "the graph has no other nodes")
        if not isinstance(node, yaml.SequenceNode):
            raise _Invalid(node, f"{context}depends_on must be a list of node ids (e.g. "
                                 f"[pick_cube]), got {_kind(node)}; {valid}")
        deps: dict[str, int] = {}
        for item in node.value:
            dep = _str_scalar(item)
            if dep is None:
                raise _Invalid(item, f"{context}depends_on entries must be node ids, got "
                                     f"{_kind(item)}; {valid}")
            if dep == node_id:
                raise _Invalid(item, f"{context}depends on itself; remove {dep!r} from "
                                     f"its depends_on; {valid}")
            if dep not in known_ids:
                raise _Invalid(item, f"{context}depends on unknown node {dep!r}"
                                     f"{_did_you_mean(dep, others)}; {valid}")
            if dep in deps:
                raise _Invalid(item, f"{context}depends_on lists {dep!r} twice (first at line "
                                     f"{deps[dep]})")
            deps[dep] = item.start_mark.line + 1
        return deps

    def _reject_cycles(self, graph: GoalGraph, dep_lines: dict[str, dict[str, int]]) -> None:
        cycle = find_dependency_cycle(to_digraph(graph))
        if cycle is None:
            return
        closing = [(cycle[i - 1], cycle[i]) for i in range(len(cycle))]
        # Report at the depends_on entry of the cycle's earliest node; list every edge so
        # the user can choose which dependency to drop.
        edges = ", ".join(f"{v!r} depends_on {u!r} (line {dep_lines[v][u]})"
                          for u, v in closing[1:] + closing[:1])
        shown = " -> ".join((*cycle, cycle[0]))
        raise self._error(
            f"dependency cycle {shown} (x -> y means y depends on x); a goal graph must be "
            f"acyclic, remove one of: {edges}",
            dep_lines[cycle[0]][cycle[-1]],
        )
