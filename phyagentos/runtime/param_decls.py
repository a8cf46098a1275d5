"""Parameter declarations of skill manifests and tree files (``params:``).

Each declared parameter maps to ``{required, default, description, example}``. In a
YAML flow mapping a comma ends a value, so ``{description: speed, in m/s}`` silently
declares a second key ``in m/s``; :func:`check_param_decls` refuses that (and any other
unknown key, or a description that is not one string) with the file and line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from phyagentos.errors import SkillError, format_choices
from phyagentos.yamlsource import SourceMap, excerpt, line_of

__all__ = ["PARAM_DECL_KEYS", "check_param_decls"]

#: Keys a parameter declaration may hold.
PARAM_DECL_KEYS: tuple[str, ...] = ("required", "default", "description", "example")


def check_param_decls(params: Any, *, path: Path, line: int | None) -> dict[str, dict[str, Any]]:
    """Validate a ``params:`` mapping; return it as ``{name: {key: value}}``.

    Args:
        params: the parsed ``params`` value (``None`` for none).
        path: the skill or tree file, for messages.
        line: 1-based line of ``params:`` (used when a declaration carries none).

    Raises:
        SkillError: ``params`` not a mapping of names to mappings, an unknown key in a
            declaration (with a hint when a comma split a description), a
            ``description`` that is not a string, or ``required`` that is not a boolean.
    """
    if params is None:
        return {}
    if not isinstance(params, dict):
        raise SkillError("'params' must map names to {required, default, description, example}", path=path, line=line)
    out: dict[str, dict[str, Any]] = {}
    for name, decl in params.items():
        where = line_of(params, name) or line
        if decl is None:
            out[name] = {}
            continue
        if not isinstance(decl, dict):
            raise SkillError(f"parameter {name!r} must be a mapping with keys {format_choices(PARAM_DECL_KEYS)}, "
                             f"got {excerpt(decl)}", path=path, line=where)
        for key, value in decl.items():
            if key not in PARAM_DECL_KEYS:
                hint = ""
                if value is None and "description" in decl:
                    hint = ("; a comma inside {...} ends the description: quote it "
                            "(description: \"speed, in m/s\")")
                raise SkillError(f"parameter {name!r}: unknown key {excerpt(key)}; valid keys: "
                                 f"{format_choices(PARAM_DECL_KEYS)}{hint}", path=path,
                                 line=(decl.key_line(key) if isinstance(decl, SourceMap) else where))
        if "description" in decl and not isinstance(decl["description"], str):
            raise SkillError(f"parameter {name!r}: description must be one string, got {excerpt(decl['description'])}",
                             path=path, line=where)
        if "required" in decl and not isinstance(decl["required"], bool):
            raise SkillError(f"parameter {name!r}: required must be true or false, got {excerpt(decl['required'])}",
                             path=path, line=where)
        out[name] = dict(decl)
    return out
