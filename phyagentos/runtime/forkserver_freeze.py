"""Imported only by the runner forkserver, last in its preload list: freezes what the
preload created (:func:`gc.freeze`).

Runners and the whole-graph check are forked from the forkserver and share its pages
(MuJoCo, SciPy, toppra, mink, the primitives: several hundred thousand
objects) copy-on-write. Without the freeze, every full collection in a child walks all
of those objects, writes their GC headers and so copies their pages; with it the
collector leaves them alone (they were never garbage: modules live as long as the
process). CPython documents this use for pre-fork servers (``gc.freeze``, Python 3.7+).
Measured on ``phyagentos run pick_and_place``: the forkserver and its
children used 3.52 s of CPU before, 3.20-3.44 s after (docs/PERFORMANCE.md, round 5).
"""

import gc

__all__: list[str] = []

gc.freeze()
