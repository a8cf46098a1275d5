"""Markers in an evidence directory through which the planes settle its RGB images.

The runner renders a session's images after its bundle is written
(:mod:`phyagentos.runtime.evidence_writer`); while they are owed the directory holds
:data:`PENDING_MARKER`. The Agent plane answers after its verdict with
:data:`PRUNED_MARKER` (a success whose images are not kept: skip them, delete any
written) or :data:`WANTED_MARKER` (render now), and waits for the images only when
it needs them (:func:`wait_for_images`). Plain files, so the planes never import
each other.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

__all__ = ["PENDING_MARKER", "PRUNED_MARKER", "WANTED_MARKER", "images_pending", "wait_for_images"]

PENDING_MARKER = ".images-pending"
PRUNED_MARKER = ".images-pruned"
WANTED_MARKER = ".images-wanted"


def images_pending(evidence_dir: str | os.PathLike[str]) -> bool:
    """True while the runner still owes images of ``evidence_dir``."""
    return (Path(evidence_dir) / PENDING_MARKER).exists()


def wait_for_images(evidence_dir: str | os.PathLike[str], *, timeout_s: float = 5.0) -> bool:
    """Ask for the images of ``evidence_dir`` now (:data:`WANTED_MARKER`) and block until
    they are written (True) or ``timeout_s`` passed (False: e.g. the runner was killed
    before it wrote them; the bundle then simply has no images)."""
    directory = Path(evidence_dir)
    if not (directory / PENDING_MARKER).exists():
        return True
    (directory / WANTED_MARKER).touch()
    deadline = time.monotonic() + timeout_s
    while (directory / PENDING_MARKER).exists():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True
