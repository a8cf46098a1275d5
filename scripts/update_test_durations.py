"""Write ``tests/durations.json``: seconds per test file, from a ``pytest --durations=0`` log.

The suite runs one file per worker at a time (``--dist loadfile``); ``tests/conftest.py``
hands the files out longest first, so that a long file does not start last and leave the
other workers idle at the end (longest-processing-time-first scheduling, Graham 1969). The
figures only order the files: a stale or missing entry costs time, never a test.

Usage::

    .venv/bin/pytest -q -n 4 --dist loadfile --no-loadscope-reorder --durations=0 > /tmp/durations.log
    .venv/bin/python scripts/update_test_durations.py /tmp/durations.log
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "tests" / "durations.json"
_LINE = re.compile(r"^([0-9.]+)s (?:call|setup|teardown)\s+(tests/[^:]+\.py)::")


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    seconds: dict[str, float] = defaultdict(float)
    for line in Path(argv[0]).read_text().splitlines():
        m = _LINE.match(line)
        if m:
            seconds[Path(m.group(2)).name] += float(m.group(1))
    if not seconds:
        print(f"no '--durations=0' lines in {argv[0]}", file=sys.stderr)
        return 1
    table = {name: round(s, 1) for name, s in sorted(seconds.items(), key=lambda kv: (-kv[1], kv[0]))}
    OUT.write_text(json.dumps(table, indent=1) + "\n")
    print(f"wrote {OUT}: {len(table)} files, {sum(table.values()):.0f} test-seconds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
