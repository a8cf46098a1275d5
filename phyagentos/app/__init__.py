"""The application layer: the composition roots that use both planes.

- :mod:`.orchestrator`: a goal graph through both planes in one process (``phyagentos run``);
- :mod:`.graph_check` and :mod:`.graph_check_process`: the whole-graph check before motion;
- :mod:`.mcp_server`: the ToolRegistry as an MCP server;
- :mod:`.factories`: the Goal Planner, revisers and default scene, wired to the Runtime's reach oracle.

The CLI (:mod:`phyagentos.cli`), the view and the benchmarks sit above it; the planes below
it never import it (``.importlinter``).
"""
