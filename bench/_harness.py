"""The shared harness of the benchmarks in bench/ (a helper, not a benchmark: ``python -m bench`` skips ``_*``).

Every script in bench/ builds its command line, writes its result and computes its
percentiles here::

    from _harness import parser, percentile, write_json

    ap = parser(__doc__, "my_bench")          # --out PATH, default bench/results/my_bench.json
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    ...
    write_json(args.out, result)              # prints "wrote PATH"

Scripts run as ``python bench/NAME.py`` or ``python -m bench NAME`` (which runs the former
from the repository root); either way bench/ is the first entry of ``sys.path``, so the
plain ``from _harness import ...`` works, as ``from _supervisor_common import ...`` does.

- ``parser(doc, name, out=True)``: an ``argparse.ArgumentParser`` whose description is the
  first line of the module docstring ``doc``, with ``--out PATH`` (a ``Path``, default
  ``results_path(name)``) unless ``out=False``. That is the one flag the scripts share;
  their own (``--runs``, ``--seeds``, ``--workspace`` ...) differ in meaning and defaults.
- ``results_path(name, suffix=".json")``: ``bench/results/<name><suffix>`` (absolute).
- ``write_json(path, data, indent=2, say=True, **dumps)``: creates the parent folders,
  writes ``json.dumps(data, indent=indent, **dumps)`` plus a newline (UTF-8), prints
  ``wrote PATH`` (unless ``say`` is false, e.g. where stdout carries ``--json``), returns the path.
- ``percentile(values, q)``: the ``q``-th percentile (``q`` in 0..100) by linear
  interpolation between the closest ranks, which is numpy's default
  (``np.percentile(values, q)``); ``None`` for no values. ``median(values)`` is ``percentile(values, 50)``.
- ``markdown_table(head, rows, align=None) -> str`` and ``print_table(...)``: a Markdown
  table (``align``: one of ``"l"``/``"r"`` per column; default: left-aligned, ``---``).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
#: where the benchmarks write their results: ``bench/results``
RESULTS = HERE / "results"


def results_path(name: str, suffix: str = ".json") -> Path:
    """``bench/results/<name><suffix>`` (absolute: the result lands there whatever the working directory)."""
    return RESULTS / f"{name}{suffix}"


def description(doc: str | None) -> str | None:
    """The first non-empty line of a module docstring (what ``python -m bench list`` shows)."""
    lines = [line.strip() for line in (doc or "").strip().splitlines()]
    return lines[0] if lines and lines[0] else None


def parser(doc: str | None, name: str, *, out: bool = True) -> argparse.ArgumentParser:
    """The argument parser of benchmark ``name``: described by ``doc``'s first line, with ``--out``.

    ``out=False`` leaves ``--out`` out (a script that writes no JSON of its own, or whose
    ``--out`` means something else). The script adds its own arguments to the parser it gets.
    """
    ap = argparse.ArgumentParser(description=description(doc))
    if out:
        default = results_path(name)
        ap.add_argument("--out", type=Path, default=default, metavar="PATH",
                        help=f"where to write the result as JSON (default bench/results/{default.name})")
    return ap


def write_json(path: str | Path, data: Any, *, indent: int | None = 2, say: bool = True, **dumps: Any) -> Path:
    """Write ``data`` as JSON (``indent``, a trailing newline, UTF-8) to ``path``, creating its folders.

    Prints ``wrote PATH`` unless ``say`` is false; ``dumps`` go to ``json.dumps`` (e.g. ``default=str``).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=indent, **dumps) + "\n", encoding="utf-8")
    if say:
        print(f"wrote {path}", flush=True)
    return path


def percentile(values: Iterable[float], q: float) -> float | None:
    """The ``q``-th percentile (0 <= q <= 100) of ``values``, linear between the closest ranks.

    numpy's default method (``np.percentile(values, q)``), without importing numpy; ``None``
    when there are no values.
    """
    xs = sorted(float(v) for v in values)
    if not xs:
        return None
    if not 0 <= q <= 100:
        raise ValueError(f"percentile q={q} is outside 0..100")
    pos = (len(xs) - 1) * q / 100
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


def median(values: Iterable[float]) -> float | None:
    """``percentile(values, 50)`` (the mean of the middle two for an even count); ``None`` for no values."""
    return percentile(values, 50)


def markdown_table(head: Sequence[Any], rows: Iterable[Sequence[Any]], align: str | Sequence[str] | None = None) -> str:
    """A Markdown table: a header row, the separator row, one line per row (cells as ``str``).

    ``align`` gives one ``"l"`` or ``"r"`` per column (``"lrr"`` or ``["l", "r", "r"]``):
    ``---`` or ``---:``; by default every column is ``---``.
    """
    head = list(head)
    marks = ["---:" if a == "r" else "---" for a in (align or "l" * len(head))]
    if len(marks) != len(head):
        raise ValueError(f"align has {len(marks)} columns, head {len(head)}")
    lines = ["| " + " | ".join(map(str, head)) + " |", "|" + "|".join(marks) + "|"]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in rows]
    return "\n".join(lines)


def print_table(head: Sequence[Any], rows: Iterable[Sequence[Any]], align: str | Sequence[str] | None = None) -> None:
    """Print ``markdown_table(head, rows, align)``."""
    print(markdown_table(head, rows, align), flush=True)


def index_range(text: str) -> list[int]:
    """Indices written as ``"0-9"``, ``"1,3,5-7"`` (inclusive ranges, comma-separated).

    Raises:
        ValueError: a part that is not an integer or ``a-b``.
    """
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def with_overrides(config: Any, overrides_json: str | None) -> Any:
    """``config`` (a pydantic model, e.g. a target's ``PerceptionConfig``) with the sections of
    ``overrides_json`` (``'{"clustering": {"split_max_cost": 0}}'``) laid over its own, key by
    key, validated again; ``config`` itself when there are none.

    Raises:
        ValueError: the JSON does not parse, or the result does not validate (pydantic's message).
    """
    if not overrides_json:
        return config
    base = config.model_dump()
    for section, values in json.loads(overrides_json).items():
        base[section] = {**base.get(section, {}), **values}
    return type(config).model_validate(base)
