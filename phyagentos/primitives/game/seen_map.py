"""The player's own map of what it has seen, and path planning on it.

The map is built only from observations (the local view and the objects drawn on it),
in the odometry frame of :meth:`~phyagentos.targets.crafter.CrafterTarget.observe`
(cells; x right, y down; the world's start at the origin). Cells never seen are
``unknown``; a ``dark`` cell leaves the remembered material unchanged. Objects are
remembered with the step they were last seen (creatures move; a remembered cow is a
hint, not a fact).

Planning is breadth-first search over remembered walkable cells (grass, sand, path:
Crafter's ``walkable``; never lava, never unknown), 4-connected, every move costing one
step, so the first goal reached is a nearest one in steps.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

__all__ = ["SeenMap", "MATERIALS", "WALKABLE", "MOVES", "Plan"]

#: Material codes of the map (index = code); 0 is unknown.
MATERIALS: tuple[str, ...] = ("unknown", "void", "water", "grass", "stone", "path", "sand", "tree", "lava", "coal",
                              "iron", "diamond", "table", "furnace")
_CODE = {name: i for i, name in enumerate(MATERIALS)}
_STONE = _CODE["stone"]
#: Cells the player can walk on (Crafter's ``walkable``; lava is walkable in Crafter but deadly).
WALKABLE: frozenset[str] = frozenset({"grass", "sand", "path"})
_WALK = np.zeros(len(MATERIALS), bool)
for _m in WALKABLE:
    _WALK[_CODE[_m]] = True
#: Move action -> (dx, dy) in cells.
MOVES: dict[str, tuple[int, int]] = {"move_left": (-1, 0), "move_right": (1, 0), "move_up": (0, -1), "move_down": (0, 1)}
_HALF = 128  # the map spans [-128, 128) cells around the start (a Crafter world is 64 x 64)


@dataclass(frozen=True)
class Plan:
    """A path: ``moves`` (action names), the cell it ends at and the goal cell it faces."""

    moves: tuple[str, ...]
    stand: tuple[int, int]
    goal: tuple[int, int]


class SeenMap:
    """Remembered materials (codes in a (256, 256) uint8 grid) and last-seen objects."""

    def __init__(self) -> None:
        self.grid = np.zeros((2 * _HALF, 2 * _HALF), np.uint8)
        self.objects: dict[tuple[int, int], tuple[str, int]] = {}  # cell -> (name, step last seen)
        self.names: set[str] = set()  # every material and object name ever seen

    # -- persistence (the target keeps it in its notes) -----------------------------
    def to_notes(self) -> dict[str, Any]:
        return {"grid": self.grid.copy(), "objects": dict(self.objects), "names": set(self.names)}

    @classmethod
    def from_notes(cls, notes: dict[str, Any] | None) -> "SeenMap":
        m = cls()
        if notes:
            m.grid = np.array(notes["grid"], np.uint8)
            m.objects = dict(notes["objects"])
            m.names = set(notes.get("names", ()))
        return m

    # -- updating -------------------------------------------------------------------
    def update(self, obs: dict) -> set[str]:
        """Write the observation's view and objects into the map; returns the names seen
        for the first time."""
        px, py = obs["position"]
        view = obs["view"]
        rows, cols = len(view), len(view[0])
        x0, y0 = px - cols // 2, py - rows // 2
        for r, row in enumerate(view):
            for c, name in enumerate(row):
                if name == "dark":
                    continue
                self.grid[x0 + c + _HALF, y0 + r + _HALF] = _CODE.get(name, 0)
        step = int(obs["step"])
        # Forget objects remembered inside the visible window: what is there now is seen.
        visible = {(x0 + c, y0 + r) for r, row in enumerate(view) for c, name in enumerate(row) if name != "dark"}
        self.objects = {cell: v for cell, v in self.objects.items() if cell not in visible}
        for o in obs["objects"]:
            self.objects[(px + o["dx"], py + o["dy"])] = (o["name"], step)
        names = {n for row in view for n in row if n not in ("dark", "void")} | {o["name"] for o in obs["objects"]}
        new = names - self.names
        self.names |= new
        return new

    # -- queries --------------------------------------------------------------------
    def material(self, cell: Sequence[int]) -> str:
        x, y = int(cell[0]) + _HALF, int(cell[1]) + _HALF
        if not (0 <= x < 2 * _HALF and 0 <= y < 2 * _HALF):
            return "void"
        return MATERIALS[self.grid[x, y]]

    def cells_of(self, names: Iterable[str]) -> set[tuple[int, int]]:
        """Remembered cells holding any of ``names`` (materials or object names)."""
        names = set(names)
        out: set[tuple[int, int]] = set()
        codes = [_CODE[n] for n in names if n in _CODE]
        if codes:
            xs, ys = np.nonzero(np.isin(self.grid, codes))
            out |= {(int(x) - _HALF, int(y) - _HALF) for x, y in zip(xs, ys)}
        out |= {cell for cell, (name, _) in self.objects.items() if name in names}
        return out

    def known(self, name: str) -> bool:
        return bool(self.cells_of([name]))

    def _free(self, cell, blocked, dig: bool = False) -> bool:
        x, y = cell[0] + _HALF, cell[1] + _HALF
        if not (0 <= x < 2 * _HALF and 0 <= y < 2 * _HALF) or cell in blocked:
            return False
        code = self.grid[x, y]
        return bool(_WALK[code]) or (dig and code == _STONE)

    def plan(self, start: Sequence[int], goals: set[tuple[int, int]], *, blocked: set[tuple[int, int]] = frozenset(),
             max_nodes: int = 20000, stand_on_goal: bool = False, dig: bool = False) -> Plan | None:
        """Shortest path from ``start`` to a free cell next to (or, with ``stand_on_goal``,
        onto) a cell of ``goals``; ``None`` when no goal is reachable on remembered cells.

        ``blocked``: cells to avoid (creatures, cells next to lava are the caller's choice).
        ``dig``: stone counts as passable (the player has a pickaxe and digs through it;
        each stone cell costs a strike and a step, planned here as one step).
        """
        start = (int(start[0]), int(start[1]))
        if not goals:
            return None
        prev: dict[tuple[int, int], tuple[tuple[int, int], str] | None] = {start: None}
        queue = deque([start])
        found = None
        while queue and len(prev) < max_nodes:
            cell = queue.popleft()
            if stand_on_goal:
                if cell in goals:
                    found = (cell, cell)
                    break
            else:
                hit = next((g for g in ((cell[0] + dx, cell[1] + dy) for dx, dy in MOVES.values()) if g in goals), None)
                if hit is not None:
                    found = (cell, hit)
                    break
            for action, (dx, dy) in MOVES.items():
                nxt = (cell[0] + dx, cell[1] + dy)
                if nxt in prev or not self._free(nxt, blocked, dig):
                    continue
                prev[nxt] = (cell, action)
                queue.append(nxt)
        if found is None:
            return None
        stand, goal = found
        moves = []
        cell = stand
        while prev[cell] is not None:
            cell, action = prev[cell]
            moves.append(action)
        return Plan(moves=tuple(reversed(moves)), stand=stand, goal=goal)

    def frontier(self) -> set[tuple[int, int]]:
        """Walkable remembered cells with an unknown 4-neighbour (where exploring pays)."""
        walk = _WALK[self.grid]
        unknown = self.grid == 0
        nb = np.zeros_like(unknown)
        nb[1:, :] |= unknown[:-1, :]
        nb[:-1, :] |= unknown[1:, :]
        nb[:, 1:] |= unknown[:, :-1]
        nb[:, :-1] |= unknown[:, 1:]
        xs, ys = np.nonzero(walk & nb)
        return {(int(x) - _HALF, int(y) - _HALF) for x, y in zip(xs, ys)}
