"""Behaviour trees authored in YAML, built into ``py_trees`` trees.

A tree file (``trees/<name>.yaml``)::

    version: 1
    name: move_to
    description: Plan and execute a collision-free motion to a tcp pose.
    params:                         # what callers must (or may) pass in
      pose: {required: true, description: blackboard key of a (4, 4) tcp pose}
      planner: {default: RRTConnect}
    root:
      sequence:
        name: MoveTo
        children:
          - primitive: solve_ik
            params: {pose: "${pose}", out: q_goal}
          - retry:
              num_failures: 3
              child: {primitive: plan_path, params: {goal: q_goal, planner: "${planner}"}}

Node kinds: ``sequence``, ``selector`` (children, ``memory`` default true),
``parallel`` (children, ``policy``: success_on_all | success_on_one), ``retry``
(``num_failures``, child), ``timeout`` (``duration_s`` wall-clock seconds, child),
``subtree`` (another tree by name, with ``params``) and leaves ``primitive`` (a
registered primitive with ``params``). A string that is exactly ``${name}`` is
replaced by the parameter's value (any type); ``${name}`` inside a longer string
is interpolated as text.
"""

from __future__ import annotations

import functools
import inspect
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import py_trees

from phyagentos.errors import SkillError, format_choices
from phyagentos.yamlsource import SourceMap, line_of, load_yaml

from .param_decls import check_param_decls
from .skills import search_dirs

__all__ = ["TreeLibrary", "TreeSpec", "NODE_KINDS", "render_ascii", "render_image"]

logger = logging.getLogger(__name__)

NODE_KINDS = ("sequence", "selector", "parallel", "retry", "timeout", "subtree", "primitive")
_PARALLEL_POLICIES = {
    "success_on_all": lambda: py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True),
    "success_on_one": lambda: py_trees.common.ParallelPolicy.SuccessOnOne(),
}
_REF = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
_MAX_DEPTH = 16  # guards against subtree recursion (a includes b includes a)


@functools.lru_cache(maxsize=None)
def _signature(cls: Callable[..., Any]) -> inspect.Signature:
    """``inspect.signature(cls)``, computed once per primitive class (a class's signature
    does not change; computing it was half the time of building a tree)."""
    return inspect.signature(cls)


@dataclass(frozen=True)
class TreeSpec:
    """A parsed tree file: its declared parameters and raw root node."""

    name: str
    description: str
    params: Mapping[str, Mapping[str, Any]]
    root: SourceMap
    path: Path


class TreeLibrary:
    """The trees in a directory plus the primitives their leaves may name.

    Args:
        directory: folder of ``*.yaml`` tree files.
        primitives: primitive name -> behaviour class; each class takes ``name``
            plus the keyword parameters its leaves pass.

    Raises:
        SkillError: for a malformed tree file (with file and line).
    """

    def __init__(self, directory: str | Path | Sequence[str | Path],
                 primitives: Mapping[str, Callable[..., py_trees.behaviour.Behaviour]]):
        self.directories = search_dirs(directory)
        self.primitives = dict(primitives)
        self._specs: dict[str, TreeSpec] = {}
        #: (name, path that wins, path shadowed by it), first folder of the search path wins
        self.shadowed: list[tuple[str, Path, Path]] = []
        seen: dict[str, Path] = {}
        for folder in self.directories:
            for path in sorted(folder.glob("*.yaml")):
                if path.stem in seen:
                    self.shadowed.append((path.stem, seen[path.stem], path))
                    logger.warning("tree %r in %s is shadowed by %s, which comes first in the search path",
                                   path.stem, path, seen[path.stem])
                else:
                    seen[path.stem] = path
        self._paths = seen

    @property
    def directory(self) -> str:
        """The search path as one ``os.pathsep``-joined string (what the runner process takes)."""
        return os.pathsep.join(str(d) for d in self.directories)

    def names(self) -> list[str]:
        """Names of all tree files along the search path, sorted."""
        return sorted(self._paths)

    def path(self, name: str) -> Path | None:
        """The file tree ``name`` is read from (the first along the search path)."""
        return self._paths.get(name)

    def spec(self, name: str) -> TreeSpec:
        """Parse (once) and return the tree ``name``.

        Raises:
            SkillError: unknown tree (listing valid ones) or malformed file.
        """
        if name in self._specs:
            return self._specs[name]
        path = self._paths.get(name)
        if path is None or not path.is_file():
            raise SkillError(f"unknown tree {name!r}; valid trees: {format_choices(self.names())}")
        data = load_yaml(path.read_text(encoding="utf-8"), path=path, error=SkillError)
        if not isinstance(data, SourceMap):
            raise SkillError("a tree file must be a mapping", path=path, line=1)
        valid = {"version", "name", "description", "params", "root"}
        for key in data:
            if key not in valid:
                raise SkillError(f"unknown key {key!r}; valid keys: {format_choices(valid)}", path=path, line=data.key_line(key))
        if data.get("version") != 1:
            raise SkillError(f"unsupported version {data.get('version')!r}; supported: 1", path=path, line=data.key_line("version"))
        if not isinstance(data.get("root"), SourceMap):
            raise SkillError("missing or non-mapping 'root'", path=path, line=data.key_line("root"))
        params = check_param_decls(data.get("params"), path=path, line=data.key_line("params"))
        if not isinstance(data.get("description", ""), str):
            raise SkillError("'description' must be one string", path=path, line=data.key_line("description"))
        spec = TreeSpec(
            name=str(data.get("name", name)),
            description=str(data.get("description", "")),
            params=params,
            root=data["root"],
            path=path,
        )
        self._specs[name] = spec
        return spec

    def build(self, name: str, params: Mapping[str, Any] | None = None) -> py_trees.behaviour.Behaviour:
        """Build a fresh behaviour tree root for tree ``name``.

        Args:
            name: tree file stem in the library directory.
            params: values for the tree's declared parameters (the session's
                skill parameters for a top-level tree).

        Raises:
            SkillError: missing/unknown parameters, unknown node kinds or
                primitives, bad primitive arguments; messages give file:line and
                the valid choices.
        """
        return self._build_tree(name, dict(params or {}), depth=0, call_site=None)

    # -- internals -------------------------------------------------------

    def _build_tree(self, name: str, params: dict, *, depth: int, call_site: tuple[Path, int | None] | None):
        if depth > _MAX_DEPTH:
            raise SkillError(f"subtree nesting deeper than {_MAX_DEPTH} (recursive include of {name!r}?)",
                             path=call_site[0] if call_site else None, line=call_site[1] if call_site else None)
        spec = self.spec(name)
        where = dict(path=call_site[0], line=call_site[1]) if call_site else dict(path=spec.path, line=None)
        unknown = set(params) - set(spec.params)
        if unknown:
            raise SkillError(f"tree {name!r} got unknown parameter(s) {format_choices(unknown)}; "
                             f"declared: {format_choices(spec.params) or 'none'}", **where)
        bound = {}
        for pname, decl in spec.params.items():
            if pname in params:
                bound[pname] = params[pname]
            elif "default" in decl:
                bound[pname] = decl["default"]
            elif decl.get("required", False):
                raise SkillError(f"tree {name!r} needs parameter {pname!r} ({decl.get('description', 'no description')})", **where)
        return self._build_node(spec, spec.root, bound, depth)

    def _build_node(self, spec: TreeSpec, node: Any, params: dict, depth: int) -> py_trees.behaviour.Behaviour:
        path = spec.path
        if not isinstance(node, SourceMap) or len(node) == 0:
            raise SkillError(f"a tree node must be a mapping with one of {format_choices(NODE_KINDS)}",
                             path=path, line=line_of(node))
        kinds = [k for k in node if k in NODE_KINDS]
        if len(kinds) != 1:
            raise SkillError(f"node must have exactly one kind key; found {sorted(map(str, node))}; "
                             f"valid kinds: {format_choices(NODE_KINDS)}", path=path, line=node.line)
        kind = kinds[0]
        line = node.key_line(kind)
        if kind == "primitive":
            return self._build_primitive(spec, node, params)
        if kind == "subtree":
            extra = set(node) - {"subtree", "params", "name"}
            if extra:
                raise SkillError(f"unknown key(s) {format_choices(extra)} on subtree; valid: 'name', 'params', 'subtree'",
                                 path=path, line=line)
            sub_params = _substitute(node.get("params") or {}, params, path, line)
            root = self._build_tree(str(node["subtree"]), sub_params, depth=depth + 1, call_site=(path, line))
            if "name" in node:
                root.name = str(node["name"])
            return root
        body = node[kind]
        if not isinstance(body, SourceMap):
            raise SkillError(f"{kind!r} must be a mapping", path=path, line=line)
        name = str(body.get("name", kind.capitalize()))
        if kind in ("sequence", "selector", "parallel"):
            allowed = {"name", "children", "memory", "policy"} if kind == "parallel" else {"name", "children", "memory"}
            _check_keys(body, allowed, kind, path)
            children_raw = body.get("children")
            if not isinstance(children_raw, list) or not children_raw:
                raise SkillError(f"{kind!r} needs a non-empty 'children' list", path=path, line=body.line)
            children = [self._build_node(spec, c, params, depth) for c in children_raw]
            if kind == "sequence":
                return py_trees.composites.Sequence(name=name, memory=bool(body.get("memory", True)), children=children)
            if kind == "selector":
                return py_trees.composites.Selector(name=name, memory=bool(body.get("memory", True)), children=children)
            policy = str(body.get("policy", "success_on_all"))
            if policy not in _PARALLEL_POLICIES:
                raise SkillError(f"unknown parallel policy {policy!r}; valid: {format_choices(_PARALLEL_POLICIES)}",
                                 path=path, line=body.key_line("policy"))
            return py_trees.composites.Parallel(name=name, policy=_PARALLEL_POLICIES[policy](), children=children)
        # decorators
        allowed = {"name", "child", "num_failures"} if kind == "retry" else {"name", "child", "duration_s"}
        _check_keys(body, allowed, kind, path)
        if "child" not in body:
            raise SkillError(f"{kind!r} needs a 'child'", path=path, line=body.line)
        child = self._build_node(spec, body["child"], params, depth)
        if kind == "retry":
            n = _substitute(body.get("num_failures", 1), params, path, line)
            if not isinstance(n, int) or n < 1:
                raise SkillError(f"retry.num_failures must be an integer >= 1, found {n!r}", path=path, line=body.key_line("num_failures"))
            return py_trees.decorators.Retry(name=name, child=child, num_failures=n)
        duration = _substitute(body.get("duration_s"), params, path, line)
        if not isinstance(duration, (int, float)) or duration <= 0:
            raise SkillError(f"timeout.duration_s must be a positive number of seconds, found {duration!r}",
                             path=path, line=body.key_line("duration_s"))
        return py_trees.decorators.Timeout(name=name, child=child, duration=float(duration))

    def _build_primitive(self, spec: TreeSpec, node: SourceMap, params: dict):
        path, line = spec.path, node.key_line("primitive")
        _check_keys(node, {"primitive", "name", "params"}, "primitive", path)
        pname = str(node["primitive"])
        if pname not in self.primitives:
            raise SkillError(f"unknown primitive {pname!r}; valid primitives: {format_choices(self.primitives)}", path=path, line=line)
        cls = self.primitives[pname]
        kwargs = _substitute(dict(node.get("params") or {}), params, path, line)
        try:
            _signature(cls).bind(name="x", **kwargs)
        except TypeError as exc:
            accepted = [p for p in _signature(cls).parameters if p != "name"]
            raise SkillError(f"bad parameters for primitive {pname!r}: {exc}; accepted: {format_choices(accepted)}",
                             path=path, line=line) from None
        try:
            return cls(name=str(node.get("name", pname)), **kwargs)
        except (ValueError, TypeError) as exc:
            raise SkillError(f"primitive {pname!r}: {exc}", path=path, line=line) from None


def _check_keys(body: SourceMap, allowed: set, kind: str, path: Path) -> None:
    for key in body:
        if key not in allowed:
            raise SkillError(f"unknown key {key!r} in {kind!r}; valid keys: {format_choices(allowed)}",
                             path=path, line=body.key_line(key))


def _substitute(value: Any, params: Mapping[str, Any], path: Path, line: int | None) -> Any:
    """Resolve ``${name}`` references against ``params`` (recursively)."""
    if isinstance(value, str):
        whole = _REF.fullmatch(value)
        if whole:
            key = whole.group(1)
            if key not in params:
                raise SkillError(f"unresolved reference ${{{key}}}; available parameters: {format_choices(params) or 'none'}",
                                 path=path, line=line)
            return params[key]

        def repl(m: re.Match) -> str:
            if m.group(1) not in params:
                raise SkillError(f"unresolved reference ${{{m.group(1)}}}; available parameters: {format_choices(params) or 'none'}",
                                 path=path, line=line)
            return str(params[m.group(1)])

        return _REF.sub(repl, value)
    if isinstance(value, dict):
        return {k: _substitute(v, params, path, line) for k, v in value.items()}
    if isinstance(value, list):
        return [_substitute(v, params, path, line) for v in value]
    return value


def render_ascii(root: py_trees.behaviour.Behaviour) -> str:
    """Unicode-free ASCII drawing of a tree (``py_trees.display.ascii_tree``)."""
    return py_trees.display.ascii_tree(root)


def render_image(root: py_trees.behaviour.Behaviour, path: str | Path) -> Path:
    """Render the tree to ``path`` (``.png`` or ``.svg``) through Graphviz.

    Raises:
        SkillError: if Graphviz's ``dot`` executable is not installed.
    """
    path = Path(path)
    graph = py_trees.display.dot_tree(root)
    for setter in (graph.set_graph_defaults, graph.set_node_defaults, graph.set_edge_defaults):
        setter(fontname="DejaVu Sans")
    # py_trees prefixes memory composites with Ⓜ, which common fonts lack (a tofu
    # box); composites are already drawn as boxes, so drop the marker.
    for node in graph.get_nodes():
        label = node.get("label")
        if isinstance(label, str) and "Ⓜ" in label:
            node.set("label", label.replace("Ⓜ ", "").replace("Ⓜ", ""))
    fmt = path.suffix.lstrip(".") or "png"
    try:
        data = graph.create(format=fmt)
    except FileNotFoundError:
        raise SkillError("rendering a tree image needs Graphviz 'dot' (apt-get install graphviz)") from None
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path
