"""GameLeaf: the base of every game primitive (one game action per behaviour-tree tick).

A game leaf reads only what the player can know (``target.observe()``; see
:mod:`phyagentos.targets.crafter`), keeps the player's map
(:class:`~.seen_map.SeenMap`, carried in the target's notes from session to session),
acts through the target's operations (``invoke_tool``: only what the session's
TargetToolManifest grants) and records what happened in the session's trace:

- ``game_vitals`` when a vital changes (``{health, food, drink, energy}``, the step);
- ``game_damage`` when health drops: the creatures next to the player, daylight,
  whether it slept, the material it stands on (the evidence a death is diagnosed from);
- ``game_achievement`` when the player's achievement list grows;
- ``game_make`` / ``game_place`` for every attempt: item, ``ok`` (the inventory gained /
  spent), the materials around the player (its 3 x 3 neighbourhood) and the inventory
  before and after (a failed ``make`` is evidence: the inventory did not change);
- ``game_sighting`` the first time a material or creature is seen (what was around it);
- ``game_death`` / ``game_over`` when the episode ends.

One tick is one game step, so cancellation and the deadline are checked between steps.
"""

from __future__ import annotations

import logging
from typing import Any

from py_trees.common import Status

from ..base import Primitive, PrimitiveFailure
from .seen_map import MOVES, WALKABLE, SeenMap

__all__ = ["GameLeaf", "MOVE_ACTIONS", "neighbourhood", "facing_cell"]

logger = logging.getLogger(__name__)

MOVE_ACTIONS = tuple(MOVES)
_DIR = {"left": (-1, 0), "right": (1, 0), "up": (0, -1), "down": (0, 1)}


def neighbourhood(obs: dict) -> list[str]:
    """Sorted materials of the player's 3 x 3 neighbourhood (Crafter's ``nearby(pos, 1)``)."""
    view = obs["view"]
    r0, c0 = len(view) // 2, len(view[0]) // 2
    return sorted({view[r][c] for r in range(r0 - 1, r0 + 2) for c in range(c0 - 1, c0 + 2)} - {"dark", "void"})


def facing_cell(obs: dict) -> tuple[int, int]:
    dx, dy = _DIR[obs["facing"]]
    return obs["position"][0] + dx, obs["position"][1] + dy


class GameLeaf(Primitive):
    """A primitive acting on a game target, one action per tick.

    Args:
        name: leaf name.
        max_steps: game steps this leaf may spend before it fails (``game.budget``);
            counted over the leaf's whole life in the session (preemption by a
            survival reflex does not reset it).
    """

    TOOLS = ("observe",)

    def __init__(self, name: str, *, max_steps: int = 1000):
        super().__init__(name)
        if not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps must be an integer >= 1, got {max_steps!r}")
        self.max_steps = max_steps
        self.spent = 0

    # -- the player's knowledge ---------------------------------------------------
    @property
    def map(self) -> SeenMap:
        notes = self.ctx.target.notes
        if "map" not in notes:
            notes["map"] = SeenMap()
        return notes["map"]

    def observe(self) -> dict:
        obs = self.ctx.target.invoke_tool("observe")
        first = self.map.update(obs)
        if first:
            around = sorted({n for row in obs["view"] for n in row} - {"dark", "void"})
            for name in sorted(first):
                self.ctx.trace.record("game_sighting", step=obs["step"], name=name, around=around,
                                      distance_from_start=abs(obs["position"][0]) + abs(obs["position"][1]))
        return obs

    def on_enter(self) -> Status | None:
        self.obs = self.observe()
        self._check_over(self.obs, now=False)
        return None

    # -- acting ---------------------------------------------------------------------
    def act(self, action: str) -> dict:
        """Take one game step, update the map and the trace; returns the new observation.

        Raises:
            PrimitiveFailure: ``game.budget`` when the leaf's steps are spent, ``game.dead``
                or ``game.over`` when the episode ended.
        """
        if self.spent >= self.max_steps:
            raise PrimitiveFailure("game.budget", f"{self.name}: {self.max_steps} steps spent")
        before = self.obs
        self.ctx.target.invoke_tool(action)
        self.spent += 1
        obs = self.observe()
        self._record(before, obs, action)
        self.obs = obs
        self._check_over(obs)
        return obs

    def _record(self, before: dict, obs: dict, action: str) -> None:
        trace = self.ctx.trace
        if obs["vitals"] != before["vitals"]:
            trace.record("game_vitals", step=obs["step"], **obs["vitals"])
            if obs["vitals"]["health"] < before["vitals"]["health"]:
                near = [o["name"] for o in obs["objects"] if abs(o["dx"]) + abs(o["dy"]) <= 1]
                near_prev = [o["name"] for o in before["objects"] if abs(o["dx"]) + abs(o["dy"]) <= 2]
                trace.record("game_damage", step=obs["step"], health=obs["vitals"]["health"],
                             lost=before["vitals"]["health"] - obs["vitals"]["health"], adjacent=near,
                             close_before=near_prev, daylight=obs["daylight"], sleeping=before["sleeping"],
                             food=obs["vitals"]["food"], drink=obs["vitals"]["drink"], energy=obs["vitals"]["energy"],
                             action=action, standing_on=obs["view"][len(obs["view"]) // 2][len(obs["view"][0]) // 2])
        new = sorted(set(obs["achievements"]) - set(before["achievements"]))
        for a in new:
            trace.record("game_achievement", step=obs["step"], achievement=a)

    def _check_over(self, obs: dict, *, now: bool = True) -> None:
        """Fail when the episode is over; the death (or the end) is recorded by the step
        that caused it (``now``), not again by later leaves and sessions."""
        if not obs["done"]:
            return
        dead = obs["vitals"]["health"] <= 0
        if now:
            kind = "game_death" if dead else "game_over"
            self.ctx.trace.record(kind, step=obs["step"], **obs["vitals"], daylight=obs["daylight"],
                                  adjacent=[o["name"] for o in obs["objects"] if abs(o["dx"]) + abs(o["dy"]) <= 1])
        if dead:
            raise PrimitiveFailure("game.dead", f"the player died at step {obs['step']}")
        raise PrimitiveFailure("game.over", f"the episode ended at step {obs['step']}")

    # -- moving ---------------------------------------------------------------------
    def blocked(self) -> set[tuple[int, int]]:
        """Cells to route around: creatures seen now, and cells next to remembered lava."""
        px, py = self.obs["position"]
        cells = {(px + o["dx"], py + o["dy"]) for o in self.obs["objects"]}
        for lx, ly in self.map.cells_of(["lava"]):
            cells |= {(lx + dx, ly + dy) for dx, dy in MOVES.values()}
        return cells

    def face(self, cell: tuple[int, int]) -> str | None:
        """The move that turns the player toward the adjacent ``cell`` (it also steps
        there when the cell is free), or ``None`` when it already faces it."""
        px, py = self.obs["position"]
        d = (cell[0] - px, cell[1] - py)
        if d == tuple(_DIR[self.obs["facing"]]):
            return None
        return next(a for a, v in MOVES.items() if v == d)

    def explore_action(self) -> str:
        """A step toward the nearest remembered frontier (walkable cell next to unseen ones);
        a step in the facing direction when none is reachable."""
        here = tuple(self.obs["position"])
        plan = self.map.plan(here, self.map.frontier() - {here}, blocked=self.blocked(), stand_on_goal=True)
        if plan is None and self.obs["inventory"].get("wood_pickaxe", 0) > 0:
            plan = self.map.plan(here, self.map.frontier() - {here}, blocked=self.blocked(), stand_on_goal=True,
                                 dig=True)
        if plan is not None and plan.moves:
            return self.dig_through(plan.moves[0])
        order = list(MOVES)
        k = (self.spent // 7) % 4
        return order[k]

    def shelter_spot(self, *, radius: int = 8) -> tuple[int, int] | None:
        """A remembered walkable cell within ``radius`` steps with the fewest walkable
        neighbours (zombies reach a sleeper only through those), preferring cells that are
        not grass (zombies appear on grass) and then nearer ones."""
        here = tuple(self.obs["position"])
        best, best_key = None, None
        for dx in range(-radius, radius + 1):
            for dy in range(-(radius - abs(dx)), radius - abs(dx) + 1):
                c = (here[0] + dx, here[1] + dy)
                m = self.map.material(c)
                if m not in WALKABLE:
                    continue
                open_ = sum(self.map.material((c[0] + a, c[1] + b)) in WALKABLE for a, b in MOVES.values())
                key = (open_, m == "grass", abs(dx) + abs(dy))
                if best_key is None or key < best_key:
                    best, best_key = c, key
        if best is not None and best != here and self.map.plan(here, {best}, blocked=self.blocked(),
                                                                stand_on_goal=True) is None:
            return None
        return best

    def flee_action(self) -> str:
        """The free move that keeps the player farthest (Manhattan) from the zombies and
        skeletons in view; ``noop`` when none is in view or no move is free."""
        px, py = self.obs["position"]
        foes = [(px + o["dx"], py + o["dy"]) for o in self.obs["objects"] if o["name"] in ("zombie", "skeleton", "arrow")]
        if not foes:
            return "noop"
        blocked = self.blocked()
        best, best_d = "noop", min(abs(fx - px) + abs(fy - py) for fx, fy in foes)
        for move, (dx, dy) in MOVES.items():
            c = (px + dx, py + dy)
            if self.map.material(c) not in WALKABLE or c in blocked:
                continue
            d = min(abs(fx - c[0]) + abs(fy - c[1]) for fx, fy in foes)
            if d > best_d:
                best, best_d = move, d
        return best

    def goto_action(self, goals: set[tuple[int, int]], *, stand_on_goal: bool = False) -> tuple[str | None, Any]:
        """Next move toward the nearest of ``goals`` (adjacent to it, or onto it); returns
        ``(move, plan)``; ``(None, plan)`` when already there; ``(None, None)`` when no
        goal is reachable on remembered cells."""
        plan = self.map.plan(self.obs["position"], goals, blocked=self.blocked(), stand_on_goal=stand_on_goal)
        if plan is None and self.obs["inventory"].get("wood_pickaxe", 0) > 0:
            plan = self.map.plan(self.obs["position"], goals, blocked=self.blocked(), stand_on_goal=stand_on_goal,
                                 dig=True)
        if plan is None:
            return None, None
        return (self.dig_through(plan.moves[0]) if plan.moves else None), plan

    def dig_through(self, move: str) -> str:
        """``move``, or ``do`` when the cell it leads to is stone the player faces (dig first)."""
        px, py = self.obs["position"]
        dx, dy = MOVES[move]
        if self.map.material((px + dx, py + dy)) == "stone" and facing_cell(self.obs) == (px + dx, py + dy):
            return "do"
        return move
