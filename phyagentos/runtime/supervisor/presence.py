"""Presence records of serving supervisors, for ``phyagentos status`` and the live view."""

from __future__ import annotations

import json
import os
from typing import Any

__all__ = ["PRESENCE_DIR", "read_presence"]

#: Each serving supervisor keeps ``<workspace>/.supervisors/<pid>-<tag>.json`` up to date
#: (owner, pid, runner pid, paused, e-stopped, current session), for ``phyagentos status``.
PRESENCE_DIR = ".supervisors"


def read_presence(workspace_root: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Presence records of the supervisors of a workspace, each with ``alive`` (its pid exists)."""
    out = []
    directory = os.path.join(os.fspath(workspace_root), PRESENCE_DIR)
    try:
        names = sorted(os.listdir(directory))
    except FileNotFoundError:
        return out
    for name in names:
        if not name.endswith(".json"):
            continue
        try:
            with open(os.path.join(directory, name), encoding="utf-8") as fh:
                data = json.load(fh)
        except (OSError, ValueError):
            continue
        try:
            os.kill(int(data.get("pid", -1)), 0)
            data["alive"] = True
        except (ProcessLookupError, ValueError, OverflowError):
            data["alive"] = False
        except PermissionError:
            data["alive"] = True
        out.append(data)
    return out
