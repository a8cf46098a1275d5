#!/usr/bin/env python3
"""CI check: no import cycles between the package's modules (issue 30, part 1).

Builds the module import graph of ``phyagentos`` with grimp (the graph import-linter
checks its contracts on; imports under ``if TYPE_CHECKING:`` are left out, they never
run) and fails (exit 1) listing every strongly connected component of more than one
module, with the direct imports that close it. Run by ``make test`` after the layer
contracts.

Usage: ``scripts/check_import_cycles.py [PACKAGE]`` (default ``phyagentos``).
"""

from __future__ import annotations

import sys

import grimp
import networkx as nx


def cycles(package: str = "phyagentos") -> list[list[tuple[str, str]]]:
    """Each import cycle of ``package`` as the direct imports (importer, imported) inside
    one strongly connected component, sorted; an empty list when there is none."""
    graph = grimp.build_graph(package, exclude_type_checking_imports=True)
    g = nx.DiGraph()
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            if imported.split(".")[0] == package:
                g.add_edge(module, imported)
    out = []
    for component in nx.strongly_connected_components(g):
        if len(component) > 1:
            out.append(sorted((a, b) for a, b in g.subgraph(component).edges))
    return sorted(out)


def main(argv: list[str]) -> int:
    package = argv[1] if len(argv) > 1 else "phyagentos"
    found = cycles(package)
    if not found:
        print(f"no import cycles in {package}")
        return 0
    for edges in found:
        modules = sorted({m for e in edges for m in e})
        print(f"import cycle among {', '.join(modules)}:")
        for a, b in edges:
            print(f"  {a} -> {b}")
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
