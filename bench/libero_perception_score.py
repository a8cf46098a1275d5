"""Per-category perception accuracy of a LIBERO bench run's first observations, against the
true poses its ground-truth records hold (scoring code: never the Agent plane).

    .venv/bin/python bench/libero_perception_score.py <bench workspace> [--out file.json]

For each episode of every bench run in the workspace: the first session's ``initial.yaml``
(the perceived snapshot before anything moved) against that session's ``ground_truth.yaml``
(``initial.objects``: the true pose of every object, robosuite's root body). Each object is
``correct`` when perceived as that object at confidence >= 0.5 within 4 cm (xy) of its true
position and nearer to it than to any other object (the root body can sit up to 3 cm off a
mesh's centre), ``wrong`` when so perceived elsewhere, ``unknown`` when reported below 0.5,
``unseen`` when absent. Prints the table per category and writes the JSON.
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

import numpy as np
import yaml
from _harness import parser, write_json

TOL_M = 0.04


def score(root: Path) -> dict[str, collections.Counter]:
    per: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for ep in sorted(root.glob("bench/*/episodes/*")):
        first = sorted(p for p in ep.glob("evidence/*-1/initial.yaml") if "-pick_" in p.parent.name)[:1]
        if not first:
            continue
        snap = yaml.safe_load(first[0].read_text(encoding="utf-8"))
        truth_doc = yaml.safe_load((first[0].parent / "ground_truth.yaml").read_text(encoding="utf-8"))["initial"]
        truth = {n: np.asarray(o["position"][:2], float) for n, o in truth_doc["objects"].items()}
        ents = {e["name"]: e for e in snap["entities"]}
        for name, p in truth.items():
            cat = name.rsplit("_", 1)[0]
            e = ents.get(name)
            if e is None:
                per[cat]["unseen"] += 1
            elif e["kind"] != "object" or (e.get("attributes") or {}).get("confidence", 0.0) < 0.5:
                per[cat]["unknown"] += 1
            else:
                q = np.asarray(e["position"][:2], float)
                d = float(np.linalg.norm(p - q))
                nearest = min((float(np.linalg.norm(r - q)) for m, r in truth.items() if m != name), default=np.inf)
                per[cat]["correct" if d < TOL_M and d < nearest else "wrong"] += 1
    return per


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_perception_score", out=False)
    ap.add_argument("workspace", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="also write the scores as JSON here (default: print only)")
    args = ap.parse_args(argv)
    per = score(args.workspace)
    if not per:
        print(f"no LIBERO bench episodes under {args.workspace}", file=sys.stderr)
        return 2
    tot: collections.Counter = collections.Counter()
    print(f"{'category':18s}   n correct wrong unknown unseen")
    for cat in sorted(per):
        c = per[cat]
        n = sum(c.values())
        tot.update(c)
        print(f"{cat:18s} {n:3d} {c['correct'] / n:7.2f} {c['wrong']:5d} {c['unknown']:7d} {c['unseen']:6d}")
    n = sum(tot.values())
    print(f"{'all':18s} {n:3d} {tot['correct'] / n:7.2f} {tot['wrong']:5d} {tot['unknown']:7d} {tot['unseen']:6d}")
    if args.out:
        write_json(args.out, {"per_category": {k: dict(v) for k, v in per.items()}, "total": dict(tot)}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
