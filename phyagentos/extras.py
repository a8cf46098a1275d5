"""Optional features and the extras that install them (pyproject's optional dependencies).

The core (``phyagentos run`` of a goal graph on a MuJoCo target, ``validate``, ``bench``)
imports none of them; each feature imports its package where it is first used, through
:func:`import_extra` (or :func:`missing_extra` for ``from ... import`` blocks), so a
missing package is a :class:`~phyagentos.errors.MissingExtraError` that says which extra
to install instead of a bare ``ModuleNotFoundError``. ``make demo`` / ``make test``
(``scripts/setup.sh``: ``pip install -e '.[test]'``) install every extra.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from phyagentos.errors import MissingExtraError

__all__ = ["EXTRAS", "import_extra", "missing_extra"]

#: Extra -> (what it enables, top-level modules it provides); pyproject.toml's
#: [project.optional-dependencies] (tests/test_extras.py keeps the two in step).
EXTRAS: dict[str, tuple[str, tuple[str, ...]]] = {
    "llm": ("language models (phyagentos.llm: llm.yaml, plan, --reviser model)", ("openai", "xllamacpp")),
    "fleet": ("the fleet over Eclipse Zenoh (router, edge, run --fleet)", ("zenoh",)),
    "mcp": ("the MCP server (phyagentos mcp)", ("mcp",)),
    "real": ("the real SO-101 on its Feetech bus (so101_real, calibrate, doctor)", ("scservo_sdk", "serial")),
    "view": ("the live web view (phyagentos view)", ("starlette", "uvicorn")),
    "game": ("the Crafter game target", ("crafter",)),
}


def _message(extra: str, module: str) -> str:
    what = EXTRAS[extra][0]
    return (f"{what} needs the Python package {module!r}, which is not installed; "
            f"install the extra: pip install 'phyagentos[{extra}]'")


def missing_extra(exc: ImportError, *, extra: str) -> MissingExtraError:
    """The error to raise for ``exc`` when it says one of ``extra``'s modules is missing.

    Raises:
        ImportError: ``exc`` itself when it is about something else (a broken install of a
            present package must not read as a missing one).
        KeyError: ``extra`` is not in :data:`EXTRAS`.
    """
    missing = (exc.name or "").split(".")[0]
    if missing not in EXTRAS[extra][1]:
        raise exc
    return MissingExtraError(_message(extra, missing), extra=extra, module=missing)


def import_extra(module: str, *, extra: str) -> ModuleType:
    """``importlib.import_module(module)``, or a :class:`MissingExtraError` naming ``extra``
    when one of that extra's packages is missing."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise missing_extra(exc, extra=extra) from exc
