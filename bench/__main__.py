"""The one entry point of the benchmarks in bench/.

    .venv/bin/python -m bench list                 # every benchmark, with its first docstring line
    .venv/bin/python -m bench NAME [ARGS ...]      # one benchmark, ARGS passed to it (NAME --help)
    .venv/bin/python -m bench all [--only NAME ...]  # every benchmark with its defaults (`make bench`)

Each benchmark runs in a fresh interpreter from the repository root, prints its table and
writes ``bench/results/<name>.json``. Suites of goal-graph episodes run through
``phyagentos bench <suite>``; the scripts here measure everything else (and
``bench_suites`` runs those suites). The exit code is the benchmark's (``all``: non-zero
if any failed; 2 for an unknown name, with the valid ones listed).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Helpers, not benchmarks: ``_*.py`` (shared code) and the package files.
_NOT_BENCHMARKS = {"__init__", "__main__"}


def benchmarks() -> dict[str, Path]:
    """Benchmark name -> script, sorted by name."""
    return {p.stem: p for p in sorted(HERE.glob("*.py")) if p.stem not in _NOT_BENCHMARKS and not p.stem.startswith("_")}


def summary(script: Path) -> str:
    """The first line of ``script``'s module docstring (empty when it has none)."""
    try:
        doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or ""
    except SyntaxError:
        return ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def run(script: Path, args: list[str]) -> int:
    return subprocess.call([sys.executable, str(script), *args], cwd=HERE.parent)


def run_all(only: list[str]) -> int:
    scripts = benchmarks()
    unknown = sorted(set(only) - set(scripts))
    if unknown:
        print(f"unknown benchmark(s) {', '.join(unknown)}; valid: {', '.join(scripts)}", file=sys.stderr)
        return 2
    failed = []
    for name, script in scripts.items():
        if only and name not in only:
            continue
        print(f"\n== {name} ==", flush=True)
        t0 = time.perf_counter()
        rc = run(script, [])
        print(f"-- {name}: exit {rc} in {time.perf_counter() - t0:.1f} s", flush=True)
        if rc != 0:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    scripts = benchmarks()
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    name, rest = argv[0], argv[1:]
    if name == "list":
        width = max(map(len, scripts))
        for n, script in scripts.items():
            print(f"{n:<{width}}  {summary(script)}")
        return 0
    if name == "all":
        only = rest[1:] if rest[:1] == ["--only"] else rest
        return run_all(only)
    if name not in scripts:
        print(f"unknown benchmark {name!r}; valid: list, all, {', '.join(scripts)}", file=sys.stderr)
        return 2
    return run(scripts[name], rest)


if __name__ == "__main__":
    raise SystemExit(main())
