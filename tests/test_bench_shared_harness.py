"""bench/_harness.py is the one harness of the benchmarks: every script's parser, JSON and percentiles."""

from __future__ import annotations

import ast
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
# loaded from its file: bench/ on this process's sys.path would shadow packages (bench/crafter.py: the game)
_spec = importlib.util.spec_from_file_location("bench_harness", BENCH / "_harness.py")
harness = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(harness)
markdown_table, median, parser, percentile = harness.markdown_table, harness.median, harness.parser, harness.percentile
results_path, write_json = harness.results_path, harness.write_json

SCRIPTS = sorted(p for p in BENCH.glob("*.py") if not p.stem.startswith("_"))

# One interpreter runs every script's ``--help`` as ``python bench/NAME.py --help`` would
# (bench/ first on sys.path, run as __main__): 37 fresh interpreters take about a minute on a loaded 2-core machine.
_DRIVER = r"""
import contextlib, io, json, runpy, sys
results = {}
saved = list(sys.path)
for script in sys.argv[1:]:
    sys.path[:] = [script.rsplit("/", 1)[0], *saved[1:]]
    sys.argv = [script, "--help"]
    out = io.StringIO()
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        code = exc.code or 0
    except BaseException as exc:
        code = f"{type(exc).__name__}: {exc}"
    results[script] = {"code": code, "output": out.getvalue()[:20000]}
sys.path[:] = saved
print(json.dumps(results))
"""


def _tree(script: Path) -> ast.Module:
    return ast.parse(script.read_text(encoding="utf-8"))


def _parses_arguments(script: Path) -> bool:
    return any(isinstance(n, ast.Attribute) and n.attr == "parse_args" for n in ast.walk(_tree(script)))


@pytest.fixture(scope="module")
def helps() -> dict:
    proc = subprocess.run([sys.executable, "-c", _DRIVER, *map(str, SCRIPTS)], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_every_script_answers_help(helps, script):
    got = helps[str(script)]
    assert got["code"] == 0, got["output"]
    if _parses_arguments(script):
        assert "usage:" in got["output"] and "--help" in got["output"], got["output"]


def test_a_script_runs_as_its_own_process_too():
    """``python bench/crafter.py`` takes bench/ off sys.path (it is named like the game): the harness came first."""
    proc = subprocess.run([sys.executable, str(BENCH / "crafter.py"), "--help"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0 and "--out PATH" in proc.stdout, proc.stderr[-2000:]


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_no_script_builds_its_own_parser_or_edits_the_import_path(script):
    tree = _tree(script)
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    names = [ast.unparse(c.func) for c in calls]
    assert not [n for n in names if n.endswith("ArgumentParser")], f"{script.name}: use _harness.parser"
    assert not [n for n in names if n.startswith("sys.path.")], f"{script.name}: bench/ is already sys.path[0]"
    if _parses_arguments(script):
        harness = {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module == "_harness"
                   for a in n.names}
        assert "parser" in harness, f"{script.name} parses arguments with a parser not from _harness"


def test_no_script_keeps_its_own_percentile():
    for script in SCRIPTS:
        defs = {n.name for n in ast.walk(_tree(script)) if isinstance(n, ast.FunctionDef)}
        assert not defs & {"percentile", "_percentile", "quantile", "median", "_median"}, script.name


@pytest.mark.parametrize("values", [[3.0], [1.0, 2.0], [5.0, 1.0, 4.0, 2.0, 3.0], list(np.random.default_rng(0).
                                    normal(size=101)), list(np.random.default_rng(1).exponential(size=40))])
@pytest.mark.parametrize("q", [0, 1, 10, 50, 90, 95, 99, 100])
def test_percentile_is_numpys_default(values, q):
    assert percentile(values, q) == pytest.approx(float(np.percentile(values, q)), rel=1e-12, abs=1e-12)
    assert median(values) == pytest.approx(float(np.median(values)))


def test_percentile_of_nothing_is_none_and_q_is_a_percent():
    assert percentile([], 50) is None and median([]) is None
    with pytest.raises(ValueError):
        percentile([1.0], 150)


def test_parser_describes_by_the_first_docstring_line_and_writes_under_results():
    ap = parser("First line.\n\nMore.", "some_bench")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args([])
    assert ap.description == "First line." and args.out == results_path("some_bench") and args.runs == 3
    assert results_path("some_bench") == BENCH / "results" / "some_bench.json"
    assert not hasattr(parser(None, "x", out=False).parse_args([]), "out")


def test_write_json_makes_folders_ends_with_a_newline_and_says_so(tmp_path, capsys):
    path = write_json(tmp_path / "a" / "b.json", {"k": [1, 2]}, indent=1)
    assert path.read_text(encoding="utf-8") == '{\n "k": [\n  1,\n  2\n ]\n}\n'
    assert capsys.readouterr().out == f"wrote {path}\n"
    write_json(tmp_path / "c.json", {}, say=False)
    assert capsys.readouterr().out == ""


def test_markdown_table():
    assert markdown_table(("a", "b"), [(1, "x"), ("y", 2.5)], "lr") == "| a | b |\n|---|---:|\n| 1 | x |\n| y | 2.5 |"
    assert markdown_table(("a",), []) == "| a |\n|---|"


def test_config_overrides_are_laid_over_each_section_key_by_key_and_validated():
    import pytest
    from pydantic import ValidationError

    from phyagentos.perception import PerceptionConfig

    base = PerceptionConfig()
    assert harness.with_overrides(base, None) is base and harness.with_overrides(base, "") is base
    got = harness.with_overrides(base, '{"clustering": {"split_max_cost": 0}}')
    assert got.clustering.split_max_cost == 0
    # the other keys of the section and the other sections are the config's own
    assert got.clustering.model_dump(exclude={"split_max_cost"}) == base.clustering.model_dump(exclude={"split_max_cost"})
    assert got.association == base.association
    with pytest.raises(ValidationError):
        harness.with_overrides(base, '{"clustering": {"split_max_cost": "lots"}}')
