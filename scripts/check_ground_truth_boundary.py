#!/usr/bin/env python3
"""CI check: the Agent plane never names the simulator's privileged channel (issue 9, part 2).

Fails (exit 1, one line per finding ``file:line: what``) when any module under
``phyagentos/agent/`` names

- ``ground_truth`` / ``ground_truth.yaml`` / ``truth`` (the privileged channel and its file),
- ``perturbation`` / ``perturbations`` / ``perturbed`` (the scene's scripted disturbances),
- an external benchmark's answer key and checker (LIBERO, docs/libero.md): ``bddl`` (the
  task file holding ``:goal``, ``:init`` and regions), ``obj_of_interest``,
  ``check_success``, ``benchmark_signals``, ``env_success``,

anywhere: identifiers (names, attributes, arguments, function and class names, keyword
arguments), imported module and object names, string constants (keys, paths, docstrings)
and comments; or imports a module (inside the package) that names them in its code
(identifiers, imported names, and string constants without whitespace, i.e. keys and file
names; prose in another module's docstrings or messages does not count there).

Read with the AST (plus :mod:`tokenize` for comments), not a grep: an import of a helper
that reads the file is caught as well as the string itself. Nothing is allow-listed.

Usage: ``scripts/check_ground_truth_boundary.py [REPO_ROOT]`` (default: this script's
repository). Run by ``make test`` before pytest.
"""

from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from pathlib import Path

#: A forbidden word: letters/digits around it end the match, ``_`` and ``.`` do not, so
#: ``ground_truth``, ``ground_truth.yaml``, ``truth``, ``scene["perturbations"]``,
#: ``parse_bddl`` and ``env.check_success()`` match while ``untruthful`` would not.
FORBIDDEN = re.compile(r"(?i)(?<![a-z0-9])(ground[_ ]?truth|truth|perturb(?:ation|ations|ed|s)?"
                       r"|bddl|obj_of_interest|check_success|benchmark_signals|env_success)(?![a-z0-9])")

PACKAGE = "phyagentos"
AGENT = "phyagentos.agent"


def _module_name(root: Path, path: Path) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _module_path(root: Path, name: str) -> Path | None:
    base = root.joinpath(*name.split("."))
    for cand in (base.with_suffix(".py"), base / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _docstring_nodes(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = getattr(node, "body", [])
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                ids.add(id(body[0].value))
    return ids


def _imports(tree: ast.AST, module: str, is_package: bool) -> list[tuple[int, str]]:
    """``(line, absolute module name)`` of every import in ``module`` (``from x import y``
    yields both ``x`` and ``x.y``, since ``y`` may be a submodule)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, a.name) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = module.split(".") if is_package else module.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join(pkg + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            out.append((node.lineno, base))
            out.extend((node.lineno, f"{base}.{a.name}") for a in node.names if a.name != "*")
    return out


def _findings(source: str, *, strict: bool) -> list[tuple[int, str]]:
    """Forbidden words in ``source``: ``strict`` (Agent modules) checks every string and
    comment; otherwise identifiers and whitespace-free string constants only."""
    tree = ast.parse(source)
    docstrings = _docstring_nodes(tree)
    found: list[tuple[int, str]] = []

    def hit(line: int, kind: str, text: str) -> None:
        if (m := FORBIDDEN.search(text)) is not None:
            found.append((line, f"{kind} {text[:60]!r} names {m.group(0)!r}"))

    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Name):
            hit(line, "name", node.id)
        elif isinstance(node, ast.Attribute):
            hit(line, "attribute", node.attr)
        elif isinstance(node, ast.arg):
            hit(line, "argument", node.arg)
        elif isinstance(node, ast.keyword) and node.arg:
            hit(line, "keyword", node.arg)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            hit(line, "definition", node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for alias in node.names:
                hit(line, "import", alias.name)
                if alias.asname:
                    hit(line, "import alias", alias.asname)
            if isinstance(node, ast.ImportFrom) and node.module:
                hit(line, "import from", node.module)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if strict or (id(node) not in docstrings and not re.search(r"\s", node.value)):
                hit(line, "docstring" if id(node) in docstrings else "string", node.value)
    if strict:
        for tok in tokenize.generate_tokens(io.StringIO(source).readline):
            if tok.type == tokenize.COMMENT:
                hit(tok.start[0], "comment", tok.string)
    return found


def check(root: Path) -> list[str]:
    """Every finding as ``path:line: message`` (empty when the boundary holds).

    Args:
        root: repository root holding the ``phyagentos`` package.
    """
    root = Path(root)
    agent_dir = root / PACKAGE / "agent"
    if not agent_dir.is_dir():
        return [f"{agent_dir}: no Agent plane package found"]
    problems: list[str] = []
    own: dict[str, list[tuple[int, str]]] = {}  # module -> its own findings (non-strict)
    deps: dict[str, set[str]] = {}  # module -> package modules it imports (outside the Agent plane)

    def load(name: str) -> bool:
        if name in own:
            return True
        target = _module_path(root, name)
        if target is None:
            return False
        source = target.read_text(encoding="utf-8")
        own[name] = _findings(source, strict=False)
        deps[name] = {sub for _, imp in _imports(ast.parse(source), name, target.name == "__init__.py")
                      if imp.startswith(PACKAGE + ".") and not imp.startswith(AGENT)
                      for sub in _with_parents(imp) if sub != name and _module_path(root, sub) is not None}
        return True

    def reach(start: str) -> list[tuple[str, list[str]]]:
        """Offending modules reachable from ``start`` with the import chain to each."""
        seen, out, queue = {start}, [], [(start, [start])]
        while queue:
            name, chain = queue.pop(0)
            if not load(name):
                continue
            if own[name]:
                out.append((name, chain))
            for sub in sorted(deps[name]):
                if sub not in seen:
                    seen.add(sub)
                    queue.append((sub, chain + [sub]))
        return out

    for path in sorted(agent_dir.rglob("*.py")):
        source = path.read_text(encoding="utf-8")
        rel = path.relative_to(root)
        problems.extend(f"{rel}:{line}: {msg}" for line, msg in _findings(source, strict=True))
        module = _module_name(root, path)
        reported: set[str] = set()
        for line, imported in _imports(ast.parse(source), module, path.name == "__init__.py"):
            if not imported.startswith(PACKAGE + ".") or imported.startswith(AGENT):
                continue
            for name in _with_parents(imported):
                for bad, chain in reach(name):
                    if (name, bad) in reported:
                        continue
                    reported.add((name, bad))
                    tline, msg = own[bad][0]
                    via = f" via {' -> '.join(chain[1:])}" if len(chain) > 1 else ""
                    target = _module_path(root, bad)
                    problems.append(f"{rel}:{line}: imports {name}{via}, which names it "
                                    f"({target.relative_to(root)}:{tline}: {msg})")
    return problems


def _with_parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(2, len(parts) + 1)]


def main(argv: list[str]) -> int:
    root = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parent.parent
    problems = check(root)
    for p in problems:
        print(p)
    if problems:
        print(f"ground-truth boundary BROKEN: {len(problems)} finding(s) in the Agent plane")
        return 1
    print("ground-truth boundary kept: no Agent-plane module names the privileged channel")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
