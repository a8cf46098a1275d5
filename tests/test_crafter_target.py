"""The Crafter game target: what the player sees is what the picture shows, nothing more."""

from __future__ import annotations

import numpy as np
import pytest

crafter = pytest.importorskip("crafter")

from phyagentos.primitives import PRIMITIVES  # noqa: E402
from phyagentos.primitives.context import SkillContext  # noqa: E402
from phyagentos.resources import skills_dir, trees_dir  # noqa: E402
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: E402
from phyagentos.targets.crafter import CRAFTER_ACTIONS, VIEW_COLS, VIEW_ROWS, CrafterScene, CrafterTarget  # noqa: E402


def test_the_manifest_offers_the_17_actions_and_observe():
    assert len(CRAFTER_ACTIONS) == 17
    assert set(CrafterTarget.TOOLS) == set(CRAFTER_ACTIONS) | {"observe", "snapshot"}
    assert CrafterTarget.KIND == "game"


def test_the_local_view_is_what_the_picture_is_painted_from():
    # Decode the rendered 9 x 7 view cell by cell against Crafter's own textures (in full
    # daylight the picture is the textures themselves) and compare with observe().
    target = CrafterTarget("crafter", seed=7)
    for _ in range(12):
        target.act("move_left")
    env = target._env
    env._world.daylight = 1.0
    obs = target.observe()
    unit = 16
    canvas = env._local_view(env._player, np.array((unit, unit)))  # (x, y, 3)
    materials = ["water", "grass", "stone", "path", "sand", "tree", "lava", "coal", "iron", "diamond", "table",
                 "furnace"]
    templates = {m: env._textures.get(m, (unit, unit))[..., :3] for m in materials}
    with_objects = {(o["dx"] + VIEW_COLS // 2, o["dy"] + VIEW_ROWS // 2) for o in obs["objects"]} | {
        (VIEW_COLS // 2, VIEW_ROWS // 2)}  # the player is drawn on its own cell
    checked = 0
    for r in range(VIEW_ROWS):
        for c in range(VIEW_COLS):
            block = canvas[c * unit:(c + 1) * unit, r * unit:(r + 1) * unit]
            exact = [m for m, t in templates.items() if np.array_equal(block, t)]
            if (c, r) in with_objects:
                assert exact == [], f"an object drawn at {(c, r)} left the texture bare"
            elif obs["view"][r][c] == "void":
                assert (block == 127).all()
            else:
                assert exact == [obs["view"][r][c]], (r, c, exact, obs["view"][r][c])
                checked += 1
    assert checked >= 40


def test_the_view_does_not_depend_on_the_world_outside_the_window():
    target = CrafterTarget("crafter", seed=3)
    before = target.observe()
    world = target._env._world
    x, y = target._env._player.pos
    water = world._mat_ids["water"]
    world._mat_map[:, : max(0, y - VIEW_ROWS // 2 - 1)] = water   # rows above the window
    world._mat_map[x + VIEW_COLS // 2 + 1:, :] = water            # columns right of the window
    assert target.observe()["view"] == before["view"]
    world._mat_map[x + 1, y] = water                              # inside: the player sees it
    assert target.observe()["view"][VIEW_ROWS // 2][VIEW_COLS // 2 + 1] == "water"


def test_the_night_hides_the_edges_of_the_view():
    target = CrafterTarget("crafter", seed=3)
    target.observe()  # the world is generated on first use
    target._env._world.daylight = 0.0
    view = target.observe()["view"]
    assert view[0][0] == "dark" and view[VIEW_ROWS // 2][VIEW_COLS // 2] != "dark"


def test_state_round_trips_and_the_game_goes_on_identically(tmp_path):
    a = CrafterTarget("crafter", CrafterScene(), seed=11)
    for act in ["move_left", "do", "move_up", "do", "noop"] * 10:
        a.act(act)
    a.notes["probe"] = 1
    a.save_state(tmp_path / "state.npz")
    b = CrafterTarget("crafter", CrafterScene(), seed=99)
    b.load_state(tmp_path / "state.npz")
    assert b.observe() == a.observe() and b.notes == {"probe": 1}
    rng = np.random.default_rng(0)
    for i in rng.integers(0, 17, size=300):
        a.act(CRAFTER_ACTIONS[i]) if not a.done else None
        b.act(CRAFTER_ACTIONS[i]) if not b.done else None
    assert a.observe() == b.observe()
    assert (tmp_path / "ground_truth.yaml").is_file()


def _play(seed: int) -> tuple[dict, list]:
    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    target = CrafterTarget("crafter", seed=seed)
    snaps = []
    for skill, params in [("game_collect", {"material": "tree", "item": "wood", "count": 3}),
                          ("game_place", {"item": "table"}),
                          ("game_make", {"item": "wood_pickaxe"})]:
        ctx = SkillContext(target=target, params=params, seed=seed)
        outcome = runtime.run(skill, ctx, deadline=float("inf"))
        assert outcome.status == "completed", outcome
        snaps.append(target.snapshot())
    return target.observe(), snaps


@pytest.mark.parametrize("seed", range(4))
def test_a_restored_game_despawns_the_same_creatures(tmp_path, seed):
    """Crafter picks the creature to despawn by index into a chunk's members; with
    id()-ordered sets a restored game (new addresses) drifted within ~1000 steps."""
    rng = np.random.default_rng(seed)
    a = CrafterTarget("crafter", CrafterScene(), seed=seed)
    for i in rng.integers(0, 17, size=100):
        a.act(CRAFTER_ACTIONS[i]) if not a.done else None
    a.save_state(tmp_path / "state.npz")
    ballast = [object() for _ in range(1000)]  # shift the allocator before the restore
    b = CrafterTarget("crafter", CrafterScene(), seed=99)
    b.load_state(tmp_path / "state.npz")
    for i in rng.integers(0, 17, size=1500):
        a.act(CRAFTER_ACTIONS[i]) if not a.done else None
        b.act(CRAFTER_ACTIONS[i]) if not b.done else None
    assert ballast and a.observe() == b.observe()


def test_withholding_the_semantic_map_changes_nothing(monkeypatch):
    # Crafter computes info['semantic'] (the whole world) on every step; replace it with
    # garbage and the same seeded skills must see and do exactly the same.
    normal = _play(5)
    monkeypatch.setattr(crafter.engine.SemanticView, "__call__", lambda self: np.full((64, 64), 255, np.uint8))
    withheld = _play(5)
    assert normal == withheld
    assert "make_wood_pickaxe" in normal[0]["achievements"]
    assert set(PRIMITIVES) >= {"game_collect", "game_place", "game_make", "game_survive"}
