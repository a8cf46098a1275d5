"""Crafter (Hafner, ICLR 2022) as a ``kind: game`` rollout target.

The adapter wraps the real ``crafter.Env`` (every action goes through its own ``step``:
its world generation, creature updates, chunk balancing and achievement bookkeeping) and
exposes the 17 Crafter actions as operations of its TargetToolManifest, plus
``observe`` and ``snapshot``.

What a player can know, and nothing else, is what :meth:`CrafterTarget.observe` returns:

- ``view``: the local view, 7 rows (top to bottom) of 9 cell names, in the player's
  frame (the player stands at row 3, column 4; column +1 is "right", row +1 is "down",
  the directions of ``move_right`` / ``move_down``). Names are Crafter's materials
  (``grass``, ``tree``, ``water`` ...), ``void`` for cells outside the world (drawn
  grey) and ``dark`` for cells the night hides (below);
- ``objects``: the creatures and items drawn over the view, ``{name, dx, dy}`` relative
  to the player (``cow``, ``zombie``, ``skeleton``, ``arrow``, ``plant``, ``plant_ripe``);
- ``inventory`` (items) and ``vitals`` (health, food, drink, energy): Crafter draws
  them in the two rows under the view;
- ``daylight`` in [0, 1] (the image's brightness), ``sleeping``, ``facing``;
- ``position``: odometry, the player's displacement from where the world began, in
  cells (x right, y down): the player knows each of its moves and sees the view scroll;
- ``step``: actions taken so far; ``achievements``: the ones unlocked (the player's own
  record of what it did).

Why the local view is the crop of the world's maps to the 9 x 7 window, and why that is
what the image shows: Crafter's ``LocalView.__call__`` draws exactly the cells
``player.pos + (x, y) - (4, 3)`` for x in 0..8, y in 0..6 (the top 7 of the 9 x 9 unit
grid; the bottom 2 rows are the inventory), each as its material's texture, then every
object whose position falls in that window, alpha-blended on top; cells outside the
world stay grey (127). So reading the world's material and object maps inside that
window gives the same symbols the picture is painted from, no more (a test decodes the
rendered image against Crafter's own textures and checks equality in daylight). At
night Crafter mixes per-pixel noise into the picture with a vignette:
``night = (1 - m) * canvas + m * noise`` with ``m = 2 (0.5 - daylight) * vignette``
(``vignette = 1 - exp(-r^2 / (2 * 0.5^2))`` over the view, r in [-1, 1]), then
desaturates and tints it half-way to dark blue, and shows
``daylight * canvas + (1 - daylight) * night``. The share of the texture left in a cell
is then ``daylight + (1 - daylight) * (1 - m) / 2``; a cell whose share at its centre is
below :data:`DARK_TEXTURE_SHARE` is reported ``dark`` (its material and objects are
withheld), so the night hides what the picture hides.

The full world map (``info['semantic']``) is never read. Ground truth for scoring (the
environment's achievement counters, health, the absolute position, whether the episode
ended) is written beside the state file as ``ground_truth.yaml`` and never enters an
observation or a snapshot.
"""

from __future__ import annotations

import io
import logging
import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from phyagentos.errors import TargetError, format_choices
from phyagentos.extras import import_extra
from phyagentos.protocol.atomic import atomic_write_bytes, atomic_write_text
from phyagentos.yamlsource import load_plain

from ..base import BaseRolloutTarget, ExecutionResult
from ..contract import RendersImages, TargetCapabilities
from ..state_file import read_state_npz

__all__ = ["CrafterScene", "CrafterTarget", "CRAFTER_ACTIONS", "CRAFTER_ACHIEVEMENTS", "VIEW_COLS", "VIEW_ROWS",
           "DARK_TEXTURE_SHARE", "VITALS"]

log = logging.getLogger(__name__)

#: Crafter's 17 actions, in its own order (``crafter/data.yaml``).
CRAFTER_ACTIONS: tuple[str, ...] = (
    "noop", "move_left", "move_right", "move_up", "move_down", "do", "sleep", "place_stone", "place_table",
    "place_furnace", "place_plant", "make_wood_pickaxe", "make_stone_pickaxe", "make_iron_pickaxe",
    "make_wood_sword", "make_stone_sword", "make_iron_sword")
#: Crafter's 22 achievements (``crafter/data.yaml``).
CRAFTER_ACHIEVEMENTS: tuple[str, ...] = (
    "collect_coal", "collect_diamond", "collect_drink", "collect_iron", "collect_sapling", "collect_stone",
    "collect_wood", "defeat_skeleton", "defeat_zombie", "eat_cow", "eat_plant", "make_iron_pickaxe",
    "make_iron_sword", "make_stone_pickaxe", "make_stone_sword", "make_wood_pickaxe", "make_wood_sword",
    "place_furnace", "place_plant", "place_stone", "place_table", "wake_up")
#: The inventory entries that are vitals (drawn as hearts, food, drops, energy).
VITALS: tuple[str, ...] = ("health", "food", "drink", "energy")
#: The local view: 9 columns by 7 rows (Crafter's 9 x 9 grid less 2 inventory rows).
VIEW_COLS, VIEW_ROWS = 9, 7
#: Below this share of its texture at a cell's centre a cell counts as hidden by the night.
DARK_TEXTURE_SHARE = 0.15
_STATE_FORMAT = 1
_FACING = {(-1, 0): "left", (1, 0): "right", (0, -1): "up", (0, 1): "down"}


@dataclass(frozen=True)
class CrafterScene:
    """What a Crafter session asks of the game.

    Attributes:
        area: world size in cells (Crafter's default 64 x 64).
        length: episode length in steps (Crafter's default 10000); the game ends there.
        size: rendered image size in pixels (Crafter's default 64 x 64; only evidence images).
    """

    area: tuple[int, int] = (64, 64)
    length: int = 10000
    size: tuple[int, int] = (64, 64)

    def __post_init__(self) -> None:
        for key in ("area", "size"):
            v = tuple(int(x) for x in getattr(self, key))
            if len(v) != 2 or min(v) < 9:
                raise TargetError(f"crafter scene: {key} must be two integers >= 9, got {getattr(self, key)!r}")
            object.__setattr__(self, key, v)
        if not isinstance(self.length, int) or self.length < 1:
            raise TargetError(f"crafter scene: length must be an integer >= 1, got {self.length!r}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "CrafterScene":
        """Build from plain data; unknown keys raise TargetError listing the valid ones."""
        d = dict(d or {})
        valid = tuple(cls.__dataclass_fields__)
        unknown = set(d) - set(valid)
        if unknown:
            raise TargetError(f"crafter scene: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(valid)}")
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        return {"area": list(self.area), "length": self.length, "size": list(self.size)}

    @property
    def object_names(self) -> tuple[str, ...]:
        return ()


def _vignette_centres() -> np.ndarray:
    """(7, 9) Crafter's night vignette at each cell centre (``LocalView._vignette``, stddev 0.5)."""
    xs = -1 + 2 * (np.arange(VIEW_COLS) + 0.5) / VIEW_COLS
    ys = -1 + 2 * (np.arange(VIEW_ROWS) + 0.5) / VIEW_ROWS
    r2 = xs[None, :] ** 2 + ys[:, None] ** 2
    return 1 - np.exp(-0.5 * r2 / 0.25)


_VIGNETTE = _vignette_centres()


def texture_share(daylight: float) -> np.ndarray:
    """(7, 9) share of each cell's own texture in the picture at ``daylight`` (module doc)."""
    d = float(daylight)
    m = 2 * (0.5 - d) * _VIGNETTE if d < 0.5 else np.zeros_like(_VIGNETTE)
    return d + (1 - d) * (1 - m) / 2


class _ChunkMembers:
    """The creatures of one Crafter chunk, iterated in insertion order.

    Crafter keeps them in a ``set``, whose order follows the objects' ``id()``: its chunk
    balancing (``Env._balance_object``) picks the creature to despawn by index into that
    order, so a restored state (new addresses) or another process diverged from the same
    seed. This stand-in offers the ``add`` / ``remove`` / iteration / ``len`` the engine
    uses, with a deterministic order that pickling preserves.
    """

    __slots__ = ("_members",)

    def __init__(self, members=()):
        self._members = dict.fromkeys(members)

    def add(self, obj) -> None:
        self._members[obj] = None

    def remove(self, obj) -> None:
        del self._members[obj]  # KeyError for a stranger, as set.remove

    def discard(self, obj) -> None:
        self._members.pop(obj, None)

    def __iter__(self):
        return iter(list(self._members))

    def __len__(self) -> int:
        return len(self._members)

    def __contains__(self, obj) -> bool:
        return obj in self._members

    def copy(self) -> "_ChunkMembers":
        return _ChunkMembers(self._members)

    def __getstate__(self):
        return list(self._members)

    def __setstate__(self, members) -> None:
        self._members = dict.fromkeys(members)


def _order_chunks(world) -> None:
    """Replace ``world._chunks`` (chunk -> set of objects) by insertion-ordered members,
    each chunk's objects ordered by their index in ``world._objects`` (a list, so the
    same for the same seed)."""
    import collections  # noqa: PLC0415

    chunks = world._chunks
    if isinstance(chunks.default_factory, type) and chunks.default_factory is _ChunkMembers:
        return
    rank = {id(obj): i for i, obj in enumerate(world._objects) if obj is not None}
    ordered = collections.defaultdict(_ChunkMembers)
    for key, members in chunks.items():
        ordered[key] = _ChunkMembers(sorted(members, key=lambda o: rank.get(id(o), len(rank))))
    world._chunks = ordered


class CrafterTarget(BaseRolloutTarget, RendersImages):
    """The Crafter game behind the rollout-target contract.

    Args:
        name: target name (TARGETS.md).
        scene: a :class:`CrafterScene`.
        seed: generates the world (``crafter.Env(seed=...)``); ``reset(seed=)`` replaces it.

    Class attributes (read by preflight without constructing a target): ``KIND``,
    ``TOOLS`` (the 17 actions, ``observe``, ``snapshot``), ``ACTION_FORMS``.
    """

    KIND = "game"
    TOOLS = CRAFTER_ACTIONS + ("observe", "snapshot")
    CAPABILITIES = TargetCapabilities(action_forms=("game_action",), sensors=("symbolic_view",),
                                      simulated_ground_truth=True)

    @staticmethod
    def scene_from_dict(d: Mapping[str, Any] | None, *, root: Any = None) -> CrafterScene:
        return CrafterScene.from_dict(d)

    def __init__(self, name: str, scene: CrafterScene | None = None, *, seed: int | None = None):
        super().__init__(name, "game")
        self.scene = scene if scene is not None else CrafterScene()
        self._env = None
        self._seed = 0 if seed is None else int(seed)
        self._spawn = np.zeros(2, dtype=int)
        self.notes: dict[str, Any] = {}  # the player's own notebook (remembered map), kept with the state
        self._done = False
        self._fresh = True  # not yet stepped: reset(seed) of the same seed is a no-op
        self._env = self._new_env(self._seed)
        self._generated = False  # the world is generated on first use (load_state never needs it)

    # -- game ---------------------------------------------------------------------
    def _new_env(self, seed: int):
        crafter = import_extra("crafter", extra="game")  # heavy: only for game targets

        return crafter.Env(area=self.scene.area, view=(9, 9), size=self.scene.size, reward=False,
                           length=self.scene.length, seed=int(seed))

    def _ensure(self) -> None:
        if not self._generated:
            self._env.reset()  # Crafter's world generation for this env's seed
            _order_chunks(self._env._world)
            self._spawn = np.array(self._env._player.pos, dtype=int)
            self._generated = True

    def reset(self, *, seed: int | None = None) -> dict:
        """Generate the world of ``seed`` (Crafter's own generator) and return :meth:`observe`."""
        if seed is None or int(seed) != self._seed or not self._fresh:
            if seed is not None:
                self._seed = int(seed)
            self._env = self._new_env(self._seed)
            self._generated = False
        self._fresh = True
        self._done = False
        self.notes = {}
        return self.observe()

    @property
    def player(self):
        self._ensure()
        return self._env._player

    @property
    def done(self) -> bool:
        """The episode is over (the player died or the step budget is spent)."""
        return self._done

    @property
    def sim_time(self) -> float:
        """Game steps taken (Crafter has no wall-clock time)."""
        return float(self._env._step or 0)

    def act(self, action: str) -> None:
        """Apply one Crafter action (a name of :data:`CRAFTER_ACTIONS`) for one game step.

        Raises:
            TargetError: unknown action, or the episode is over.
        """
        try:
            index = CRAFTER_ACTIONS.index(action)
        except ValueError:
            raise TargetError(f"unknown Crafter action {action!r}; valid actions: {format_choices(CRAFTER_ACTIONS)}") from None
        if self._done:
            raise TargetError(f"target {self.name!r}: the episode is over (step {self.sim_time:.0f})")
        self._ensure()
        _, _, done, _ = self._env.step(index)
        self._fresh = False
        self._done = bool(done)

    def step(self, ctrl) -> None:
        """One game step: ``ctrl`` is an action name or its index in :data:`CRAFTER_ACTIONS`."""
        self.act(CRAFTER_ACTIONS[int(ctrl)] if isinstance(ctrl, (int, np.integer)) else str(ctrl))

    def execute_trajectory(self, traj, *, tracking_tol_rad: float) -> ExecutionResult:
        raise TargetError(f"target {self.name!r} is a game: it has no arm to stream a joint trajectory to")

    # -- what the player knows ------------------------------------------------------
    def observe(self) -> dict:
        """The player's observation (module doc): ``view`` (7 x 9 names), ``objects``,
        ``inventory``, ``vitals``, ``daylight``, ``sleeping``, ``facing``, ``position``
        (odometry, cells), ``step``, ``achievements``, ``done``."""
        self._ensure()
        env = self._env
        world, player = env._world, env._player
        share = texture_share(world.daylight)
        centre = np.array(player.pos)
        x0, y0 = int(centre[0]) - VIEW_COLS // 2, int(centre[1]) - VIEW_ROWS // 2
        W, H = world.area
        view: list[list[str]] = []
        for r in range(VIEW_ROWS):
            row = []
            for c in range(VIEW_COLS):
                x, y = x0 + c, y0 + r
                if not (0 <= x < W and 0 <= y < H):
                    row.append("void")
                elif share[r, c] < DARK_TEXTURE_SHARE:
                    row.append("dark")
                else:
                    row.append(world._mat_names[int(world._mat_map[x, y])])
            view.append(row)
        objects = []
        for obj in world.objects:
            if obj is player:
                continue
            c, r = int(obj.pos[0]) - x0, int(obj.pos[1]) - y0
            if 0 <= c < VIEW_COLS and 0 <= r < VIEW_ROWS and share[r, c] >= DARK_TEXTURE_SHARE:
                objects.append({"name": _object_name(obj), "dx": c - VIEW_COLS // 2, "dy": r - VIEW_ROWS // 2})
        inv = {k: int(v) for k, v in player.inventory.items()}
        pos = np.array(player.pos, dtype=int) - self._spawn
        return {
            "view": view,
            "objects": objects,
            "inventory": {k: v for k, v in inv.items() if k not in VITALS},
            "vitals": {k: inv[k] for k in VITALS},
            "daylight": round(float(world.daylight), 4),
            "sleeping": bool(player.sleeping),
            "facing": _FACING[tuple(int(v) for v in player.facing)],
            "position": [int(pos[0]), int(pos[1])],
            "step": int(env._step or 0),
            "achievements": sorted(k for k, v in player.achievements.items() if v > 0),
            "done": self._done,
        }

    def query_state(self) -> dict:
        """JSON-ready summary: :meth:`observe` without the view grid."""
        obs = self.observe()
        obs.pop("view")
        return obs

    def snapshot(self) -> dict:
        """ENVIRONMENT-style snapshot of what the player knows (evidence for the verifier):
        one entity ``player`` whose ``position`` is the odometry ``[x, y, 0]`` in cells
        (not metres) and whose ``attributes`` hold inventory, vitals, achievements,
        daylight, step, facing, sleeping, done, the local view rows, the objects and
        ``world`` (the seed the session's run asked for)."""
        obs = self.observe()
        attrs = {k: obs[k] for k in ("inventory", "vitals", "achievements", "daylight", "step", "facing", "sleeping",
                                     "done", "objects")}
        attrs["view"] = [" ".join(row) for row in obs["view"]]
        attrs["world"] = self._seed  # which world this is: the seed the session asked for
        return {
            "sim_time_s": float(obs["step"]),
            "entities": [{"name": "player", "kind": "player", "position": [float(obs["position"][0]),
                                                                           float(obs["position"][1]), 0.0],
                          "attributes": attrs}],
            "relations": [],
        }

    def ground_truth(self) -> dict:
        """Scoring only (never an observation): the environment's own achievement counters,
        health, absolute position, seed and whether the episode ended (and why)."""
        self._ensure()
        env, player = self._env, self._env._player
        return {
            "seed": self._seed,
            "step": int(env._step or 0),
            "achievements": {k: int(v) for k, v in player.achievements.items()},
            "health": int(player.health),
            "dead": bool(player.health <= 0),
            "done": self._done,
            "player_pos": [int(v) for v in player.pos],
        }

    def render(self, camera: str = "", width: int = 320, height: int = 240, *, shadows: bool = False) -> np.ndarray:
        """(height, width, 3) uint8: Crafter's own picture (local view + inventory), scaled to fit."""
        side = int(min(width, height))
        self._ensure()
        env = self._env
        # Crafter draws its night noise from the world's RNG: restore it so that looking
        # at the game for the evidence never changes how the game goes on.
        rng = env._world.random.get_state()
        try:
            unit = np.array((side // 9, side // 9))
            view = np.concatenate([env._local_view(env._player, unit), env._item_view(env._player.inventory, unit)], 1)
        finally:
            env._world.random.set_state(rng)
        img = view.transpose((1, 0, 2)).astype(np.uint8)
        canvas = np.zeros((height, width, 3), np.uint8)
        oy, ox = (height - img.shape[0]) // 2, (width - img.shape[1]) // 2
        canvas[oy:oy + img.shape[0], ox:ox + img.shape[1]] = img
        return canvas

    # -- state between sessions -----------------------------------------------------
    def save_state(self, path: str | os.PathLike) -> Path:
        """Write the game state (world, creatures, player, step counters, RNG) and the
        player's notebook to ``path`` (.npz, atomically) and the scoring ground truth to
        ``ground_truth.yaml`` beside it."""
        self._ensure()
        env = self._env
        blob = pickle.dumps({"world": env._world, "player": env._player, "step": env._step, "episode": env._episode,
                             "unlocked": env._unlocked, "last_health": env._last_health}, protocol=5)
        notes = pickle.dumps(self.notes, protocol=5)
        buf = io.BytesIO()
        np.savez(buf, format=np.array(_STATE_FORMAT), seed=np.array(self._seed), spawn=self._spawn,
                 done=np.array(self._done), scene=np.frombuffer(yaml.safe_dump(self.scene.to_dict()).encode(), np.uint8),
                 game=np.frombuffer(blob, np.uint8), notes=np.frombuffer(notes, np.uint8))
        p = Path(path)
        atomic_write_bytes(p, buf.getvalue())
        atomic_write_text(p.with_name("ground_truth.yaml"), yaml.safe_dump(self.ground_truth(), sort_keys=True))
        return p

    def load_state(self, path: str | os.PathLike) -> None:
        """Restore what :meth:`save_state` wrote.

        Raises:
            TargetError: missing or unreadable file, another format, or another scene.
        """
        z = read_state_npz(path)
        if int(z.get("format", -1)) != _STATE_FORMAT:
            raise TargetError(f"state file {path}: format {z.get('format')} is not {_STATE_FORMAT}")
        scene = CrafterScene.from_dict(load_plain(z["scene"].tobytes().decode(), path=path, error=TargetError))
        if scene != self.scene:
            raise TargetError(f"state file {path} belongs to scene {scene}, not {self.scene}")
        try:
            game = pickle.loads(z["game"].tobytes())  # our own file, written by save_state
            notes = pickle.loads(z["notes"].tobytes())
        except Exception as exc:  # noqa: BLE001
            raise TargetError(f"state file {path}: unreadable game state: {exc}") from exc
        crafter = import_extra("crafter", extra="game")

        env = self._env  # keep its loaded textures; the world, player and counters are replaced
        env._world, env._player = game["world"], game["player"]
        env._step, env._episode = game["step"], game["episode"]
        env._unlocked, env._last_health = game["unlocked"], game["last_health"]
        _order_chunks(env._world)  # a no-op for states this module wrote; converts older ones
        # The views hold a reference to the world: rebuild them on the restored one.
        env._local_view = crafter.engine.LocalView(env._world, env._textures, [9, 7])
        env._sem_view = crafter.engine.SemanticView(env._world, [
            crafter.objects.Player, crafter.objects.Cow, crafter.objects.Zombie, crafter.objects.Skeleton,
            crafter.objects.Arrow, crafter.objects.Plant])
        self._env = env
        self._seed = int(z["seed"])
        self._spawn = np.array(z["spawn"], dtype=int)
        self._done = bool(z["done"])
        self._fresh = False
        self._generated = True
        self.notes = notes

    def tools(self) -> tuple[str, ...]:
        return self.TOOLS

    def _tool_observe(self) -> dict:
        return self.observe()

    def _tool_snapshot(self) -> dict:
        return self.snapshot()

    def close(self) -> None:
        self._env = None if self.closed else self._env
        super().close()


def _object_name(obj) -> str:
    kind = type(obj).__name__.lower()
    if kind == "plant" and getattr(obj, "ripe", False):
        return "plant_ripe"
    return kind


def _make_action_tool(action: str):
    def tool(self) -> None:
        self.act(action)

    tool.__name__ = f"_tool_{action}"
    tool.__doc__ = f"Crafter action ``{action}`` for one game step."
    return tool


for _action in CRAFTER_ACTIONS:
    setattr(CrafterTarget, f"_tool_{_action}", _make_action_tool(_action))
del _action
