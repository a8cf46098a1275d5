"""The CLI commands about authoring: which skills, trees and primitives there are.

    phyagentos skills list [--workspace DIR] [--json]
    phyagentos skills show NAME [--workspace DIR]
    phyagentos primitives [--json] [--markdown]

Skills and trees come from the search path (:func:`phyagentos.resources.search_path`):
the workspace's ``skills/`` and ``trees/``, then every ``--skills-path`` folder, then
the shipped ones; the first folder with a name wins and every shadowed file is shown.
The primitive listing is generated from the code (:mod:`phyagentos.primitives.schema`),
as is ``docs/primitives.md`` (:func:`primitives_markdown`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

if TYPE_CHECKING:  # rich is imported where it prints (a quiet command never loads it)
    from rich.console import Console


__all__ = ["add_skill_commands", "SKILL_HANDLERS", "skill_search_env", "primitives_markdown"]

EXIT_OK = 0


@contextlib.contextmanager
def skill_search_env(args: argparse.Namespace, err: Console) -> Iterator[None]:
    """Put the command's workspace and ``--skills-path`` folders in front of
    ``PHYAGENTOS_SKILLS_PATH`` for the command (and every process it starts)."""
    from phyagentos.resources import SKILLS_PATH_ENV  # noqa: PLC0415

    entries = [str(p) for p in getattr(args, "skills_path", []) or []]
    for p in entries:
        if not Path(p).is_dir():
            err.print(f"warning: --skills-path {p} is not a folder; ignored", markup=False, highlight=False)
    entries = [p for p in entries if Path(p).is_dir()]
    workspace = getattr(args, "workspace", None)
    if workspace is not None and Path(workspace).is_dir():
        entries.insert(0, str(workspace))
    before = os.environ.get(SKILLS_PATH_ENV)
    if entries:
        os.environ[SKILLS_PATH_ENV] = os.pathsep.join(entries + ([before] if before else []))
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(SKILLS_PATH_ENV, None)
        else:
            os.environ[SKILLS_PATH_ENV] = before


def add_skill_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``skills`` and ``primitives`` to the ``phyagentos`` parser."""
    skills = sub.add_parser("skills", help="the skills along the search path (workspace, --skills-path, shipped)")
    ssub = skills.add_subparsers(dest="what", required=True)
    lst = ssub.add_parser("list", help="every skill with where it comes from, and what it shadows")
    lst.add_argument("--workspace", type=Path, help="include this workspace's skills/ and trees/ (searched first)")
    lst.add_argument("--json", action="store_true", help="print one JSON object")
    show = ssub.add_parser("show", help="a skill's manifest, parameters, gripper effect and tree")
    show.add_argument("name")
    show.add_argument("--workspace", type=Path, help="include this workspace's skills/ and trees/ (searched first)")
    prim = sub.add_parser("primitives", help="every primitive with its parameters, types, units and defaults")
    prim.add_argument("--json", action="store_true", help="print one JSON object")
    prim.add_argument("--markdown", action="store_true", help="print docs/primitives.md")


def _runtime():
    from phyagentos.resources import skill_dirs, tree_dirs  # noqa: PLC0415
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

    return BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs())


def _cmd_skills(args, out: Console, err: Console) -> int:
    runtime = _runtime()
    if args.what == "show":
        return _show(runtime, args.name, out)
    from phyagentos.resources import data_root  # noqa: PLC0415

    def origin(path: Path) -> str:
        root = path.parent.parent
        return "shipped" if root.resolve() == data_root().resolve() else str(root)

    rows = [{"name": m.name, "runtime": m.runtime, "tree": m.tree, "path": str(m.path), "origin": origin(m.path),
             "acquires": m.acquires,
             "releases": m.releases, "description": m.description} for m in runtime.skills.manifests()]
    shadowed = [{"kind": kind, "name": n, "wins": str(w), "shadowed": str(s)}
                for kind, items in (("skill", runtime.skills.shadowed), ("tree", runtime.trees.shadowed))
                for n, w, s in items]
    if args.json:
        print(json.dumps({"search_path": [str(d) for d in runtime.skills.directories], "skills": rows,
                          "shadowed": shadowed}, ensure_ascii=False))
        return EXIT_OK
    out.print("search path (first wins): " + ", ".join(str(d) for d in runtime.skills.directories),
              markup=False, highlight=False, soft_wrap=True)
    from rich.table import Table  # noqa: PLC0415 - rich loads where it prints

    table = Table(title="skills")
    for col in ("skill", "runtime", "gripper", "from", "description"):
        table.add_column(col, overflow="fold")
    for r in rows:
        grip = ", ".join(f"{k} {r[k]}" for k in ("acquires", "releases") if r[k]) or "-"
        table.add_row(r["name"], r["runtime"], grip, r["origin"], r["description"])
    out.print(table)
    for s in shadowed:
        out.print(f"{s['kind']} {s['name']!r}: {s['wins']} wins over {s['shadowed']}", markup=False, highlight=False,
                  soft_wrap=True)
    return EXIT_OK


def _show(runtime, name: str, out: Console) -> int:
    from phyagentos.runtime.trees import render_ascii  # noqa: PLC0415

    m = runtime.skills.get(name)
    say = lambda text: out.print(text, markup=False, highlight=False, soft_wrap=True)  # noqa: E731
    say(f"skill {m.name} ({m.runtime})  from {m.path}")
    say(f"  {m.description}")
    if m.acquires or m.releases:
        say("  gripper: " + ", ".join(f"{k} params[{v}]" for k, v in (("acquires", m.acquires), ("releases", m.releases)) if v))
    say(f"  requires capabilities: {', '.join(m.capabilities) or 'none'}; observations: {', '.join(m.observations) or 'none'}")
    say("  parameters:")
    for k, d in m.params.items():
        say(f"    {k}{' (required)' if d.get('required') else ''}: {d.get('description', '')}")
    for n, w, s in runtime.skills.shadowed:
        if n == name:
            say(f"  shadows {s}")
    if m.tree:
        say(f"tree {m.tree} from {runtime.trees.path(m.tree)}:")
        params = {k: d.get("example", f"<{k}>") for k, d in m.params.items() if d.get("required") or "example" in d}
        print(render_ascii(runtime.trees.build(m.tree, params)))
    return EXIT_OK


def _default(value) -> str:
    from phyagentos.primitives.schema import REQUIRED  # noqa: PLC0415

    return "required" if value is REQUIRED else json.dumps(value)


def _cmd_primitives(args, out: Console, err: Console) -> int:
    from phyagentos.primitives.schema import primitive_schemas  # noqa: PLC0415

    schemas = primitive_schemas()
    if args.markdown:
        print(primitives_markdown(), end="")
        return EXIT_OK
    if args.json:
        print(json.dumps({s.name: {"class": s.cls.__name__, "summary": s.summary, "params": [
            {"name": p.name, "type": p.type, "unit": p.unit, "required": p.required,
             "default": None if p.required else p.default, "description": p.description} for p in s.params]}
            for s in schemas}, ensure_ascii=False))
        return EXIT_OK
    for s in schemas:
        from rich.table import Table  # noqa: PLC0415

        table = Table(title=f"{s.name}  ({s.cls.__name__}): {s.summary}", title_justify="left")
        for col in ("parameter", "type", "unit", "default", "description"):
            table.add_column(col, overflow="fold")
        for p in s.params:
            table.add_row(p.name, p.type, p.unit or "-", _default(p.default), p.description)
        out.print(table)
    return EXIT_OK


def primitives_markdown() -> str:
    """``docs/primitives.md``: every primitive's parameters, generated from the code."""
    from phyagentos.primitives.schema import primitive_schemas  # noqa: PLC0415

    lines = ["# Primitives", "",
             "<!-- Generated by `phyagentos primitives --markdown > docs/primitives.md`; do not edit by hand. -->",
             "", "The leaves a behaviour tree (`trees/*.yaml`) may use, with every parameter a leaf may pass:",
             "type, unit (SI), default (`required` when there is none) and meaning. Keys are blackboard",
             "entry names that earlier leaves write and later ones read. Generated from each primitive's",
             "parameter table (`phyagentos/primitives/schema.py`) and its `__init__` signature.", ""]
    for s in primitive_schemas():
        lines += [f"## `{s.name}`", "", f"{s.summary} (`{s.cls.__module__}.{s.cls.__name__}`)", "",
                  "| parameter | type | unit | default | description |", "|---|---|---|---|---|"]
        for p in s.params:
            lines.append(f"| `{p.name}` | {p.type.replace('|', '&#124;')} | {p.unit or '-'} | `{_default(p.default)}` "
                         f"| {p.description} |")
        lines.append("")
    return "\n".join(lines)


SKILL_HANDLERS = {"skills": _cmd_skills, "primitives": _cmd_primitives}
