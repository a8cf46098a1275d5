"""A goal graph's composed YAML as the input of its pydantic schema, and back to file:line.

:func:`compose` reads the text into a YAML node tree (``yaml.compose``) within the bounds
of :mod:`phyagentos.yamlsource`. :class:`GraphSource` turns that tree into the plain data
:class:`~phyagentos.agent.goal_graph_schema.GoalGraphSpec` validates and remembers the
YAML nodes of every location of it, so each schema error (its ``loc``, and the ``at`` of
its context) maps back to the line of the offending key or value, and its message
describes the value as the file wrote it. Duplicate keys and values YAML cannot
construct are found here, on the tree, before the schema runs.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from phyagentos.agent.goal_graph_schema import (
    DEFAULTS_KEYS,
    ERROR_TYPE,
    NODE_KEYS,
    TOP_LEVEL_KEYS,
    render,
    unknown_key,
)
from phyagentos.errors import GoalGraphError
from phyagentos.yamlsource import MAX_YAML_CHARS, check_bounds, clip, excerpt

__all__ = ["GraphSource", "Problem", "compose"]

def compose(text: str, path: str | Path | None) -> yaml.Node | None:
    """The YAML node tree of ``text`` (``None`` when empty), within the bounds."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader) if len(text) <= MAX_YAML_CHARS else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        context = f" ({exc.context})" if exc.context else ""
        raise GoalGraphError(f"YAML syntax error: {clip(str(exc.problem or exc))}{context}", path=path,
                             line=mark.line + 1 if mark is not None else None) from exc
    except yaml.YAMLError as exc:
        raise GoalGraphError(f"YAML syntax error: {clip(str(exc))}", path=path, line=None) from exc
    if len(text) > MAX_YAML_CHARS:
        raise GoalGraphError(f"goal graph of {len(text)} characters is longer than the limit of "
                             f"{MAX_YAML_CHARS}", path=path, line=1)
    if "&" in text:  # without an anchor there is no alias to expand
        check_bounds(root, path=path, error=GoalGraphError)
    return root


_STR_TAG = "tag:yaml.org,2002:str"
_NULL_TAG = "tag:yaml.org,2002:null"
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"
_MERGE_TAG = "tag:yaml.org,2002:merge"
#: A problem: 1-based line, column, message.
Problem = tuple[int, int, str]


def _kind(node: yaml.Node) -> str:
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    if node.tag == _NULL_TAG:
        return "nothing (null)"
    return f"the scalar {excerpt(node.value)}"


def _str_scalar(node: yaml.Node) -> str | None:
    """Return the text of a plain string scalar, else ``None`` (numbers, null, containers)."""
    if isinstance(node, yaml.ScalarNode) and node.tag == _STR_TAG:
        return node.value
    return None


def _where(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column


class _Key:
    """A YAML node that is not a string (a number, ``<<``, a list), as the schema sees a key
    or a value it checks as written: not a ``str``, so "must be a string" catches it."""

    __slots__ = ("node",)

    def __init__(self, node: yaml.Node):
        self.node = node

    def __str__(self) -> str:
        return self.node.value if isinstance(self.node, yaml.ScalarNode) else _kind(self.node)


class _Unreadable:
    """A value YAML could not construct (its problem is already recorded)."""


class GraphSource:
    """The composed YAML of one goal graph (:func:`compose`) as the schema's input
    (:attr:`data`), with the YAML nodes of every input location (:attr:`nodes`), so a schema
    error's ``loc`` maps back to its line (:meth:`locate`, :meth:`line`).

    The schema's own mappings (the graph, ``defaults``, each node) keep each key's text,
    and so do the mappings whose keys the schema checks (``params``, ``limits``, ``accept``;
    a key that is not a YAML string stays a :class:`_Key`); other values are constructed
    as YAML data. Duplicate keys and values YAML cannot construct are :attr:`problems`.
    """

    def __init__(self, root: yaml.Node | None):
        self.nodes: dict[tuple[Any, ...], tuple[yaml.Node | None, yaml.Node]] = {}
        self.problems: list[Problem] = []
        self._unreadable: set[tuple[Any, ...]] = set()
        self._constructor = yaml.constructor.SafeConstructor()
        if root is None:
            self.data: Any = None
        elif isinstance(root, yaml.MappingNode):
            self.data = self._fields(root, (), "goal graph", TOP_LEVEL_KEYS)
        else:
            self.data = self._value(root, ())
        if root is not None:
            self.nodes[()] = (None, root)

    # -- schema errors

    def locate_all(self, exc: ValidationError) -> list[Problem]:
        """The schema's errors as problems (:meth:`locate`), but those about a value YAML
        could not construct: that is its problem, already in :attr:`problems`."""
        out = []
        for error in exc.errors(include_url=False):
            loc = tuple(error["loc"]) + tuple((error.get("ctx") or {}).get("at", ()))
            if not any(loc[:n] in self._unreadable for n in range(len(loc) + 1)):
                out.append(self.locate(error))
        return out

    def locate(self, error: Any) -> Problem:
        """``error`` (pydantic's) as a problem at its YAML node, its message rendered from the YAML."""
        ctx = error.get("ctx") or {}
        loc = tuple(error["loc"])
        if error["type"] != ERROR_TYPE:
            key, node = self._node(loc)
            where = _where(node) if node is not None else (1, 0)
            return (*where, f"{'.'.join(map(str, loc))}: {error['msg']}" if loc else error["msg"])
        key, node = self._node(loc + tuple(ctx.get("at", ())))
        values = dict(ctx)
        shown = key if ctx.get("got_key") else node
        if "got" in ctx and shown is not None:
            values["got"] = _kind(shown)
        if "first_at" in ctx:
            _k, first = self._node(loc + tuple(ctx["first_at"]))
            if first is not None:
                values["first"] = f"line {_where(first)[0]}"
        target = key if ctx.get("on_key") and key is not None else node
        where = _where(target) if target is not None else (1, 0)
        return (*where, render(ctx["template"], values))

    def line(self, loc: tuple[Any, ...]) -> int:
        """1-based line of the YAML value at ``loc`` (or of its nearest enclosing value)."""
        _key, node = self._node(loc)
        return _where(node)[0] if node is not None else 1

    def _node(self, loc: tuple[Any, ...]) -> tuple[yaml.Node | None, yaml.Node | None]:
        """(key node, value node) of ``loc``, or of its longest prefix with nodes."""
        for n in range(len(loc), -1, -1):
            try:
                found = self.nodes.get(loc[:n])
            except TypeError:  # an unhashable key
                found = None
            if found is not None:
                return found
        return None, None

    # -- building the input

    def _fields(self, node: yaml.MappingNode, loc: tuple[Any, ...], what: str, allowed: tuple[str, ...]
                ) -> dict[str, Any]:
        """A mapping of the schema: key text -> input (an unknown key's value is not read)."""
        out: dict[str, Any] = {}
        first: dict[str, yaml.Node] = {}
        for key_node, value_node in node.value:
            key = _str_scalar(key_node)
            text = key if key is not None else str(_Key(key_node))
            if key is not None and key in allowed:
                if key in first:
                    self.problems.append((*_where(key_node), f"duplicate key {key!r} in {what} (first defined at "
                                                             f"line {_where(first[key])[0]})"))
                    continue
                first[key] = key_node
                out[key] = self._field(value_node, loc + (key,), what, key)
            elif text in allowed:  # a key that is not a string (``!tag id``) named like a valid one
                self.problems.append((*_where(key_node), unknown_key(text, what, allowed).message()))
                continue
            elif text in out:  # an unknown key again: the first is reported
                continue
            else:
                out[text] = None
            self.nodes[loc + (text,)] = (key_node, value_node)
        return out

    def _field(self, node: yaml.Node, loc: tuple[Any, ...], what: str, key: str) -> Any:
        """The input of ``key`` in ``what``: YAML data is constructed only where a value
        passes through (version, schedule, scene, provenance, params, limits, accept); the
        rest is checked as written (a tagged scalar is not a string, whatever its tag)."""
        mapping, sequence = isinstance(node, yaml.MappingNode), isinstance(node, yaml.SequenceNode)
        if key == "defaults" and mapping:
            return self._fields(node, loc, "defaults", DEFAULTS_KEYS)
        if key == "nodes" and sequence:
            for i, item in enumerate(node.value):
                self.nodes[loc + (i,)] = (None, item)
            return [self._fields(item, loc + (i,), "node", NODE_KEYS) if isinstance(item, yaml.MappingNode)
                    else _opaque(item) for i, item in enumerate(node.value)]
        if key == "depends_on" and sequence:
            for i, item in enumerate(node.value):
                self.nodes[loc + (i,)] = (None, item)
            return [_opaque(item) for item in node.value]
        if key in ("params", "limits", "accept") and node.tag == _MAP_TAG and mapping:
            if key == "accept":
                for key_node, _ in node.value:
                    _predicate_name(key_node)
            if key != "limits":
                self._duplicate_keys(node)
            return self._entries(node, loc, checked=key != "limits")
        if key == "accept" and node.tag == _SEQ_TAG and sequence:
            single = [isinstance(item, yaml.MappingNode) and item.tag == _MAP_TAG and len(item.value) == 1
                      for item in node.value]
            for i, item in enumerate(node.value):
                self.nodes[loc + (i,)] = (None, item)
                if single[i]:
                    _predicate_name(item.value[0][0])
            self._duplicate_keys(node)
            return [self._entries(item, loc + (i,), checked=True) if single[i] else _opaque(item)
                    for i, item in enumerate(node.value)]
        if key in ("version", "schedule") or (key in ("scene", "provenance") and mapping):
            return self._value(node, loc, whole=True)
        if mapping or (sequence and key == "accept"):  # a tagged params, limits or accept
            return self._value(node, loc)
        return _opaque(node)

    def _entries(self, node: yaml.MappingNode, loc: tuple[Any, ...], *, checked: bool) -> dict[Any, Any]:
        """A mapping whose keys the schema checks: key -> constructed value."""
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = _str_scalar(key_node)
            name: Any = key if key is not None else _Key(key_node)
            out[name] = self._value(value_node, loc + (name,), checked=checked)
            self.nodes[loc + (name,)] = (key_node, value_node)
        return out

    def _value(self, node: yaml.Node, loc: tuple[Any, ...], *, checked: bool = False, whole: bool = False) -> Any:
        """``node`` constructed as YAML data (deep-copied: aliases would otherwise share one
        object), its duplicate keys recorded unless ``checked`` already (``whole``: a value
        with a duplicate key is not read further)."""
        if not checked and not self._duplicate_keys(node) and whole:
            return self._unread(loc)
        try:
            return copy.deepcopy(self._constructor.construct_object(node, deep=True))
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark
            where = (mark.line + 1, mark.column) if mark is not None else _where(node)
            self.problems.append((*where, f"cannot read value: {exc.problem or exc}"))
            return self._unread(loc)

    def _unread(self, loc: tuple[Any, ...]) -> _Unreadable:
        self._unreadable.add(loc)
        return _Unreadable()

    def _duplicate_keys(self, node: yaml.Node) -> bool:
        """Record the first duplicate key inside ``node``; whether there was none. (A value
        with one is still read: a problem of its shape, earlier in the file, comes first.)"""
        try:
            _reject_duplicate_keys(node, set())
        except _Duplicate as dup:
            self.problems.append((*_where(dup.key), str(dup)))
            return False
        return True


def _opaque(node: yaml.Node) -> Any:
    """A value the schema checks as written: a YAML string as its text, null as ``None``,
    anything else as a stand-in that is neither (its messages describe the YAML node)."""
    text = _str_scalar(node)
    if text is not None:
        return text
    return None if isinstance(node, yaml.ScalarNode) and node.tag == _NULL_TAG else _Key(node)


class _Duplicate(Exception):
    def __init__(self, key: yaml.Node, first: yaml.Node):
        super().__init__(f"duplicate key {key.value!r} (first defined at line {first.start_mark.line + 1})")
        self.key = key


def _reject_duplicate_keys(node: yaml.Node, seen: set[int]) -> None:
    if id(node) in seen:  # recursive alias; the constructor handles it
        return
    seen.add(id(node))
    if isinstance(node, yaml.MappingNode):
        first: dict[tuple[str, str], yaml.Node] = {}
        for key, value in node.value:
            if isinstance(key, yaml.ScalarNode) and key.tag != _MERGE_TAG:
                ident = (key.tag, key.value)
                if ident in first:
                    raise _Duplicate(key, first[ident])
                first[ident] = key
            _reject_duplicate_keys(value, seen)
    elif isinstance(node, yaml.SequenceNode):
        for item in node.value:
            _reject_duplicate_keys(item, seen)


def _predicate_name(node: yaml.Node) -> None:
    """YAML 1.1 reads a plain ``on`` as the boolean true; as an accept key it can only be
    the predicate ``on`` (``accept: {on: {object: a, support: b}}``), so it is kept as
    the string the user wrote."""
    if isinstance(node, yaml.ScalarNode) and node.style is None and node.value in ("on", "On", "ON"):
        node.tag = _STR_TAG
