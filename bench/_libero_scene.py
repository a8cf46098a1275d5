"""The declared scene of a generated LIBERO world, as the LIBERO bench declares it (for the
benches that set objects by hand on scenes from LIBERO's placement sampler)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from phyagentos.bench.libero import _descriptors, _fixture_looks
from phyagentos.primitives.observation import make_perceiver
from phyagentos.targets.libero import LiberoScene, parse_bddl, resolve_task


def generated_scene(workspace: str | Path, suite: str, task: int, *,
                    where: Mapping[str, Mapping[str, Any]] | None = None) -> LiberoScene:
    """A generated (sampler) scene of LIBERO ``suite`` task ``task`` declaring the task's BDDL
    objects and fixtures with the looks of their categories (measured on generated scenes,
    cached in ``workspace``/libero) and, per object name in ``where``, its spatial reference."""
    ws = Path(workspace)
    (ws / "libero").mkdir(parents=True, exist_ok=True)
    looks = _descriptors(ws, suite, [task])
    fixture_looks = _fixture_looks(ws, suite, [task])
    declared = parse_bddl(resolve_task(suite, task).bddl_path).declared()
    where = where or {}
    objects = tuple({**o, **looks.get(o["class"], {}), **({"where": where[o["name"]]} if o["name"] in where else {})}
                    for o in declared["objects"])
    fixtures = tuple({**f, **fixture_looks[task].get(f["class"], {})} for f in declared["fixtures"])
    return LiberoScene(suite=suite, task=task, generated=True, objects=objects, fixtures=fixtures)


def fresh_perceiver(target, seed: int):
    """Generate the sampler's scene ``seed`` in ``target`` (a
    :class:`~phyagentos.targets.libero.LiberoTarget`) and return a new perceiver for it, with
    nothing remembered from the scene before."""
    target.generate_scene(seed)
    target.runtime_notes.pop("perception", None)
    return make_perceiver(target)
