"""Simulated world state on disk: one ``.npz`` per target.

Every MuJoCo-backed target (Franka tabletop, SO-101, FrankaKitchen) carries its
state between sessions and processes the same way; this module is that one way.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from phyagentos.errors import TargetError

__all__ = ["read_state_npz"]


def read_state_npz(path: str | os.PathLike, *, content: bytes | None = None) -> dict[str, np.ndarray]:
    """Read every array of a target state file.

    Writers build their own npz layout and write it with
    :func:`phyagentos.protocol.atomic.atomic_write_bytes`.

    Args:
        path: the file (named in errors).
        content: its bytes, already read by the caller (e.g. to hash exactly what is
            parsed); None reads ``path``.

    Raises:
        TargetError: the file is missing or is not a readable npz.
    """
    p = Path(path)
    try:
        with np.load(io.BytesIO(content) if content is not None else p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError as exc:
        raise TargetError(f"state file {p} does not exist") from exc
    except Exception as exc:
        raise TargetError(f"state file {p} is not a readable npz: {exc}") from exc
