"""A sealed two-cell shelter, and how to get into it and out again.

In Crafter a move turns the player and steps forward when the cell ahead is free, so
a player can only face a free cell by arriving from the opposite side. A single cell
therefore cannot be sealed from inside: the cell one came from stays open behind. Two
cells in a line can: enter ``E`` from ``O`` (now facing ``I``), step into ``I`` (block
the cell beyond it when free), step back into ``E`` (now facing ``O``) and block ``O``.
With the four side cells of ``E`` and ``I`` not walkable, nothing can reach the player
and nothing can appear next to it (Crafter spawns creatures at least 6 cells away, on
grass). Stone cells on the line are dug through first when the player has a pickaxe.

:class:`ShelterPlan` is the pure geometry (found on the player's own map);
:func:`shelter_step` returns the next action of building and using it.
"""

from __future__ import annotations

from dataclasses import dataclass

from .seen_map import MOVES, WALKABLE, SeenMap

__all__ = ["ShelterPlan", "find_shelter", "shelter_step", "leave_step", "water_at", "Rest"]

_SOLID_OK = frozenset({"stone", "tree", "water", "coal", "iron", "diamond", "table", "furnace", "lava"})


@dataclass(frozen=True)
class ShelterPlan:
    """Cells (odometry frame) of the shelter: approach ``o``, entry ``e``, inner ``i``;
    ``d`` is the direction from ``o`` to ``i``."""

    o: tuple[int, int]
    e: tuple[int, int]
    i: tuple[int, int]
    d: tuple[int, int]


def _add(a, b, k=1):
    return a[0] + k * b[0], a[1] + k * b[1]


def find_shelter(m: SeenMap, here: tuple[int, int], *, can_dig: bool, radius: int = 10,
                 avoid: set[tuple[int, int]] = frozenset(), stones: int = 99, water_detour: int = 12) -> ShelterPlan | None:
    """The nearest (in BFS steps to ``o``) two-cell shelter on remembered cells: ``e``, ``i``
    walkable (or stone, when ``can_dig``), their side cells solid (not walkable, not
    unknown), ``o`` walkable and reachable, and sealable with ``stones`` (the cells to
    block, ``o`` and the one beyond ``i`` when free, less the stone dug out of ``e``, ``i``).
    One with water at a wall (:func:`water_at`) is taken when it is at most
    ``water_detour`` steps farther than the nearest."""
    starts: dict[tuple[int, int], list[ShelterPlan]] = {}
    # plants stand on grass but block the way (and a shelter must not wall one in)
    avoid = set(avoid) | m.cells_of(["plant", "plant_ripe"])
    for dx in range(-radius, radius + 1):
        for dy in range(-radius, radius + 1):
            o = (here[0] + dx, here[1] + dy)
            if m.material(o) not in WALKABLE:
                continue
            for d in MOVES.values():
                e, i = _add(o, d), _add(o, d, 2)
                ok = True
                for c in (e, i):
                    mat = m.material(c)
                    if not (mat in WALKABLE or (can_dig and mat == "stone")):
                        ok = False
                        break
                    side = (d[1], d[0])
                    for s in (_add(c, side), _add(c, side, -1)):
                        if m.material(s) not in _SOLID_OK or m.material(s) == "lava":
                            ok = False
                    if not ok:
                        break
                beyond = m.material(_add(o, d, 3))
                need = 1 + (beyond in WALKABLE) - sum(m.material(c) == "stone" for c in (e, i))
                if ok and beyond != "lava" and beyond not in ("unknown",) and not {o, e, i} & avoid and need <= stones:
                    starts.setdefault(o, []).append(ShelterPlan(o=o, e=e, i=i, d=d))
    if not starts:
        return None
    plan = m.plan(here, set(starts), stand_on_goal=True)
    if plan is None:
        return None
    # Prefer a shelter with water at one of its walls (a little farther is worth it): the
    # player drinks from inside (a move toward water only turns it) and never has to go
    # out at night for water.
    wet = {o: [p for p in ps if water_at(m, p)] for o, ps in starts.items()}
    wet = {o: ps for o, ps in wet.items() if ps}
    if wet:
        wet_plan = m.plan(here, set(wet), stand_on_goal=True)
        if wet_plan is not None and len(wet_plan.moves) <= len(plan.moves) + water_detour:
            return wet[wet_plan.stand][0]
    return starts[plan.stand][0]


def water_at(m: SeenMap, plan: ShelterPlan) -> list[tuple[int, int]]:
    """Water cells (remembered) a player inside ``plan`` can face and drink from: the
    side cells of ``e`` and ``i`` and the cell beyond ``i``."""
    side = (plan.d[1], plan.d[0])
    cells = [_add(plan.e, side), _add(plan.e, side, -1), _add(plan.i, side), _add(plan.i, side, -1), _add(plan.i, plan.d)]
    return [c for c in cells if m.material(c) == "water"]


def shelter_step(leaf, plan: ShelterPlan, state: dict) -> str | None:
    """Next action toward being sealed in ``plan`` (``None`` once sealed). ``state`` is the
    caller's scratch dict (``phase``). ``leaf`` is the acting :class:`~.base.GameLeaf`."""
    obs = leaf.obs
    here = tuple(obs["position"])
    m = leaf.map
    facing = {"left": (-1, 0), "right": (1, 0), "up": (0, -1), "down": (0, 1)}[obs["facing"]]
    front = _add(here, facing)
    back = (-plan.d[0], -plan.d[1])
    move_to = {v: k for k, v in MOVES.items()}
    phase = state.setdefault("phase", "approach")
    if phase == "approach":
        if here == plan.e:
            state["phase"] = phase = "inner"
        elif here != plan.o:
            move, p = leaf.goto_action({plan.o}, stand_on_goal=True)
            return move if move is not None else move_to[plan.d]
        else:
            if front == plan.e and m.material(plan.e) == "stone":
                return "do"
            return move_to[plan.d]  # steps into e when free, else turns to it
    if phase == "inner":
        if here == plan.i:
            state["phase"] = phase = "seal_far"
        elif here == plan.e:
            if front == plan.i and m.material(plan.i) == "stone":
                return "do"
            return move_to[plan.d]
        else:
            state["phase"] = "approach"
            return move_to[plan.d]
    if phase == "seal_far":
        far = _add(plan.i, plan.d)
        if here != plan.i:
            state["phase"] = "approach"
            return "noop"
        if front == far and m.material(far) in WALKABLE and obs["inventory"].get("stone", 0) > 0:
            return "place_stone"
        if front != far:
            return move_to[plan.d]  # far is solid: only turns
        state["phase"] = phase = "back"
    if phase == "back":
        if here == plan.i:
            return move_to[back]
        if here == plan.e:
            state["phase"] = phase = "seal_near"
        else:
            state["phase"] = "approach"
            return "noop"
    if phase == "seal_near":
        if here != plan.e:
            state["phase"] = "approach"
            return "noop"
        if front == plan.o and m.material(plan.o) in WALKABLE and obs["inventory"].get("stone", 0) > 0:
            return "place_stone"
        state["phase"] = "sealed"
    return None


def leave_step(leaf, plan: ShelterPlan) -> str | None:
    """Next action of leaving the shelter (dig through ``o`` again); ``None`` when out
    (the player stands on a cell with a walkable way on, or the shelter is open)."""
    obs = leaf.obs
    here = tuple(obs["position"])
    if here not in (plan.e, plan.i):
        return None
    move_to = {v: k for k, v in MOVES.items()}
    back = (-plan.d[0], -plan.d[1])
    facing = {"left": (-1, 0), "right": (1, 0), "up": (0, -1), "down": (0, 1)}[obs["facing"]]
    front = _add(here, facing)
    if here == plan.i:
        return move_to[back]
    if front == plan.o and leaf.map.material(plan.o) == "stone":
        return "do"
    return move_to[back]


class Rest:
    """Resting as a routine: into a sealed shelter when the player can dig (a pickaxe; it
    also digs itself out), else onto the most enclosed cell nearby; sleep until woken;
    with ``until_day``, stay (sleeping again when tired) until daylight returns; leave.
    :meth:`step` returns the next action, ``None`` when the rest is over."""

    def __init__(self, *, until_day: bool = True, day_above: float = 0.65, until_health: int | None = None,
                 until_step: int | None = None, radius: int = 16):
        self.until_day, self.day_above = until_day, float(day_above)
        self.until_health = until_health  # also stay until health reaches this (a retreat to heal)
        self.until_step = until_step  # also stay until the player's step count reaches this (waiting)
        self.building, self.build_limit, self.gave_up = 0, 60, False  # steps spent reaching and sealing
        self.radius = int(radius)  # how far from where the rest began a shelter may be (cells)
        self.plan: ShelterPlan | None = None
        self.state: dict = {}
        self.slept = False
        self.leaving = False
        self.spot = None

    def sealed(self) -> bool:
        return self.plan is not None and self.state.get("phase") == "sealed"

    def can_drink(self, leaf) -> bool:
        """Sealed in a shelter with water at a wall: thirst is no reason to go out."""
        return self.sealed() and bool(water_at(leaf.map, self.plan))

    def drink_step(self, leaf) -> str | None:
        """Drink from inside a sealed shelter with water at a wall while drink is below 8:
        step to the shelter cell next to the water, turn to it (water is not walkable, so
        the move only turns), strike. ``None`` when there is nothing to do."""
        obs = leaf.obs
        if not self.can_drink(leaf) or obs["vitals"]["drink"] >= 8:
            return None
        here = tuple(obs["position"])
        move_to = {v: k for k, v in MOVES.items()}
        water = water_at(leaf.map, self.plan)
        nextto = [w for w in water if abs(w[0] - here[0]) + abs(w[1] - here[1]) == 1]
        if not nextto:
            other = self.plan.i if here == self.plan.e else self.plan.e
            return move_to[(other[0] - here[0], other[1] - here[1])] if here in (self.plan.e, self.plan.i) else None
        w = nextto[0]
        facing = {"left": (-1, 0), "right": (1, 0), "up": (0, -1), "down": (0, 1)}[obs["facing"]]
        if _add(here, facing) == w:
            return "do"
        return move_to[(w[0] - here[0], w[1] - here[1])]

    def _waiting(self, obs) -> bool:
        if self.until_health is not None and obs["vitals"]["health"] < self.until_health:
            return True
        return self.until_step is not None and int(obs["step"]) < self.until_step

    @staticmethod
    def _foe_near(obs, radius: int = 4) -> bool:
        return any(o["name"] in ("zombie", "skeleton") and abs(o["dx"]) + abs(o["dy"]) <= radius
                   for o in obs["objects"])

    def step(self, leaf) -> str | None:
        obs = leaf.obs
        here = tuple(obs["position"])
        if obs["sleeping"]:
            self.slept = True
            return "noop"
        waits = self.until_health is not None or self.until_step is not None
        if not self.leaving and (self.slept or waits):
            drink = 9 if self.can_drink(leaf) else obs["vitals"]["drink"]
            if min(obs["vitals"]["food"], drink) <= 1:
                self.leaving = True  # hunger or thirst outweighs the night
        if self.leaving:
            return leave_step(leaf, self.plan) if self.plan is not None else None
        can_dig = obs["inventory"].get("wood_pickaxe", 0) > 0
        night = self.until_day and obs["daylight"] < self.day_above
        if self.plan is None and can_dig and not self.state.get("no_shelter"):
            self.plan = find_shelter(leaf.map, here, can_dig=True, radius=self.radius, stones=obs["inventory"].get("stone", 0))
            if self.plan is None:
                self.state["no_shelter"] = True
        if self.plan is None and night and not self.slept and obs["vitals"]["energy"] > 0:
            return None  # no sealed shelter: sleeping in the open at night is what zombies wait for
        if self.plan is not None and self.state.get("phase") != "sealed":
            self.building += 1
            if self.building > self.build_limit:
                # the shelter could not be reached and sealed in time (a creature in the
                # way, a cell that is not what the map says): give up this rest
                self.gave_up = True
                return None
            action = shelter_step(leaf, self.plan, self.state)
            if action is not None:
                return action
        if self.plan is None:
            if self.spot is None:
                self.spot = leaf.shelter_spot() or here
            if self.spot != here:
                move, plan = leaf.goto_action({self.spot}, stand_on_goal=True)
                if move is not None:
                    return move
                self.spot = here
        drink = self.drink_step(leaf)
        if drink is not None:
            return drink
        if not self.slept or (night and obs["vitals"]["energy"] < 9):
            return "sleep"
        if night or self._waiting(obs):
            if obs["vitals"]["energy"] < 9 and self.plan is not None:
                return "sleep"  # in a sealed shelter, sleep heals twice as fast (Crafter's _recover)
            return "noop"
        if self.plan is not None and self._foe_near(obs):
            return "noop"  # sealed in: let the zombies outside wander off before digging out
        self.leaving = True
        return leave_step(leaf, self.plan) if self.plan is not None else None
