"""Game primitives that pursue a task: explore, go to, collect, hunt, place, make, sleep.

Each leaf re-plans from the player's map every tick (creatures move, a survival reflex
may have taken over for a while), takes one game action and returns RUNNING until its
goal holds in the player's own observation (SUCCESS) or its step budget, the episode,
or its attempts run out (FAILURE with a ``game.*`` code).
"""

from __future__ import annotations

import logging

from py_trees.common import Status

from ..base import PrimitiveFailure
from .base import GameLeaf, facing_cell, neighbourhood
from .seen_map import MOVES, WALKABLE
from .shelter import Rest

__all__ = ["GameObserve", "GameExplore", "GameGoto", "GameCollect", "GameHunt", "GamePlace", "GameMake", "GameSleep",
           "PLACE_ONTO"]

logger = logging.getLogger(__name__)

#: Where each ``place_*`` action puts its item: a free cell of these materials in front of
#: the player (the action's affordance as the game shows it, not its cost).
PLACE_ONTO = {"stone": ("grass", "sand", "path", "water", "lava"), "table": ("grass", "sand", "path"),
              "furnace": ("grass", "sand", "path"), "plant": ("grass",)}
_MOVE_ACTIONS = tuple(MOVES)
#: Stations a ``game_make`` session may place for a recipe from memory (a table and a furnace).
MAX_BUILDS = 2


def _inv(obs: dict) -> dict[str, int]:
    return {**obs["inventory"], **obs["vitals"]}


class GameObserve(GameLeaf):
    """Look (no game step): update the map and publish the snapshot (ENVIRONMENT.md)."""

    TOOLS = ("observe", "snapshot")

    def step(self):
        if self.ctx.on_observation is not None:
            self.ctx.on_observation(self.ctx.target.invoke_tool("snapshot"))
        return Status.SUCCESS


class GameExplore(GameLeaf):
    """Walk toward unseen cells for ``steps`` game steps, or until ``until`` (a material or
    creature name) has been seen."""

    TOOLS = ("observe",) + _MOVE_ACTIONS

    def __init__(self, name: str, *, steps: int = 50, until: str | None = None, max_steps: int = 1000):
        super().__init__(name, max_steps=max_steps)
        self.steps, self.until = int(steps), until
        self._walked = 0

    def step(self):
        if self.until and self.map.known(self.until):
            return Status.SUCCESS
        if self._walked >= self.steps:
            return Status.SUCCESS if not self.until else Status.FAILURE
        self.act(self.explore_action())
        self._walked += 1
        return Status.RUNNING


class GameGoto(GameLeaf):
    """Go next to the nearest remembered ``target`` (material or creature), exploring
    until one is seen; SUCCESS when the player stands next to one and faces it."""

    TOOLS = ("observe",) + _MOVE_ACTIONS

    def __init__(self, name: str, *, target: str, max_steps: int = 1000):
        super().__init__(name, max_steps=max_steps)
        self.target = target

    def step(self):
        goals = self.map.cells_of([self.target])
        if facing_cell(self.obs) in goals:
            return Status.SUCCESS
        move, plan = self.goto_action(goals)
        if plan is None:
            self.act(self.explore_action())
        elif move is not None:
            self.act(move)
        else:
            turn = self.face(plan.goal)
            if turn is None:
                return Status.SUCCESS
            self.act(turn)
        return Status.RUNNING


class GameCollect(GameLeaf):
    """Collect from ``material`` (``do`` facing it) until the inventory (or vital) ``item``
    reaches ``count``; fails ``game.no_effect`` after ``patience`` strikes in a row that
    change nothing (e.g. stone without a pickaxe)."""

    TOOLS = ("observe", "do") + _MOVE_ACTIONS

    def __init__(self, name: str, *, material: str, item: str, count: int = 1, strikes: int = 0, patience: int = 8,
                 max_steps: int = 1000):
        super().__init__(name, max_steps=max_steps)
        self.material, self.item, self.count = material, item, int(count)
        self.strikes, self._gains = int(strikes), 0  # successful strikes required (e.g. drink although full)
        self.patience = int(patience) if material not in WALKABLE else max(int(patience), 60)  # saplings: 10 %
        self._strikes = 0

    def step(self):
        if _inv(self.obs).get(self.item, 0) >= self.count and self._gains >= self.strikes:
            return Status.SUCCESS
        front = facing_cell(self.obs)
        if self.map.material(front) == self.material and not self._occupied(front):
            before = _inv(self.obs).get(self.item, 0)
            achieved = len(self.obs["achievements"])
            self.act("do")
            gained = _inv(self.obs).get(self.item, 0) > before or len(self.obs["achievements"]) > achieved
            self._gains += int(gained)
            self._strikes = 0 if gained else self._strikes + 1
            if self._strikes >= self.patience:
                raise PrimitiveFailure("game.no_effect", f"{self.patience} strikes on {self.material} gave no {self.item} "
                                                         f"(inventory {self.obs['inventory']})")
            return Status.RUNNING
        goals = self.map.cells_of([self.material])
        move, plan = self.goto_action(goals)
        if plan is None:
            self.act(self.explore_action())
        elif move is not None:
            self.act(move)
        else:
            self.act(self.face(plan.goal) or self.explore_action())
        return Status.RUNNING

    def _occupied(self, cell) -> bool:
        px, py = self.obs["position"]
        return any((px + o["dx"], py + o["dy"]) == tuple(cell) for o in self.obs["objects"])


class GameHunt(GameLeaf):
    """Hunt ``creature`` (``cow``, ``zombie``, ``skeleton``, or ``plant_ripe``: wait by a
    remembered plant until it ripens): go next to it and strike until ``until`` (an
    achievement) is newly unlocked, or, for a cow, the food rises."""

    TOOLS = ("observe", "do", "noop", "sleep", "place_stone") + _MOVE_ACTIONS

    def __init__(self, name: str, *, creature: str, until: str | None = None, min_health: int = 5,
                 max_steps: int = 1000):
        super().__init__(name, max_steps=max_steps)
        self.creature, self.until, self.min_health = creature, until, int(min_health)
        self._start: dict | None = None
        self._rest: Rest | None = None

    def on_enter(self):
        super().on_enter()
        if self._start is None:
            self._start = {"achievements": set(self.obs["achievements"]), "food": self.obs["vitals"]["food"]}

    def _done(self) -> bool:
        # the player's own record already holds the achievement (a fight the survival
        # reflex won, a plant eaten earlier): hunting on only risks the player
        if self.until and self.until in self.obs["achievements"]:
            return True
        return self.creature == "cow" and self.obs["vitals"]["food"] > self._start["food"]

    def step(self):
        if self._done():
            return Status.SUCCESS
        hostile = self.creature in ("zombie", "skeleton")
        if hostile and (self._rest is not None or self.obs["vitals"]["health"] < self.min_health):
            # too weak to fight: rest (in shelter) until healed, then hunt on
            self._rest = self._rest or Rest(until_day=False)
            action = self._rest.step(self) if self.obs["vitals"]["health"] < 9 or not self._rest.slept else None
            if action is None and self.obs["vitals"]["health"] < self.min_health:
                action = self.flee_action()  # cannot rest safely now: keep away until healed
            if action is not None:
                self.act(action)
                return Status.RUNNING
            self._rest = None
        px, py = self.obs["position"]
        here = {(px + o["dx"], py + o["dy"]) for o in self.obs["objects"] if o["name"] == self.creature}
        front = facing_cell(self.obs)
        if front in here:
            self.act("do")
            return Status.RUNNING
        adjacent = [c for c in here if abs(c[0] - px) + abs(c[1] - py) == 1]
        if adjacent:
            self.act(self.face(adjacent[0]) or "do")
            return Status.RUNNING
        goals = here or self.map.cells_of([self.creature])
        if not goals and self.creature == "plant_ripe" and self._wait_for_plant():
            return Status.RUNNING
        if not goals and self.creature == "plant_ripe":
            # A sapling ripens where it was planted: wait next to a remembered plant.
            move, plan = self.goto_action(self.map.cells_of(["plant"]))
            self.act(move if move is not None else ("noop" if plan is not None else self.explore_action()))
            return Status.RUNNING
        move, plan = self.goto_action(goals)
        self.act(move if move is not None else self.explore_action())
        return Status.RUNNING


    def _wait_for_plant(self) -> bool:
        """A sapling ripens ~300 steps after planting, and only while the player is within
        Crafter's update distance: wait in a sealed shelter near the plant until then (the
        player's own record of when it planted, ``notes['plants']``). True when it acted."""
        plants = self.map.cells_of(["plant"])
        planted = [int(s) for c, s in self.ctx.target.notes.get("plants", []) if tuple(c) in plants]
        if self._rest is None:
            if not planted or int(self.obs["step"]) >= min(planted) + 310 or \
                    self.obs["inventory"].get("wood_pickaxe", 0) == 0:
                return False
            px, py = self.obs["position"]
            if min(abs(x - px) + abs(y - py) for x, y in plants) > 6:
                move, plan = self.goto_action(plants)
                if move is None:
                    return False
                self.act(move)
                return True
            self._rest = Rest(until_day=False, until_step=min(planted) + 310, radius=8)
            self.ctx.trace.record("game_plant_wait", step=self.obs["step"], until=min(planted) + 310)
        action = self._rest.step(self)
        if action is None:
            self._rest = None
            return False
        self.act(action)
        return True


class GamePlace(GameLeaf):
    """Place ``item`` (``table``, ``furnace``, ``stone``, ``plant``) on a free cell in front,
    next to ``near`` (a material) when given; SUCCESS when the inventory paid for it.
    Each attempt is a ``game_place`` trace record; ``max_tries`` failed attempts on a
    valid cell fail the leaf (``game.place_failed``: the inventory did not change)."""

    TOOLS = ("observe", "place_stone", "place_table", "place_furnace", "place_plant") + _MOVE_ACTIONS

    def __init__(self, name: str, *, item: str, near: str | None = None, max_tries: int = 2, protect: bool = False,
                 max_steps: int = 300):
        super().__init__(name, max_steps=max_steps)
        if item not in PLACE_ONTO:
            raise ValueError(f"cannot place {item!r}; placeable: {sorted(PLACE_ONTO)}")
        self.item, self.near, self.max_tries = item, near, int(max_tries)
        self.protect = bool(protect) and item == "plant"
        self._tries = 0
        self._turns = 0
        self._nook = None  # (X, d): the grass cell to plant on and the direction from the stand cell to it
        self._seal: list[str] | None = None
        self._wall_tries = 0

    # -- a protected plant -------------------------------------------------------------
    # A sapling ripens only while no zombie, skeleton or cow stands next to it (Crafter's
    # Plant.update), and a player faces a free cell only right after moving toward it. So:
    # plant on a grass cell X whose three other neighbours are solid, standing on Y with Z
    # and W behind it in a line (Z = Y - d, W = Y - 2d); then back off to W, step forward
    # into Z (now facing Y) and place stone on Y. X is then walled in on all four sides.
    def _find_nook(self):
        """``(X, d, walls)``: the nearest grass cell X to plant on, approached along ``d``
        (Y = X - d, Z, W behind it walkable), whose other three neighbours are solid or
        can be walled with stone (``walls``: directions e whose X + e is open, with X + 2e
        and X + 3e walkable to stand on and come from); the fewest walls first. The player
        needs ``len(walls) + 1`` stones."""
        here = tuple(self.obs["position"])
        m = self.map
        px, py = here
        stones = self.obs["inventory"].get("stone", 0)
        occupied = {(px + o["dx"], py + o["dy"]) for o in self.obs["objects"]} | m.cells_of(["plant", "plant_ripe"])

        def at(c, e, k):
            return c[0] + k * e[0], c[1] + k * e[1]

        best: dict[tuple[int, int], tuple] = {}
        for dx in range(-10, 11):
            for dy in range(-10, 11):
                x = (px + dx, py + dy)
                if m.material(x) != "grass" or x in occupied:
                    continue
                for d in MOVES.values():
                    back = (-d[0], -d[1])
                    if not all(m.material(at(x, back, k)) in WALKABLE for k in (1, 2, 3)):
                        continue
                    walls, ok = [], True
                    for e in MOVES.values():
                        if e == back:
                            continue
                        n = m.material(at(x, e, 1))
                        if n in ("unknown", "lava"):
                            ok = False
                        elif n in WALKABLE:
                            if at(x, e, 1) in occupied or not all(m.material(at(x, e, k)) in WALKABLE for k in (2, 3)):
                                ok = False
                            walls.append(e)
                    if not ok or len(walls) + 1 > stones:
                        continue
                    z = at(x, back, 2)
                    key = (len(walls), abs(dx) + abs(dy))
                    if z not in best or key < best[z][0]:
                        best[z] = (key, (x, d, walls))
        if not best:
            return None
        fewest = min(v[0][0] for v in best.values())
        goals = {z for z, v in best.items() if v[0][0] == fewest}
        plan = m.plan(here, goals, blocked=self.blocked(), stand_on_goal=True)
        return None if plan is None else best[plan.stand][1]

    def _wall_step(self) -> bool:
        """Wall the next open neighbour of the chosen cell: stand on X + 3e, step to X + 2e
        (now facing X + e), place stone. True when it acted."""
        x, d, walls = self._nook
        while walls:
            e = walls[0]
            n = (x[0] + e[0], x[1] + e[1])
            if self.map.material(n) not in WALKABLE:
                walls.pop(0)  # walled (or already solid)
                continue
            two, three = (x[0] + 2 * e[0], x[1] + 2 * e[1]), (x[0] + 3 * e[0], x[1] + 3 * e[1])
            here = tuple(self.obs["position"])
            move_to = {v: k for k, v in MOVES.items()}
            if here == two and facing_cell(self.obs) == n:
                if self.obs["inventory"].get("stone", 0) == 0:
                    raise PrimitiveFailure("game.place_failed", "no stone left to wall the plant in")
                self.act("place_stone")
                self._wall_tries += 1
                if self._wall_tries > 12:
                    raise PrimitiveFailure("game.place_failed", f"could not wall {n} in 12 tries")
                return True
            if here == three:
                self.act(move_to[(-e[0], -e[1])])
                return True
            move, plan = self.goto_action({three}, stand_on_goal=True)
            if move is None:
                self.protect = False  # cannot get there now: plant unprotected
                self._nook = None
                return False
            self.act(move)
            return True
        return False

    def _protected_step(self):
        obs = self.obs
        here = tuple(obs["position"])
        if self._seal is None and self._wall_step():
            return Status.RUNNING
        if self._nook is None:
            return Status.RUNNING
        x, d, _ = self._nook
        move_to = {v: k for k, v in MOVES.items()}
        back = move_to[(-d[0], -d[1])]
        if self._seal is not None:  # planted: back off two cells, step forward, wall Y in
            if not self._seal:
                front = facing_cell(obs)
                y = (x[0] - d[0], x[1] - d[1])
                if front == y and self.map.material(y) in WALKABLE and obs["inventory"].get("stone", 0) > 0:
                    self.act("place_stone")
                    self.ctx.trace.record("game_plant_protected", step=self.obs["step"], ok=self.map.material(y) == "stone")
                return Status.SUCCESS
            self.act(self._seal.pop(0))
            return Status.RUNNING
        y = (x[0] - d[0], x[1] - d[1])
        z = (x[0] - 2 * d[0], x[1] - 2 * d[1])
        if here == y and facing_cell(obs) == x:
            status = self._try_place(obs)
            if status == Status.SUCCESS:
                notes = self.ctx.target.notes
                notes.setdefault("plants", []).append((x, int(self.obs["step"])))
                self._seal = [back, back, move_to[d]] if obs["inventory"].get("stone", 0) > 0 else []
                return Status.RUNNING
            return status
        if here == z:
            self.act(move_to[d])
            return Status.RUNNING
        move, plan = self.goto_action({z}, stand_on_goal=True)
        if plan is None or move is None:
            self._nook = None  # unreachable now: place anywhere
            self.protect = False
            self.act(self.explore_action() if plan is None else back)
            return Status.RUNNING
        self.act(move)
        return Status.RUNNING

    def _try_place(self, obs):
        before = dict(obs["inventory"])
        self.act(f"place_{self.item}")
        ok = self.obs["inventory"] != before
        if ok:  # the player's own record of what it built (GameMake tries near it first)
            self.ctx.target.notes.setdefault("placed", set()).add(self.item)
        self.ctx.trace.record("game_place", step=self.obs["step"], item=self.item, ok=ok,
                              nearby=neighbourhood(obs), inventory_before=before,
                              inventory_after=dict(self.obs["inventory"]))
        if ok:
            return Status.SUCCESS
        self._tries += 1
        if self._tries >= self.max_tries:
            raise PrimitiveFailure("game.place_failed", f"place_{self.item} changed nothing {self._tries} times "
                                                        f"(inventory {before})")
        return Status.RUNNING

    def step(self):
        obs = self.obs
        if self.protect:
            if self._nook is None:
                self._nook = self._find_nook()
                if self._nook is None:
                    self.protect = False
                    self.ctx.trace.record("game_plant_protected", step=obs["step"], ok=False, why="no walled nook seen")
            if self._nook is not None:
                return self._protected_step()
        if self.near and self.near not in neighbourhood(obs):
            move, plan = self.goto_action(self.map.cells_of([self.near]))
            self.act(move if move is not None else self.explore_action())
            return Status.RUNNING
        front = facing_cell(obs)
        px, py = obs["position"]
        occupied = {(px + o["dx"], py + o["dy"]) for o in obs["objects"]}
        if self.map.material(front) in PLACE_ONTO[self.item] and front not in occupied:
            status = self._try_place(obs)
            if status == Status.SUCCESS and self.item == "plant":
                self.ctx.target.notes.setdefault("plants", []).append((front, int(self.obs["step"])))
            return status
        # Turn or step so that a placeable cell comes in front.
        self._turns += 1
        order = list(MOVES)
        self.act(order[self._turns % 4])
        return Status.RUNNING


class GameMake(GameLeaf):
    """Make ``item`` (``make_<item>``). With ``near`` (the stations the recipe needs, from
    memory) the player first goes where all of them are within its 3 x 3 neighbourhood;
    where no remembered place has them together (an arrow breaks a table into path; a
    furnace stands two cells from the table), it places the missing ones beside the
    first one it can reach (:meth:`_build_step`). Without it (or when memory's recipe names stations not remembered together, or a
    planned try fails) the recipe is searched for: the player tries where it stands, then
    next to each remembered material it has not yet had around it at a failed try (what
    it placed itself first, ``notes['placed']``, then the nearest), then where two or more
    materials it never had around it together are within its neighbourhood (a recipe may
    need several stations at once).
    Every try is a ``game_make`` trace record (a failure leaves the inventory unchanged);
    SUCCESS when the item's count rose, ``game.make_failed`` after ``max_tries``."""

    TOOLS = ("observe", "make_wood_pickaxe", "make_stone_pickaxe", "make_iron_pickaxe", "make_wood_sword",
             "make_stone_sword", "make_iron_sword", "place_table", "place_furnace") + _MOVE_ACTIONS

    def __init__(self, name: str, *, item: str, near: list | None = None, max_tries: int = 12, max_steps: int = 600):
        super().__init__(name, max_steps=max_steps)
        self.item, self.near, self.max_tries = item, list(near or []), int(max_tries)
        self._tries = 0
        self._tried: set[str] = set()
        self._failed: list[set[str]] = []  # the materials around each failed try
        self._combos: set[tuple[int, int]] | None = None
        self._builds = 0  # stations placed for the recipe

    def _attempt(self) -> Status:
        obs = self.obs
        before = dict(obs["inventory"])
        nearby = neighbourhood(obs)
        self.act(f"make_{self.item}")
        ok = self.obs["inventory"].get(self.item, 0) > before.get(self.item, 0)
        self.ctx.trace.record("game_make", step=self.obs["step"], item=self.item, ok=ok, nearby=nearby,
                              inventory_before=before, inventory_after=dict(self.obs["inventory"]),
                              recipe_known=bool(self.near))
        self._tries += 1
        self._tried |= set(nearby)
        if not ok:
            self._failed.append(set(nearby))
        self._combos = None
        if ok:
            return Status.SUCCESS
        if self._tries >= self.max_tries:
            raise PrimitiveFailure("game.make_failed", f"make_{self.item} changed nothing in {self._tries} tries "
                                                       f"(inventory {before}, last nearby {nearby})")
        return Status.RUNNING

    def _abandon(self, why: str) -> None:
        self.ctx.trace.record("game_recipe_abandoned", step=self.obs["step"], item=self.item, near=self.near, why=why)
        self.near = []

    def _stations(self) -> set[tuple[int, int]]:
        """Walkable cells whose 3 x 3 neighbourhood holds every material of ``near``."""
        sets = []
        for name in self.near:
            cells = self.map.cells_of([name])
            sets.append({(x + dx, y + dy) for x, y in cells for dx in (-1, 0, 1) for dy in (-1, 0, 1)})
        if not sets:
            return set()
        out = set.intersection(*sets)
        return {c for c in out if self.map.material(c) in WALKABLE}

    def step(self):
        obs = self.obs
        if self.near:
            if all(n in neighbourhood(obs) for n in self.near):
                status = self._attempt()
                if status == Status.RUNNING:  # the recipe from memory did not work here: search instead
                    self._abandon("a planned attempt failed")
                return status
            stations = self._stations()
            move, plan = self.goto_action(stations, stand_on_goal=True) if stations else (None, None)
            if plan is None:
                # no reachable remembered place has the stations together: build the missing
                # ones (the recipe says which); else search
                if self._build_step():
                    return Status.RUNNING
                self._abandon(f"no reachable remembered place has {self.near} together and they cannot be built")
                return Status.RUNNING
            if move is None:
                return self._attempt()
            self.act(move)
            return Status.RUNNING
        # Recipe unknown: try here, then next to each untried remembered material.
        if self._tries == 0 or not set(neighbourhood(obs)) <= self._tried:
            return self._attempt()
        untried = {m for m in ("water", "stone", "tree", "coal", "iron", "diamond", "table", "furnace", "sand", "path",
                               "grass") if m not in self._tried and self.map.known(m)}
        built = untried & set(self.ctx.target.notes.get("placed", ()))  # what it built itself first
        move, plan = self.goto_action(self.map.cells_of(built)) if built else (None, None)
        if plan is None and untried:
            move, plan = self.goto_action(self.map.cells_of(untried))
        if plan is None:
            # every material was tried on its own: a recipe may need several stations at
            # once; go where the materials around the player are a set no failed try had
            goals = self._new_combinations()
            move, plan = self.goto_action(goals, stand_on_goal=True) if goals else (None, None)
            if plan is None:
                raise PrimitiveFailure("game.make_failed", f"make_{self.item} failed next to every material and "
                                                           f"combination seen ({sorted(self._tried)})")
        if move is None:
            return self._attempt()
        self.act(move)
        return Status.RUNNING

    def _build_step(self) -> bool:
        """One action toward a place where every station of the recipe is around the
        player, building the stations that are missing; False when that cannot be done
        (a station that cannot be placed, no place to put it, or :data:`MAX_BUILDS`
        placements already made). A placement that changes nothing (the player lacks
        what the station is built from) abandons the recipe for the search.

        The *anchor* is the recipe's first station remembered at a reachable place (what
        the player placed itself first); every other station is placed anew beside it:
        the player walks onto a cell Q next to the anchor, arriving by a move along d so
        that it faces Q + d, a free cell the station can stand on, and places it there.
        Q's 3 x 3 neighbourhood then holds the anchor and the new station. Without an
        anchor the first station is placed wherever a cell in front is free. Each
        placement is a ``game_place`` trace record (``for_recipe``: the item made)."""
        if self._builds >= MAX_BUILDS or any(n not in PLACE_ONTO for n in self.near):
            return False
        obs = self.obs
        here = tuple(obs["position"])
        m = self.map
        blocked = self.blocked()
        placed = list(self.ctx.target.notes.get("placed", ()))
        order = sorted(self.near, key=lambda n: (n not in placed, self.near.index(n)))
        anchor_cells: set[tuple[int, int]] = set()
        anchor = None
        for name in order:
            cells = m.cells_of([name])
            if cells and m.plan(here, cells, blocked=blocked) is not None:
                anchor, anchor_cells = name, cells
                break
        build = next(n for n in self.near if n != anchor)
        # (stand-before cell Q - d, Q, direction d): Q next to the anchor (or anywhere without one)
        candidates = {}
        span = range(-12, 13)
        for dx in span:
            for dy in span:
                q = (here[0] + dx, here[1] + dy)
                if m.material(q) not in WALKABLE or q in blocked:
                    continue
                if anchor is not None and not any((q[0] + a, q[1] + b) in anchor_cells
                                                  for a in (-1, 0, 1) for b in (-1, 0, 1)):
                    continue
                for d in MOVES.values():
                    front, before = (q[0] + d[0], q[1] + d[1]), (q[0] - d[0], q[1] - d[1])
                    if m.material(front) in PLACE_ONTO[build] and front not in blocked \
                            and m.material(before) in WALKABLE and before not in blocked:
                        candidates.setdefault(before, (q, d))
        front = facing_cell(obs)
        for q, d in candidates.values():  # already standing on Q facing Q + d: place now
            if q == here and front == (q[0] + d[0], q[1] + d[1]):
                self._place_station(build)
                return True
        for q, d in candidates.values():  # on Q - d: step along d onto Q (now facing Q + d)
            if (q[0] - d[0], q[1] - d[1]) == here:
                self.act(next(a for a, v in MOVES.items() if v == d))
                return True
        move, plan = self.goto_action(set(candidates), stand_on_goal=True) if candidates else (None, None)
        if plan is None or move is None:
            return False
        self.act(move)
        return True

    def _place_station(self, station: str) -> None:
        before = dict(self.obs["inventory"])
        nearby = neighbourhood(self.obs)
        self.act(f"place_{station}")
        ok = self.obs["inventory"] != before
        self._builds += 1
        if ok:
            self.ctx.target.notes.setdefault("placed", set()).add(station)
        self.ctx.trace.record("game_place", step=self.obs["step"], item=station, ok=ok, nearby=nearby,
                              inventory_before=before, inventory_after=dict(self.obs["inventory"]),
                              for_recipe=self.item)
        if not ok:  # cannot build it (nothing to build it from): the recipe is not followed here
            self._abandon(f"place_{station} changed nothing (inventory {before})")

    def _new_combinations(self, radius: int = 24) -> set[tuple[int, int]]:
        """Walkable remembered cells within ``radius`` whose 3 x 3 neighbourhood holds two or
        more non-ground materials that no failed try had around it all together; of those,
        the ones with the most materials the player placed itself (its own record,
        ``notes['placed']``: what it built is the likeliest station), then the most
        materials. Computed once per try (the map hardly changes between tries)."""
        if self._combos is not None:
            return self._combos
        here = self.obs["position"]
        ground = {"grass", "sand", "path", "unknown", "void", "lava"}
        placed = set(self.ctx.target.notes.get("placed", ()))
        best, out = None, set()
        for dx in range(-radius, radius + 1):
            for dy in range(-radius, radius + 1):
                c = (here[0] + dx, here[1] + dy)
                if self.map.material(c) not in WALKABLE:
                    continue
                around = {self.map.material((c[0] + a, c[1] + b)) for a in (-1, 0, 1) for b in (-1, 0, 1)} - ground
                if len(around) < 2 or any(around <= failed for failed in self._failed):
                    continue
                key = (len(around & placed), len(around))
                if best is None or key > best:
                    best, out = key, {c}
                elif key == best:
                    out.add(c)
        self._combos = out
        return out


class GameSleep(GameLeaf):
    """Rest (:class:`~.shelter.Rest`): into a sealed shelter when the player can dig,
    sleep until woken, stay until daylight, dig out; SUCCESS when the rest is over after
    the player slept (at once when its record already holds ``wake_up``: the night
    reflex slept). Crafter lets a player sleep only below full energy: until then
    each ``sleep`` is tried again."""

    TOOLS = ("observe", "sleep", "noop", "place_stone", "do") + _MOVE_ACTIONS

    def __init__(self, name: str, *, shelter: bool = True, max_steps: int = 1500):
        super().__init__(name, max_steps=max_steps)
        self.shelter = bool(shelter)
        self._rest = Rest(until_day=True)

    def step(self):
        if "wake_up" in self.obs["achievements"] and not self._rest.slept and not self.obs["sleeping"] \
                and self._rest.plan is None:
            return Status.SUCCESS  # already slept and woke this episode (the night reflex): nothing to add
        action = self._rest.step(self)
        if action is None:
            if self._rest.slept:
                return Status.SUCCESS
            self._rest = Rest(until_day=True)  # no sealed shelter at night: wait for the day
            action = "noop"
        self.act(action)
        return Status.RUNNING
