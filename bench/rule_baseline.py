"""BASELINE, not the planner: a rule-based intent parser posing as a model client.

It answers the Goal Planner's prompt with the same JSON a model would, from regular
expressions over the request and the scene lines of the prompt, so that its plans go
through exactly the same checks (policy, grounding, selector, validator) and the same
scoring as the model's. It exists only to show what the language suite asks for; it is
used by ``bench/language.py --baseline`` and nowhere else.
"""

from __future__ import annotations

import json
import re

from phyagentos.llm import LLMCall, LLMReply

__all__ = ["RuleBaselineClient"]


class RuleBaselineClient:
    provider, model = "rules", "baseline-intent-parser"

    def complete(self, messages, *, schema=None, max_tokens=256, purpose="chat"):
        text = messages[-1]["content"]
        scene = dict(re.findall(r"^- ([a-z0-9_]+): (.+)$", text, re.M))
        request = text.rsplit("Request:", 1)[-1].strip().lower()
        objects = {n: d for n, d in scene.items() if not d.endswith("region")}
        regions = [n for n, d in scene.items() if d.endswith("region")]

        def obj(words: str) -> str | None:
            for n, d in objects.items():
                if any(w in d.split() for w in words.split() if w not in ("cube", "the", "one")):
                    return n
            return None

        def region(words: str) -> str | None:
            for n in regions:
                if n.replace("_", " ") in words or n in words or scene[n].split()[0] in words.split():
                    return n
            return None

        steps = []
        if m := re.search(r"stack the (\w+) cube on the (\w+) cube", request):
            a, b = obj(m.group(1)), obj(m.group(2))
            steps = [(a, f"on_{b}")] if a and b else []
        elif "except" in request:
            keep = obj(request.split("except", 1)[1].split(" in ")[0])
            r = region(request.rsplit(" in ", 1)[-1])
            steps = [(o, r) for o in objects if o != keep]
        elif m := re.search(r"put (two|three) cubes in the (.+)", request):
            n = {"two": 2, "three": 3}[m.group(1)]
            steps = [(o, region(m.group(2))) for o in list(objects)[:n]]
        elif "colour" in request or "color" in request:
            steps = [(o, next((r for r in regions if scene[r].split()[0] == objects[o].split()[0]), None))
                     for o in objects]
        elif "size" in request:
            large = next((o for o, d in objects.items() if "large" in d), None)
            small = next((o for o, d in objects.items() if "small" in d), None)
            steps = [(large, region(request.split("large", 1)[1].split(",")[0])),
                     (small, region(request.split("small", 1)[1]))]
        else:
            for clause in re.split(r",? then |, and | and then ", request):
                if m := re.search(r"the (\w+ ?\w*?) cube (?:in|into|to|on) the (.+)", clause):
                    steps.append((obj(m.group(1)), region(m.group(2))))
        if not steps or any(o is None or d is None for o, d in steps):
            answer = {"decision": "refuse", "reason": "unknown_object", "steps": []}
        else:
            answer = {"decision": "plan", "reason": "none",
                      "steps": [{"skill": "pick_and_place", "object": o, "destination": d} for o, d in steps]}
        out = json.dumps(answer)
        return LLMReply(text=out, call=LLMCall(self.provider, self.model, purpose, "-", 0, 0, 0.0, 0.0, 0, False))
