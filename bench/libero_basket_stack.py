"""A second can let go into a basket that holds one, on generated scenes: does the verifier's
``on(can, basket)`` hold, and is the first can still seen?

    .venv/bin/python bench/libero_basket_stack.py [--seeds 95000-95019] [--cases top,table]
        [--workspace /tmp/ws_10] [--out bench/results/libero_basket_stack.json]

LIBERO-10 task 0's world ("put both the alphabet soup and the tomato sauce in the basket"),
scenes from LIBERO's placement sampler with seeds from 95000 (never an init state). Each scene:
one perception at the start pose (both cameras); the alphabet soup set upright in the basket's
middle and let go there (the perceiver told, as proprioception would tell it, that the hand held
it at its pose and opened), one perception; then the tomato sauce set

- ``top``: upright on the soup (where the bench's place into the basket's middle leaves it),
- ``beside``: beside the soup along the basket's long side, in the basket,
- ``table``: on the table 5 cm in front of the basket (not in it: the verdict must not be
  ``satisfied``),

and let go with the hand 10 cm above it (the place's look straight down after the release, the
hand solved by IK), one perception there; then the arm back at its start pose and one perception
more (the place's ``ObserveAfterPlace``). The declared scene is the LIBERO bench's (looks measured
on generated scenes, cached in the workspace). Scoring (here only): the true boxes. Prints, per
scene and case, the confidences of the basket and both cans at each look and the verifier's
verdicts of ``on(sauce, basket)`` and ``on(soup, basket)`` at the last; then the totals.
"""

from __future__ import annotations

import json
import time

import mujoco
import numpy as np
from _harness import index_range, parser, write_json
from _libero_scene import fresh_perceiver, generated_scene

from phyagentos.agent.criteria import evaluate, parse_criteria
from phyagentos.motion.ik import solve_ik
from phyagentos.perception.perceiver import _pose
from phyagentos.primitives.motion import ik_options
from phyagentos.primitives.observation import perceive_now
from phyagentos.targets.libero import LiberoTarget
from phyagentos.targets.libero.descriptors import _free_adr, object_boxes

SOUP, SAUCE, BASKET = "alphabet_soup_1", "tomato_sauce_1", "basket_1"
CASES = ("top", "beside", "table")
#: How far (m) above the let-go can's top the hand looks straight down (the place's retreat).
LOOK_DOWN_M = 0.10
#: Two cans side by side along the basket's long side: each centre this far (m) from its middle.
BESIDE_M = 0.036


def _centre(target, obj: str) -> np.ndarray:
    lo, hi = object_boxes(target)[obj]
    return 0.5 * (lo + hi)


def _set(target, obj: str, xy, bottom_z: float) -> None:
    """``obj``'s true box centred over ``xy`` (world, m), its bottom at ``bottom_z``; 1.5 s of physics."""
    m, d = target.model, target._data
    lo, hi = object_boxes(target)[obj]
    body = m.body(target.object_body(obj)).id
    qadr, _ = _free_adr(m, int(m.body_rootid[body]))
    d.qpos[qadr:qadr + 2] += np.asarray(xy, dtype=float) - 0.5 * (lo + hi)[:2]
    d.qpos[qadr + 2] += float(bottom_z - lo[2])
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=1.5)


def _let_go(perceiver, target, obj: str) -> None:
    """Tell the perceiver what proprioception would: the hand held ``obj`` at its true pose and
    has opened (the next observation notices the release)."""
    t = perceiver.tracks[obj]
    tcp = np.asarray(target.proprioception().tcp_pose, dtype=float)
    t.held, t.placed_xy = True, None
    t.grasp_offset = np.linalg.inv(tcp) @ _pose(_centre(target, obj), t.yaw)
    perceiver._held = obj


def _look_down(target, perceiver, obj: str) -> dict:
    """The hand :data:`LOOK_DOWN_M` above ``obj``'s top, ``obj`` let go there, one perception;
    then the arm back where it was."""
    home = np.asarray(target.arm_qpos(), dtype=float).copy()
    c, top = _centre(target, obj), float(object_boxes(target)[obj][1][2])
    T = np.asarray(target.proprioception().tcp_pose, dtype=float).copy()
    T[:3, 3] = [c[0], c[1], top + LOOK_DOWN_M]
    sol = solve_ik(target.model, q_seed=home, target=T, qpos_full=target._data.qpos.copy(), **ik_options(target))
    target.hold(np.asarray(sol.q), duration_s=2.5)
    _let_go(perceiver, target, obj)
    snap = perceive_now(target, perceiver)
    target.hold(home, duration_s=2.5)
    return snap


def _seen(snap: dict) -> dict:
    by_name = {e["name"]: e for e in snap["entities"] if e["kind"] == "object"}
    out = {n: (None if n not in by_name else round(float(by_name[n]["attributes"].get("confidence", 0.0)), 2))
           for n in (BASKET, SOUP, SAUCE)}
    out["unknown"] = sum(1 for n in by_name if n.startswith("unknown"))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_basket_stack")
    ap.add_argument("--seeds", default="95000-95019")
    ap.add_argument("--cases", default="top,table", help=f"comma-separated, of {', '.join(CASES)}")
    ap.add_argument("--workspace", default="/tmp/ws_10", help="where the looks are cached")
    args = ap.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    bad = [c for c in cases if c not in CASES]
    if bad:
        ap.error(f"unknown case(s) {', '.join(bad)}; valid: {', '.join(CASES)}")
    scene = generated_scene(args.workspace, "libero_10", 0)
    [on_sauce] = parse_criteria({"on": {"object": SAUCE, "support": BASKET}})
    [on_soup] = parse_criteria({"on": {"object": SOUP, "support": BASKET}})
    rows = []
    seeds = index_range(args.seeds)
    with LiberoTarget("basket_stack", scene, seed=seeds[0]) as target:
        for seed in seeds:
            for case in cases:
                t0 = time.perf_counter()
                perceiver = fresh_perceiver(target, seed)
                start = perceive_now(target, perceiver)
                blo, bhi = object_boxes(target)[BASKET]
                middle = 0.5 * (blo + bhi)
                long_axis = int(np.argmax((bhi - blo)[:2]))
                xy = middle[:2].copy()
                if case == "beside":
                    xy[long_axis] -= BESIDE_M
                _set(target, SOUP, xy, float(blo[2]) + 0.03)
                _let_go(perceiver, target, SOUP)
                after_soup = perceive_now(target, perceiver)
                slo, shi = object_boxes(target)[SOUP]
                if case == "top":
                    _set(target, SAUCE, 0.5 * (slo + shi)[:2], float(shi[2]) + 0.005)
                elif case == "beside":
                    xy = middle[:2].copy()
                    xy[long_axis] += BESIDE_M
                    _set(target, SAUCE, xy, float(blo[2]) + 0.03)
                else:
                    _set(target, SAUCE, [float(blo[0]) - 0.05, float(middle[1])], float(blo[2]) + 0.003)
                down = _look_down(target, perceiver, SAUCE)
                final = perceive_now(target, perceiver)
                sc = _centre(target, SAUCE)
                v_sauce, v_soup = evaluate(on_sauce, start, final), evaluate(on_soup, start, final)
                row = {"seed": seed, "case": case,
                       "sauce_over_basket_true": bool(np.all(sc[:2] > blo[:2]) and np.all(sc[:2] < bhi[:2])),
                       "after_soup": _seen(after_soup), "look_down": _seen(down), "final": _seen(final),
                       "on_sauce": v_sauce.status, "on_soup": v_soup.status, "reason": v_sauce.reason[:200],
                       "s": round(time.perf_counter() - t0, 1)}
                rows.append(row)
                print(json.dumps(row), flush=True)
    totals = {}
    for case in cases:
        rs = [r for r in rows if r["case"] == case]
        totals[case] = {"scenes": len(rs),
                        **{f"on_sauce_{s}": sum(r["on_sauce"] == s for r in rs)
                           for s in ("satisfied", "unknown", "unsatisfied")},
                        "on_soup_satisfied": sum(r["on_soup"] == "satisfied" for r in rs)}
    print(json.dumps(totals))
    write_json(args.out, {"rows": rows, "totals": totals}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
