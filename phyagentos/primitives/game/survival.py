"""The survival reflex: a leaf that takes over while something urgent needs doing.

Used as the first child of a selector in front of a task leaf (``selector(memory:
false)[game_survive, task]``): it returns FAILURE when nothing is urgent (the task
runs), RUNNING while it handles an urgency (the task is preempted and re-plans from
the map when it resumes), and never SUCCESS. Urgencies, most pressing first:

1. ``fight``: a zombie (or skeleton) next to the player: face it and strike;
2. ``sleeping``: the game keeps the player asleep; wait;
3. ``drink``: drink below ``drink_below``: go to remembered water and drink until full;
4. ``eat``: food below ``food_below``: hunt the nearest remembered cow until the food rises;
5. ``retreat``: health below ``health_below`` and a pickaxe: heal sealed in a shelter
   (sleeping there when tired heals twice as fast), staying while zombies wait outside;
   ``flee`` from a skeleton or its arrows when hurt and no shelter is at hand (a zombie is
   fought: it follows a fleeing player);
6. ``rest``: energy below ``energy_below``, or night (daylight below ``night_below``) and a
   pickaxe to dig with: rest (:class:`~.shelter.Rest`: a sealed two-cell shelter, sleep,
   stay until daylight, dig out);
7. ``forage``: drink or food at 3 or less and no water or cow remembered: explore.

A rest whose shelter cannot be reached and sealed within 60 steps is given up (and not
tried again for 30 steps); thirst or hunger at 2 or less ends a rest.

The thresholds are skill parameters: a death diagnosed from the trace (thirst,
starvation, exhaustion) becomes a lesson that raises the matching one.
"""

from __future__ import annotations

from py_trees.common import Status

from .base import GameLeaf, facing_cell
from .seen_map import MOVES
from .shelter import Rest, find_shelter

__all__ = ["GameSurvive"]


class GameSurvive(GameLeaf):
    """Survival reflex (module doc). Thresholds are vital levels in Crafter's 0..9 units."""

    TOOLS = ("observe", "do", "sleep", "noop", "place_stone") + tuple(MOVES)

    def __init__(self, name: str, *, drink_below: int = 4, food_below: int = 4, energy_below: int = 3,
                 health_below: int = 5, night_below: float = 0.5, fight: bool = True, topup_below: int = 7,
                 near: int = 3, dusk_below: float = 0.85, max_steps: int = 100000):
        super().__init__(name, max_steps=max_steps)
        self.drink_below, self.food_below, self.energy_below = int(drink_below), int(food_below), int(energy_below)
        self.health_below = int(health_below)
        self.night_below = float(night_below)
        self.topup_below, self.near, self.dusk_below = int(topup_below), int(near), float(dusk_below)
        self.fight = bool(fight)
        self.mode: str | None = None
        self._rest: Rest | None = None
        self._food0 = 0

    def step(self):
        obs = self.obs
        v = obs["vitals"]
        px, py = obs["position"]
        threats = [(px + o["dx"], py + o["dy"]) for o in obs["objects"]
                   if o["name"] in ("zombie", "skeleton") and abs(o["dx"]) + abs(o["dy"]) == 1]
        if self.fight and threats and not obs["sleeping"]:
            self._note("fight")
            front = facing_cell(obs)
            self.act("do" if front in threats else (self.face(threats[0]) or "do"))
            return Status.RUNNING
        if obs["sleeping"]:
            self._note("sleeping")
            if self._rest is not None:
                self._rest.slept = True
            self.act("noop")
            return Status.RUNNING
        if self.mode in ("rest", "retreat") and not obs["sleeping"] and \
                ((v["drink"] <= 2 and self.map.known("water") and not (self._rest and self._rest.can_drink(self))) or
                 (v["food"] <= 2 and self.map.known("cow"))):
            self.mode, self._rest = None, None  # thirst or hunger outweighs resting: out to drink or eat
        if self.mode in ("drink", "eat") and v["health"] < self.health_below and \
                v["drink" if self.mode == "drink" else "food"] > 2:
            self.mode = None  # hurt: healing comes first unless the thirst or hunger is acute
        if self.mode == "drink" and v["drink"] >= 9:
            self.mode = None
        if self.mode == "eat" and v["food"] > self._food0:
            self.mode = None
        if self.mode is None:
            self._label = None
        falling = obs["daylight"] < getattr(self, "_day_prev", obs["daylight"])
        self._day_prev = obs["daylight"]
        weak = v["health"] < self.health_below
        # a zombie follows a fleeing player (it moves toward it 9 steps in 10); a skeleton
        # shoots along its line from up to 5 cells away: only that is worth fleeing
        foes = [o for o in obs["objects"] if o["name"] in ("skeleton", "arrow")]
        if self.mode is None:
            if v["drink"] < self.drink_below and self.map.known("water") and (not weak or v["drink"] <= 2):
                self.mode = "drink"
            elif v["food"] < self.food_below and self.map.known("cow") and (not weak or v["food"] <= 2):
                self.mode, self._food0 = "eat", v["food"]
            elif not weak and self._topup(obs, falling):
                pass  # a cow or water at hand, or dusk coming: fill up now, not at night
            elif weak and obs["inventory"].get("wood_pickaxe", 0) > 0 and self._rest_allowed(obs) and \
                    self._night_shelter(obs):
                # hurt: heal sealed in a shelter (sleeping there heals twice as fast)
                self.mode, self._rest = "retreat", Rest(until_day=False, until_health=min(9, self.health_below + 3))
            elif weak and foes:
                self._note("flee")
                action = self.flee_action()
                if action != "noop":
                    self.act(action)
                    return Status.RUNNING
            elif v["energy"] < self.energy_below:
                self.mode, self._rest = "rest", Rest(until_day=True)
                if not self._rest_allowed(obs):
                    self._rest.state["no_shelter"] = True  # the shelter failed just now: sleep where it is safest
            elif obs["daylight"] < self.night_below and obs["inventory"].get("wood_pickaxe", 0) > 0 and \
                    self._rest_allowed(obs) and self._night_shelter(obs):
                # night, and a shelter it can dig is known: rest in it until day
                self.mode, self._rest = "rest", Rest(until_day=True)
        # cows do not come back where they were eaten: look for them by day, before hunger is acute
        if self.mode is None and ((v["drink"] <= 3 and not self.map.known("water")) or
                                  (v["food"] <= (self.topup_below - 2 if obs["daylight"] > 0.7 else 3) and
                                   not self.map.known("cow"))):
            # thirsty or hungry and no water or cow remembered: look for one
            self._note("forage")
            self.act(self.explore_action())
            return Status.RUNNING
        if self.mode is None:
            return Status.FAILURE
        self._note(self._label or self.mode)
        if self.mode == "drink":
            return self._toward(self.map.cells_of(["water"]), strike=True)
        if self.mode == "eat":
            here = {(px + o["dx"], py + o["dy"]) for o in obs["objects"] if o["name"] == "cow"}
            if not here and not self.map.known("cow"):
                self.mode = None
                return Status.FAILURE
            return self._toward(here or self.map.cells_of(["cow"]), strike=True)
        action = self._rest.step(self)
        if action is None:
            if self._rest.gave_up:
                self._gave_up_at = int(obs["step"])
                self.ctx.trace.record("game_shelter_abandoned", step=obs["step"], mode=self.mode)
            self.mode, self._rest = None, None
            return Status.FAILURE
        self.act(action)
        return Status.RUNNING

    def _topup(self, obs, falling: bool) -> bool:
        """Fill up before the need is urgent (sets ``mode``; True when it did): a cow in
        view within ``near`` cells while food is below ``topup_below``, remembered water
        within ``near`` cells while drink is below it; and at dusk (daylight falling below
        ``dusk_below``) remembered water (or a cow within 8 cells) while drink (food) is
        below ``topup_below``, so the night is spent sealed in with full vitals. Recorded
        as its own reflex modes (``topup_*``, ``dusk_*``): they are not the thresholds
        that memory corrects."""
        v = obs["vitals"]
        px, py = obs["position"]
        cows = [abs(o["dx"]) + abs(o["dy"]) for o in obs["objects"] if o["name"] == "cow"]
        water = [abs(x - px) + abs(y - py) for x, y in self.map.cells_of(["water"])] if v["drink"] < self.topup_below \
            else []
        if v["drink"] < self.topup_below and water and min(water) <= self.near:
            self.mode, self._label = "drink", "topup_drink"
        elif v["food"] < self.topup_below and cows and min(cows) <= 2 * self.near:  # a cow in view is a meal
            self.mode, self._food0, self._label = "eat", v["food"], "topup_eat"
        elif falling and obs["daylight"] < self.dusk_below and v["drink"] < self.topup_below and water:
            self.mode, self._label = "drink", "dusk_drink"
        elif falling and obs["daylight"] < self.dusk_below and v["food"] < self.topup_below - 1 and \
                any(abs(x - px) + abs(y - py) <= 8 for x, y in self.map.cells_of(["cow"])):
            self.mode, self._food0, self._label = "eat", v["food"], "dusk_eat"
        return self.mode is not None

    def _rest_allowed(self, obs) -> bool:
        """Not within 30 steps of giving up on a shelter (do not loop on the same one)."""
        return int(obs["step"]) - getattr(self, "_gave_up_at", -1000) > 30

    def _night_shelter(self, obs) -> bool:
        step = int(obs["step"])
        if getattr(self, "_shelter_checked", -100) > step - 10:
            return False  # looked less than 10 steps ago and found none
        self._shelter_checked = step
        return find_shelter(self.map, tuple(obs["position"]), can_dig=True, radius=16,
                            stones=obs["inventory"].get("stone", 0)) is not None

    def _toward(self, goals, *, strike: bool):
        front = facing_cell(self.obs)
        if front in goals and strike:
            self.act("do")
            return Status.RUNNING
        move, plan = self.goto_action(goals)
        if plan is None:
            self.mode = None
            return Status.FAILURE
        self.act(move if move is not None else (self.face(plan.goal) or "do"))
        return Status.RUNNING

    def _note(self, mode: str) -> None:
        if getattr(self, "_last_note", None) != mode:
            self.ctx.trace.record("game_reflex", step=self.obs["step"], mode=mode, **self.obs["vitals"])
            self._last_note = mode
