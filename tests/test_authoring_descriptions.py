"""Skill and tree descriptions survive YAML (issue 11, item 4): in a flow mapping a comma
ends a value, so an unquoted ``{description: speed, in m/s}`` used to declare a second
key and cut the text that ``skills show`` and ``docs`` print. Every shipped skill and tree
loads with each description one string, and a split description is refused with the
file and line."""

from __future__ import annotations

import pytest

from phyagentos.cli import main
from phyagentos.errors import SkillError
from phyagentos.resources import skills_dir, trees_dir
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
from phyagentos.runtime.param_decls import PARAM_DECL_KEYS
from phyagentos.runtime.skills import SkillRegistry
from phyagentos.runtime.trees import TreeLibrary


def test_every_shipped_skill_and_tree_has_one_string_per_description():
    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    skills = [runtime.skills.get(n) for n in runtime.skills.names()]
    trees = [runtime.trees.spec(n) for n in runtime.trees.names()]
    assert len(skills) == len(list(skills_dir().glob("*.yaml"))) and len(trees) == len(list(trees_dir().glob("*.yaml")))
    for item in (*skills, *trees):
        assert isinstance(item.description, str) and item.description.strip(), item.path
        for name, decl in item.params.items():
            assert set(decl) <= set(PARAM_DECL_KEYS), (item.path, name, decl)
            assert isinstance(decl.get("description"), str) and decl["description"].strip(), (item.path, name)
    pick = runtime.skills.get("pick")
    assert pick.params["backoff_m"]["description"] == (
        "raise the hand this far before observing, clearing a previous attempt, in m (default 0)")


def test_a_description_split_by_a_comma_is_refused_with_file_and_line(tmp_path):
    skills = tmp_path / "skills"
    skills.mkdir()
    path = skills / "nudge.yaml"
    path.write_text("version: 1\nname: nudge\ndescription: Touch, then lift.\ntree: noop\nparams:\n"
                    "  height_m: {default: 0.1, description: approach height, m}\n", encoding="utf-8")
    with pytest.raises(SkillError, match=r"parameter 'height_m': unknown key 'm'.*quote it") as exc:
        SkillRegistry(skills)
    assert f"{path}:6" in str(exc.value)
    trees = tmp_path / "trees"
    trees.mkdir()
    tree = trees / "nudge.yaml"
    tree.write_text("version: 1\nname: nudge\nparams:\n  object: {required: true, description: the object, a cube}\n"
                    "root: {primitive: observe}\n", encoding="utf-8")
    with pytest.raises(SkillError, match=r"parameter 'object': unknown key 'a cube'.*quote it") as exc:
        TreeLibrary(trees, primitives={}).spec("nudge")
    assert f"{tree}:4" in str(exc.value)


def test_skills_show_prints_the_whole_description(capsys):
    assert main(["skills", "show", "pick"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "fraction of the joint limits (default 0.3)" in out
