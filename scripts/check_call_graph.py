"""The call graph of the CANopen node's C files (firmware_c/src/slipest_co*.c) folded onto files has no
cycle: slipest_co.c (NMT, PDOs) -> slipest_co_sdo.c (SDO server) -> slipest_co_od_access.c (object
reads and writes) -> slipest_co_model.c (model lifecycle, a leaf). GCC's own call graph
(-fcallgraph-info, the one the stack bound uses) is read, so an edge hidden in a macro counts too.

    python scripts/check_call_graph.py        # prints the file edges; exit 1 on a cycle

Needs arm-none-eabi-gcc (scripts/apt-packages.txt), as `fleetlab assure` does.
"""

from __future__ import annotations

import sys

from fleetlab.assurance.sources import fw
from fleetlab.assurance.stack import StackGraph, compile_graph



def co_files() -> set[str]:
    """The CANopen sources: slipest_co.c and slipest_co_*.c (not slipest_cobs.c)."""
    return {p.name for p in (fw() / "src").glob("slipest_co*.c") if p.stem == "slipest_co" or p.stem.startswith("slipest_co_")}


def co_file_cycles(graph: StackGraph) -> tuple[dict[str, set[str]], list[list[str]]]:
    """(file -> files it calls, cycles) among the slipest_co*.c files."""
    edges = graph.file_edges(co_files())
    return edges, StackGraph(calls=edges).cycles()


def main() -> int:
    edges, cycles = co_file_cycles(compile_graph(q_only=False))
    for f in sorted(edges):
        print(f"{f} -> {', '.join(sorted(edges[f])) or '(leaf)'}")
    for c in cycles:
        print("cycle: " + " -> ".join(c), file=sys.stderr)
    print("no cycle" if not cycles else f"{len(cycles)} cycle(s)")
    return 1 if cycles else 0


if __name__ == "__main__":
    sys.exit(main())
