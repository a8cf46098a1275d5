"""Counts of the hostile cases tried and handled well, per surface (issue 33's report).

Every hostile test (``tests/test_hostile_*.py``, the bench suite file tests) records each case
it tries with :func:`tally` (or the :func:`tallied` block) under the name of the surface it
attacks; a case is handled well when the test's own assertions about it hold. Counting never
replaces an assertion: the test still fails on a case handled badly, after counting it.

With ``PHYAGENTOS_FUZZ_REPORT=FILE`` the counts are written to FILE as JSON when the
process exits, ``{surface: {"tried": n, "handled_well": m}}``. A surface this process
tallied replaces that surface's entry in FILE and other entries are kept, so the hostile files
run one after another (each in its own ``pytest``) add up to one report -- so a surface name
belongs to one test file. Run it without ``pytest-xdist`` (``-p no:xdist``): workers would
each write a part of a surface. docs/security.md ("Measured") has the command and numbers.
"""

from __future__ import annotations

import atexit
import functools
import json
import os
from collections import Counter
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

TRIED: Counter = Counter()
GOOD: Counter = Counter()


def tally(surface: str, ok: bool) -> None:
    """Record one case tried against ``surface``; ``ok``: it was handled well."""
    TRIED[surface] += 1
    GOOD[surface] += bool(ok)


@contextmanager
def tallied(surface: str) -> Iterator[None]:
    """Count the block as one case of ``surface``: handled well when it raises nothing
    (its assertions hold); any exception is counted as handled badly and re-raised."""
    ok = False
    try:
        yield
        ok = True
    finally:
        tally(surface, ok)


def counted(surface: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorate a test so each call (each parameter set; under ``@given``, each example) is
    one :func:`tallied` case of ``surface``. Put it below ``@given``/``@pytest.mark``."""

    def decorate(test: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(test)
        def run(*args: Any, **kwargs: Any) -> Any:
            with tallied(surface):
                return test(*args, **kwargs)

        return run

    return decorate


def report() -> dict[str, dict[str, int]]:
    """This process's counts, by surface."""
    return {s: {"tried": TRIED[s], "handled_well": GOOD[s]} for s in sorted(TRIED)}


@atexit.register
def _write_report() -> None:
    target = os.environ.get("PHYAGENTOS_FUZZ_REPORT")
    if not target or not TRIED:
        return
    path = Path(target)
    try:
        merged = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    except (OSError, ValueError):
        merged = {}
    if not isinstance(merged, dict):
        merged = {}
    merged.update(report())
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps(dict(sorted(merged.items())), indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, path)
