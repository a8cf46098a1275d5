"""Ordinary phrasings rewritten into the forms the clause rules read (:mod:`.meaning`), by class.

Requests from people who had not read the rules were refused for words that change nothing of
what is asked (measured on ``bench/language_heldout_outside.yaml``: 16 of 25 plannable requests
refused, none planned wrong). Each class below is a rewrite of a *kind* of phrasing, never of a
particular sentence, into a canonical form (``put ... in ...``, ``..., then ...``, ``hold it``,
``leave ... where it is``) that :func:`.meaning.read_request` then reads and checks as before:

* **openers and filler**: polite or indirect requests (``could you please``, ``I'd like you
  to``, ``would you mind putting``), ``just``, ``go ahead and``, ``for me``, ``pls``, a leading
  ``actually``/``okay``; ``I'd like the X placed in Y`` and ``the X goes/should go in Y`` are a move;
* **sequence connectives** beyond ``then``: ``after that``, ``afterwards``, ``once that's
  done``, ``when you're done``, ``next``, ``and finally``; a subordinate clause orders the two
  (``put A in X once you've moved B to Y`` is B first, then A; ``... before you ...`` the other
  way). A connective with nothing after it is reported (:data:`DANGLING`), never dropped;
* **indifference**: ``doesn't matter which``, ``whichever``, ``any two of``, ``either``: what is
  left is a count (``any``) the clause already states or that ``the`` + a singular noun becomes;
* **exclusivity**: ``nothing else``, ``and don't touch anything else``, ``leave the rest where
  they are`` after an action: the plan does only what the clauses ask anyway, so these add nothing;
* **holding**: ``keep holding it``, ``don't let go``, ``hold on to it``, ``don't put it down``,
  ``keep it in the gripper``, ``hold it in the air``, ``pick up and keep X`` are ``hold``;
* **doing nothing**: ``don't touch anything``, ``leave it all as is``, ``never mind`` (alone),
  ``X should stay where it is``;
* **plurals and names**: ``the reds`` are ``the red ones``; ``the object called X`` is ``X``;
  ``off the table`` names the support every object starts on, not an object;
* **where possible**: ``..., if there is one`` on a by-colour clause leaves the objects whose
  colour has no region where they are, instead of refusing the request.

What is rewritten is what the meaning check then holds the plan to: the rewrites never add an
object, a destination or an action the words did not state.
"""

from __future__ import annotations

import re

__all__ = ["normalise", "DANGLING", "WHERE_POSSIBLE"]

#: Marker the normaliser leaves for a sequence connective with no clause after it.
DANGLING = "dangling_sequence_connective"
#: Canonical words for "if there is one" on a clause (read by :mod:`.meaning`).
WHERE_POSSIBLE = "where possible"

_F = re.IGNORECASE

# past participles and gerunds of the verbs the rules know -> the base form
_BASE = {"put": "put", "putting": "put", "placed": "place", "placing": "place", "moved": "move", "moving": "move",
         "set": "set", "setting": "set", "dropped": "drop", "dropping": "drop", "stacked": "stack",
         "stacking": "stack", "picked": "pick", "picking": "pick", "lifted": "lift", "lifting": "lift",
         "grabbed": "grab", "grabbing": "grab", "taken": "take", "took": "take", "taking": "take",
         "brought": "bring", "bringing": "bring", "holding": "hold", "held": "hold", "leaving": "leave",
         "left": "leave", "transferred": "transfer", "transferring": "transfer", "carried": "carry",
         "carrying": "carry", "sorted": "sort", "sorting": "sort", "shifted": "shift", "shifting": "shift",
         "relocated": "relocate", "relocating": "relocate", "slid": "slide", "sliding": "slide",
         "deposited": "deposit", "depositing": "deposit", "tossed": "toss", "tossing": "toss",
         "piled": "pile", "piling": "pile", "raised": "raise", "raising": "raise", "grasped": "grasp",
         "grasping": "grasp", "fetched": "fetch", "fetching": "fetch", "got": "get", "getting": "get",
         "moves": "move", "puts": "put", "places": "place"}
_BASES = {"put", "place", "move", "set", "drop", "stack", "pick", "lift", "grab", "take", "bring", "transfer",
          "carry", "sort", "shift", "relocate", "slide", "deposit", "toss", "pile", "raise", "grasp", "fetch", "get",
          "hold"}
_DONE = "|".join(sorted(set(_BASE) - {"left", "leaving", "holding", "held"}, key=len, reverse=True))
_DONE_OR_BASE = "|".join(sorted((set(_BASE) | _BASES) - {"left", "leaving"}, key=len, reverse=True))
_GERUND = "|".join(sorted([w for w in _BASE if w.endswith("ing")], key=len, reverse=True))
_PREP = r"(?:into|in|inside|onto|on\s+top\s+of|on|to)"

# -- openers and filler ----------------------------------------------------------------------------------------

_OPENERS = [
    r"(?:ok(?:ay)?|alright|all\s+right|right|so|hey|hi|hello|well|um+|uh+|erm|actually|now|robot|also)\s*[,!:-]\s*",
    r"(?:ok(?:ay)?|alright|so|hey|well|actually|also)\s+(?=\w)",
    r"never\s*mind\s*[,.;:!-]+\s*",
    r"(?:please|kindly|pls|plz)\s*,?\s+",
    r"i(?:'d|\s+would)\s+(?:really\s+)?(?:like|love|want)\s+(?:you|the\s+robot|the\s+arm)\s+to\s+",
    r"i\s+(?:want|need)\s+(?:you|the\s+robot|the\s+arm)\s+to\s+",
    r"i(?:'d|\s+would)\s+(?:appreciate\s+it|be\s+grateful)\s+if\s+you\s+(?:could|would|can)\s+",
    r"(?:can|could|would|will)\s+(?:you|u)\s+(?:please\s+|kindly\s+|just\s+|maybe\s+)*",
    r"(?:can|could|may)\s+i\s+(?:ask|get)\s+you\s+to\s+",
    r"(?:would|is)\s+it\s+be\s+possible\s+(?:for\s+you\s+)?to\s+",
    r"is\s+it\s+possible\s+(?:for\s+you\s+)?to\s+",
    r"are\s+you\s+able\s+to\s+",
    r"(?:if\s+you\s+(?:could|would|can)|you\s+(?:should|can|could|need\s+to|have\s+to|must))\s+",
    r"(?:go\s+ahead\s+and|go\s+and|try\s+to|try\s+and|let'?s|let\s+us|time\s+to|help\s+me)\s+",
    r"(?:just|simply)\s+",
]
_OPENER = re.compile(r"^(?:" + "|".join(_OPENERS) + r")", _F)
# "would you mind putting ..." / "do you mind putting ...": the gerund is the verb
_MIND = re.compile(r"^(?:would|do|will)\s+you\s+mind\s+(?:just\s+)?(" + _GERUND + r")\b", _F)
_TRAILERS = re.compile(
    r"(?:\s*,?\s+|\s*,\s*)(?:please|pls|plz|thanks|thank\s+you|thx|for\s+me|if\s+you\s+(?:can|could|would)|"
    r"if\s+possible|when\s+you\s+(?:can|get\s+a\s+chance)|right\s+now|now|will\s+you|would\s+you|ok(?:ay)?|"
    r"real\s+quick|quickly)\s*$", _F)
_FILLER = [
    (re.compile(r"\b(?:just|simply|go\s+ahead\s+and|kindly|please|pls|plz)\s+", _F), ""),
    (re.compile(r"\s*,?\s*\bfor\s+me\b", _F), ""),
    # "move the green block over to the back tray"
    (re.compile(r"\bover\s+(?=(?:to|into|onto|in)\b)", _F), ""),
    # "lift the cube off the table": the table is what every object stands on, not an object
    # ("from the table center" is a place on it: kept)
    (re.compile(r"\s+(?:off|from)\s+(?:of\s+)?(?:the\s+)?(?:table(?:top)?|surface|desk|floor|ground|workbench)\b"
                r"(?!\s+(?:cent(?:er|re)|middle)\b)", _F), ""),
    # "the object called dont_touch" is dont_touch
    (re.compile(r"\b(?:the\s+|a\s+)?(?:\w+\s+)?(?:object|cube|block|thing|item|one|box|piece)\s+(?:called|named|"
                r"labell?ed|marked)\s+['\"]?(\w+)['\"]?", _F), r"\1"),
    # plurals of colour words: "the reds" are the red ones
    (re.compile(r"\b(red|green|blue|yellow|orange|purple|white|black|grey|gray|pink|brown)s\b", _F), r"\1 ones"),
]
# "I'd like the yellow cube placed into the back tray": a move of the cube
_LIKE_DONE = re.compile(r"^i(?:'d|\s+would)?\s+(?:like|want|need)\s+(the\s+.+?)\s+(" + _DONE + r")\s+(" + _PREP
                        + r")\s+", _F)
# "I want the red cube in the left bin"
_LIKE_IN = re.compile(r"^i(?:'d|\s+would)?\s+(?:like|want|need)\s+(the\s+[^,;]+?)\s+(into|in|inside|onto|on)\s+", _F)
# "each cube goes into the area ...", "the red cube should go in the left bin"
# the subject of _GOES/_STAYS: no auxiliary or negation inside it ("the red cube could be ...", "should not be")
_SUBJECT = r"(?:(?!\b(?:could|can|might|may|would|will|is|are|was|were|not|never|should|must|needs?|has|have|shouldn|"\
           r"mustn|doesn|don|isn|aren|won|wouldn|couldn|cannot)\b)[^,;:'])*?"
_GOES = re.compile(r"^((?:the|each|every|all|both|any|a|an)\b" + _SUBJECT + r")\s+(?:should|must|needs?\s+to|has\s+to|"
                   r"have\s+to)?\s*(?:go|goes|be|end\s+up|ends\s+up|belongs?)\s+(" + _PREP + r")\s+",
                   _F)
# "the red cube should stay where it is"
_STAYS = re.compile(r"^((?:the|each|every|all|both|everything|it|they)\b" + _SUBJECT + r")\s+(?:should|must|needs?\s+to|has\s+to|"
                    r"have\s+to|can|will)?\s*(?:stay|stays|remain|remains)\s+(?:put\b|where|in\s+place|as\s+|there\b)",
                    _F)
_HEADS = re.compile(r"^(?:tidy\s+up|clean\s+up|here'?s\s+(?:what|the\s+plan)[^:]*|the\s+task|task|instructions?|"
                    r"organi[sz]e\s+(?:things|the\s+table|everything))\s*[:-]\s*(?=\S)", _F)

# -- sequence connectives ------------------------------------------------------------------------------------

_CONNECTIVE = (r"(?:after\s+that|after\s+this|afterwards?|and\s+then\s+after\s+that|subsequently|following\s+that|"
               r"once\s+(?:that|this|it)(?:'s|\s+is|\s+has\s+been)\s+(?:done|finished|complete|over)|"
               r"when\s+(?:that|this|it)(?:'s|\s+is|\s+has\s+been)\s+(?:done|finished|complete|over)|"
               r"once\s+(?:you(?:'re|\s+are)\s+)?(?:done|finished)(?:\s+with\s+(?:that|this|it))?|"
               r"when\s+(?:you(?:'re|\s+are)\s+)?(?:done|finished)(?:\s+with\s+(?:that|this|it))?|"
               r"and\s+next|and\s+(?:finally|lastly)|then\s+finally)")
# words that are a connective only after a comma or a full stop ("the second cube" is not one)
_WEAK = r"(?:next(?!\s+to\b)|finally|lastly|secondly|second|thirdly|third|later)"
_SEQ_INNER = re.compile(r"(?:\s*(?:[,;.]\s*|\s+)(?:and\s+)?(?:then\s+)?" + _CONNECTIVE + r"|\s*[,;.]\s*(?:and\s+)?"
                        + _WEAK + r")\s*,?\s+(?:then\s+)?", _F)
_SEQ_END = re.compile(r"(?:\s*[,;.]?\s*(?:and\s+)?(?:then|" + _CONNECTIVE + r")|\s*[,;.]\s*(?:and\s+)?" + _WEAK
                      + r")\s*[,.;]?\s*$", _F)
_SEQ_START = re.compile(r"^(?:then|and\s+then|" + _CONNECTIVE + r")\s*[,]?\s*(?=\w)", _F)
_FIRST = re.compile(r"^(?:first(?:ly)?|first\s+of\s+all|to\s+start(?:\s+with)?|to\s+begin(?:\s+with)?)\s*,?\s+", _F)
_SUB = r"(?:once|after|when)\s+(?:you(?:'ve|\s+have|'re\s+done|\s+are\s+done)?\s+|having\s+)?(?:done\s+)?"
# "once you've moved B to Y, put A in X" -> "move B to Y, then put A in X"
_SUB_FIRST = re.compile(r"^" + _SUB + r"(" + _DONE_OR_BASE + r")\s+([^,;]+?)\s*,\s*(?:then\s+)?(.+)$", _F)
# "put A in X once you've moved B to Y" -> "move B to Y, then put A in X"
_SUB_LAST = re.compile(r"^(.+?)\s*,?\s+" + _SUB + r"(" + _DONE + r")\s+([^,;]+)$", _F)
# "put A in X before you move B to Y" -> "put A in X, then move B to Y"; and the other way round
_BEFORE_LAST = re.compile(r"^(.+?)\s*,?\s+before\s+(?:you\s+)?(" + _DONE_OR_BASE + r")\s+([^,;]+)$", _F)
_BEFORE_FIRST = re.compile(r"^before\s+(?:you\s+)?(" + _DONE_OR_BASE + r")\s+([^,;]+?)\s*,\s*(.+)$", _F)

# -- indifference and exclusivity -------------------------------------------------------------------------------

_INDIFFERENT = re.compile(
    r"\s*(?:[,;.-]\s*|\s+)(?:then\s+)?(?:(?:it\s+)?(?:doesn'?t|does\s+not|don'?t|do\s+not)\s+matter\s+which(?:\s+(?:ones?|cubes?|"
    r"blocks?|of\s+them|two|three))?|no\s+matter\s+which(?:\s+ones?)?|i\s+(?:don'?t|do\s+not)\s+(?:mind|care)\s+"
    r"which(?:\s+ones?)?|(?:any|whichever|either)(?:\s+ones?)?\s+(?:will\s+do|is\s+fine|are\s+fine|works)|"
    r"(?:you\s+)?(?:can\s+)?(?:choose|pick|decide)\s+which(?:\s+ones?)?|your\s+choice|whichever\s+you\s+"
    r"(?:like|want|prefer))\s*$", _F)
_ANY_COUNT = re.compile(r"\b(?:any|whichever|either)\s+(?=(?:one|two|three|four|five|[1-5])\b)", _F)
_EITHER = re.compile(r"\beither\s+(?:one\s+)?of\s+", _F)
_EITHER_ONE = re.compile(r"\beither\b(?!\s+of\b)", _F)
_WHICHEVER = re.compile(r"\bwhichever\s+((?:\w+\s+)?(?:cube|block|one|object))(?:\s+you\s+(?:like|want|prefer))?\b",
                        _F)
_SINGULAR_THE = re.compile(r"\b(" + "|".join(sorted(_BASES - {"hold"})) + r")(\s+up)?\s+the\s+((?:\w+\s+)?(?:cube|block|"
                           r"object|one|thing|item|piece))\b", _F)
_EXCLUSIVE = re.compile(
    r"\s*(?:[,;.-]\s*|\s+)(?:then\s+)?(?:and\s+|but\s+)?(?:(?:and\s+)?(?:do\s+)?(?:nothing|no\s+other)\s+(?:else|more|other\s+(?:cubes?|"
    r"blocks?|objects?))|(?:do\s+not|don'?t|never)\s+(?:touch|move|disturb)\s+(?:anything(?:\s+else)?|the\s+"
    r"(?:rest|others)|any(?:thing|\s+of\s+the\s+others|\s+other\s+(?:cubes?|blocks?|objects?|ones?))(?:\s+else)?)|"
    r"leave\s+(?:the\s+rest|everything\s+else|all\s+the\s+others?|the\s+others?|the\s+other\s+(?:cubes?|blocks?|"
    r"objects?|ones?))(?:\s+(?:where\s+they\s+are|alone|as\s+they\s+are|as\s+is|untouched|in\s+place))?|"
    r"(?:do\s+not|don'?t)\s+do\s+anything\s+else|(?:and\s+)?only\s+(?:that|this)(?:\s+one)?)\s*$", _F)

# -- holding and doing nothing ----------------------------------------------------------------------------------

_HOLD = [
    # "pick up and keep the red cube" / "grab and hold the red cube"
    (re.compile(r"\b(?:pick\s+up|lift\s+up|lift|grab|take|pick|get|raise|grasp)\s+and\s+(?:keep|hold)(?:\s+on\s+to|"
                r"\s+onto)?\s+(?!it\b|them\b)", _F), "hold "),
    (re.compile(r"\b(?:keep|continue|carry\s+on)\s+(?:on\s+)?(?:holding|gripping|grasping|clutching)(?:\s+on)?"
                r"(?:\s+(?:to|onto))?\b", _F), "hold"),
    (re.compile(r"\b(?:keep|have|get)\s+(?:a\s+)?(?:firm\s+)?(?:hold|grip|grasp)\s+(?:of|on)\b", _F), "hold"),
    (re.compile(r"\b(?:hold|hang)\s+(?:on\s+to|onto)\b", _F), "hold"),
    (re.compile(r"\b(?:do\s+not|don'?t|never)\s+(?:let\s+(?:it|them)\s+go|let\s+go(?:\s+of\s+(it|them))?|release\s+"
                r"(it|them)|drop\s+(it|them)|put\s+(it|them)\s+(?:back\s+)?down|set\s+(it|them)\s+(?:back\s+)?down|"
                r"put\s+down\s+(it|them))\b(?=\s*(?:$|[,;.]|(?:and|until|while|for)\b))", _F), "hold it"),
    (re.compile(r"\bkeep\s+(it|them)(?:\s+(?:up|raised|lifted|aloft|held|in\s+hand|in\s+the\s+air|in\s+(?:the|your)"
                r"\s+(?:gripper|hand|hands|grip|fingers|claw)))?(?=\s*(?:$|[,;.]|\s+and\b|\s+for\b))", _F), r"hold \1"),
]
# what a hold may say about where it is held: nothing for the plan
_HELD_WHERE = re.compile(r"\b(hold|holding|lift|raise)\b([^,;]*?)\s+(?:up\s+)?(?:in\s+the\s+air|up\s+high|high|"
                         r"aloft|above\s+the\s+table|steady|there|in\s+(?:the|your|its)\s+(?:gripper|hand|hands|"
                         r"grip|fingers|claw))(?=\s*(?:$|[,;.]|\s+and\b|\s+for\b|\s+until\b))", _F)
_HOLD_FOR = re.compile(r"\b(hold|holding)\b([^,;]*?)\s+(?:for\s+(?:now|a\s+(?:while|moment|bit|second|few\s+seconds))|"
                       r"until\s+(?:i\s+say\s+(?:so|otherwise)|further\s+notice|told\s+otherwise|i\s+tell\s+you\s+"
                       r"otherwise))\b", _F)
_NOTHING = [
    (re.compile(r"^(?:never\s*mind|forget\s+(?:it|about\s+it)|cancel\s+(?:that|it)|nothing\s+for\s+now|"
                r"no\s+need\s+to\s+(?:do|move)\s+anything|don'?t\s+do\s+a\s+thing)\s*[.!]*$", _F), "do nothing"),
    # "don't touch anything", "do not disturb the red cube": not moving it
    (re.compile(r"\b(do\s+not|don'?t|never)\s+(?:touch|disturb|mess\s+(?:around\s+)?with|handle|bother(?:\s+with)?|"
                r"play\s+with|interfere\s+with)\b", _F), r"\1 move"),
]


def _ordered(segment: str) -> str:
    """A subordinate clause of time (``once you've ...``, ``before you ...``) as ``first, then second``."""
    m = _SUB_FIRST.match(segment)
    if m:
        return f"{_BASE.get(m.group(1).lower(), m.group(1))} {m.group(2)}, then {m.group(3)}"
    m = _SUB_LAST.match(segment)
    if m:
        return f"{_BASE.get(m.group(2).lower(), m.group(2))} {m.group(3)}, then {m.group(1)}"
    m = _BEFORE_FIRST.match(segment)
    if m:
        return f"{m.group(3)}, then {_BASE.get(m.group(1).lower(), m.group(1))} {m.group(2)}"
    m = _BEFORE_LAST.match(segment)
    if m:
        return f"{m.group(1)}, then {_BASE.get(m.group(2).lower(), m.group(2))} {m.group(3)}"
    return segment


def _clause(text: str) -> str:
    """One segment (between sequence separators) with its opener, filler and trailers read."""
    t = text.strip(" ,")
    for _ in range(6):
        before = t
        m = _MIND.match(t)
        if m:
            t = _BASE[m.group(1).lower()] + t[m.end():]
        t = _OPENER.sub("", t).strip(" ,")
        t = _TRAILERS.sub("", t).strip(" ,")
        if t == before:
            break
    m = _LIKE_DONE.match(t)
    if m:
        t = f"{_BASE.get(m.group(2).lower(), m.group(2))} {m.group(1)} {m.group(3)} " + t[m.end():]
    else:
        m = _LIKE_IN.match(t)
        if m:
            t = f"put {m.group(1)} {m.group(2)} " + t[m.end():]
    m = _GOES.match(t)
    if m:
        t = f"put {m.group(1)} {m.group(2)} " + t[m.end():]
    m = _STAYS.match(t)
    if m:
        t = f"leave {m.group(1)} where it is"
    return t


def normalise(request: str) -> str:
    """``request`` with the phrasing classes of the module docstring rewritten into the rules' forms; a
    sequence connective with nothing after (or before) it is left as :data:`DANGLING`, which the reader
    refuses."""
    t = request.translate(str.maketrans({"\u2019": "'", "\u2018": "'", "\u201c": '"', "\u201d": '"',
                                         "\u2013": "-", "\u2014": "-"}))
    t = re.sub(r"\s+", " ", t).strip()
    t = re.sub(r"[?!]+", ".", t).strip(" .")
    # "never mind - leave everything" / "sort them by colour - reds into ...": a spaced dash after a head that
    # puts nothing anywhere is a colon; after a destination ("... in the left bin - the blue one ...") a comma
    dash = re.search(r"\s+-+\s+", t)
    if dash and ":" not in t and not re.search(r"\b(?:in|into|on|onto|to|inside)\b", t[:dash.start()], _F):
        t = t[:dash.start()] + ": " + t[dash.end():]
    t = re.sub(r"\s+-+\s+", ", ", t)
    t = _HEADS.sub("", t)
    for pattern, repl in _NOTHING[:1]:
        if pattern.match(t):
            return repl
    t = _clause(t)
    t = _FIRST.sub("", t)
    if _SEQ_START.match(t) or _SEQ_END.search(t):
        return DANGLING
    t = _SEQ_INNER.sub(", then ", t)
    # sentences: "Put A in X. Then put B in Y." -> a sequence
    t = re.sub(r"\.\s+(?:then\s+)?", ", then ", t, flags=_F)
    t = re.sub(r"\b(then)\s+then\b", r"\1", t, flags=_F)
    segments = re.split(r"(\s*,\s*then\s+|\s*;\s*|:\s*)", t)
    out = []
    for seg in segments:
        if re.fullmatch(r"\s*,\s*then\s+|\s*;\s*|:\s*", seg or " "):
            out.append(seg)
            continue
        seg = _clause(seg)
        seg = _ordered(seg)
        if re.match(r"(?:once|after|when|before|until|while)\s+(?:you|i|having)\b", seg, _F):
            return DANGLING  # "after you put the red cube in the left bin": no main clause to order it with
        out.append(seg)
    t = "".join(out)
    if re.search(r"(?:^|,\s*then\s*)$|^\s*,?\s*then\b", t.strip(), _F):
        return DANGLING
    t = _INDIFFERENT.sub(" \x00", t)
    indifferent = "\x00" in t
    t = t.replace(" \x00", "")
    t = _EXCLUSIVE.sub("", t)
    if re.search(r",\s*if\s+(?:there\s+is|there'?s)\s+(?:one|any)\b|\bif\s+any\b|\bwhere\s+(?:there\s+is\s+one|"
                 r"possible)\b", t, _F):
        t = re.sub(r"\s*,?\s*(?:if\s+(?:there\s+is|there'?s)\s+(?:one|any)|if\s+any|where\s+(?:there\s+is\s+one|"
                   r"possible))\b", "", t, flags=_F) + " " + WHERE_POSSIBLE
    for pattern, repl in _FILLER + _HOLD + _NOTHING[1:]:
        t = pattern.sub(repl, t)
    for _ in range(2):
        t = _HELD_WHERE.sub(r"\1\2", t)
        t = _HOLD_FOR.sub(r"\1\2", t)
    t = _ANY_COUNT.sub("", t)
    t = _EITHER.sub("one of ", t)
    t = _EITHER_ONE.sub("any", t)
    t = _WHICHEVER.sub(r"any \1", t)
    if indifferent and not re.search(r"\b(?:any|a|an|one|two|three|four|five|[1-5])\b", t, _F):
        t = _SINGULAR_THE.sub(lambda m: f"{m.group(1)}{m.group(2) or ''} any {m.group(3)}", t, count=1)
    return re.sub(r"\s+", " ", t).strip(" ,.")
