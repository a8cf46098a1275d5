"""Running one ``ComputePlace`` leaf outside a tree, for the place tests: the leaf's blackboard
is a dict, its trace a list, and whether a reach is blocked is the caller's (reach is tested
elsewhere; these tests pin where the place goes)."""

from __future__ import annotations

from types import SimpleNamespace


def compute_place(target, snapshot, blocked=None, *, object: str, region: str, line_blocked=None, release_blocked=None,
                  **params):
    """``(board, trace records)`` after one step of ``ComputePlace`` on ``snapshot``:
    ``board["place_pose"]`` and ``board["preplace_pose"]`` are (4, 4) world tcp poses.
    ``blocked(T_pre, T_place)``, ``line_blocked(T_pre, T_place)`` (the straight lowering) and
    ``release_blocked(T_place)`` (the fingers opened there): a ``Blocked`` or None (default:
    nothing is blocked)."""
    from phyagentos.primitives.perception import ComputePlace

    leaf = ComputePlace("ComputePlace", object=object, region=region, **params)
    board = {"snapshot": snapshot}
    records: list[dict] = []
    leaf.ctx = SimpleNamespace(target=target, perceiver=None,
                               trace=SimpleNamespace(record=lambda kind, **f: records.append({"kind": kind, **f})))
    leaf.get = board.__getitem__
    leaf.set = board.__setitem__
    leaf._blocked = blocked or (lambda T_pre, T_place: None)
    leaf._line_blocked = line_blocked or (lambda T_pre, T_place: None)
    leaf._release_blocked = release_blocked or (lambda T_place: None)
    leaf.step()
    return board, records
