"""Game primitives: behaviour-tree leaves acting on a ``kind: game`` target (Crafter).

========================  ==========================================================
name                      behaviour
========================  ==========================================================
game_observe              update the player's map, publish the snapshot
game_explore              walk toward unseen cells (for n steps or until X is seen)
game_goto                 go next to the nearest remembered X, exploring until seen
game_collect              strike a material until an item (or vital) reaches a count
game_hunt                 go to a creature and strike until it is defeated / eaten
game_place                place table / furnace / stone / plant in front
game_make                 make a tool; with the recipe's stations from memory or by trying
game_sleep                sleep (in the most enclosed spot nearby) until awake
game_survive              reflex: fight, drink, eat, sleep when a vital runs low
========================  ==========================================================
"""

from .base import GameLeaf
from .seen_map import SeenMap
from .survival import GameSurvive
from .tasks import GameCollect, GameExplore, GameGoto, GameHunt, GameMake, GameObserve, GamePlace, GameSleep

__all__ = ["GAME_PRIMITIVES", "GameLeaf", "SeenMap"]

#: Primitive name (as used in ``trees/game_*.yaml``) -> behaviour class.
GAME_PRIMITIVES = {
    "game_observe": GameObserve,
    "game_explore": GameExplore,
    "game_goto": GameGoto,
    "game_collect": GameCollect,
    "game_hunt": GameHunt,
    "game_place": GamePlace,
    "game_make": GameMake,
    "game_sleep": GameSleep,
    "game_survive": GameSurvive,
}
