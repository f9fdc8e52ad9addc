"""The library's C files call each other without a cycle, in every configuration CMake builds: the call graph
of every firmware_c/src/*.c file that configuration compiles, folded onto files, has no cycle, with the layer
table on and off (SLIPEST_LAYER_TABLE: the format-2 image visitor and the layer-table kernel) and the store's
image authentication on and off. Among them the CANopen node's files run slipest_co.c (NMT, PDOs) ->
slipest_co_sdo.c (SDO server) -> slipest_co_od_access.c (object reads and writes) -> slipest_co_model.c (model
lifecycle, a leaf), and the image reader's run slipest_image_buffer.c (whole-buffer reads) ->
slipest_image_stream.c (the format-neutral stream) -> slipest_image_v1.c / slipest_image_table.c (one visitor
per format, leaves among the image files). GCC's own call graph (-fcallgraph-info, the one the stack bound
uses) is read, so an edge hidden in a macro counts too.

Authentication is chosen at run time, not at build time: a store opened with SLIPEST_STORE_AUTH_HMAC_SHA256()
calls the HMAC functions that macro names through the pointers of its slipest_store_auth_t, which GCC sees
only as indirect calls. With authentication on, every slipest_store.c function that makes an indirect call is
given an edge to each of them (more edges than the store has: a cycle through them would still be found).

    python scripts/check_call_graph.py [--edges]   # one line per configuration; exit 1 on any cycle

Needs arm-none-eabi-gcc (scripts/apt-packages.txt), as `fleetlab assure` does.
"""

from __future__ import annotations

import re
import sys

from fleetlab.assurance.sources import LAYER_TABLE_SOURCES, fw, library_sources
from fleetlab.assurance.stack import StackGraph, compile_graph

STORE = "slipest_store.c"
INDIRECT = "__indirect_call"  # GCC's placeholder callee of a call through a pointer


def co_files() -> set[str]:
    """The CANopen sources: slipest_co.c and slipest_co_*.c (not slipest_cobs.c)."""
    return {p.name for p in (fw() / "src").glob("slipest_co*.c") if p.stem == "slipest_co" or p.stem.startswith("slipest_co_")}


def library_files(layer_table: bool) -> set[str]:
    """The firmware_c/src/*.c files CMake compiles into the (full) library with the layer table on or off."""
    return {p.name for p in library_sources(include_float=True) if layer_table or p.name not in LAYER_TABLE_SOURCES}


def auth_callbacks() -> list[str]:
    """The functions SLIPEST_STORE_AUTH_HMAC_SHA256() (slipest_store.h) puts in a store's authentication."""
    text = (fw() / "include" / "slipest_store.h").read_text()
    m = re.search(r"#define SLIPEST_STORE_AUTH_HMAC_SHA256\([^)]*\)\s*\\\s*\{([^}]*)\}", text)
    if not m:
        raise SystemExit("slipest_store.h: no SLIPEST_STORE_AUTH_HMAC_SHA256(key, key_len) {...} initialiser found")
    names = [n.strip() for n in m[1].split(",")][2:]  # after the key and its length
    if not names or not all(re.fullmatch(r"slipest_\w+", n) for n in names):
        raise SystemExit(f"slipest_store.h: SLIPEST_STORE_AUTH_HMAC_SHA256 names {names}, not library functions")
    return names


def with_auth(graph: StackGraph) -> StackGraph:
    """The graph of a store opened with authentication: the store's indirect calls may reach the HMAC functions."""
    callbacks = auth_callbacks()
    calls = {src: set(dsts) for src, dsts in graph.calls.items()}
    for src, dsts in calls.items():
        if graph.owner.get(src) == STORE and INDIRECT in dsts:
            dsts.update(callbacks)
    return StackGraph(frame=graph.frame, qualifier=graph.qualifier, calls=calls, owner=graph.owner)


def file_cycles(graph: StackGraph, files: set[str]) -> tuple[dict[str, set[str]], list[list[str]]]:
    """(file -> files it calls, cycles) among `files`."""
    edges = graph.file_edges(files)
    return edges, StackGraph(calls=edges).cycles()


def co_file_cycles(graph: StackGraph) -> tuple[dict[str, set[str]], list[list[str]]]:
    """(file -> files it calls, cycles) among the slipest_co*.c files."""
    return file_cycles(graph, co_files())


def configurations():
    """(name, file -> files it calls, cycles) of every configuration: layer table on/off x authentication off/on."""
    for layer_table in (True, False):
        graph = compile_graph(q_only=False, layer_table=layer_table)
        files = library_files(layer_table)
        for auth in (False, True):
            name = f"layer table {'on' if layer_table else 'off'}, authentication {'on' if auth else 'off'}"
            edges, cycles = file_cycles(with_auth(graph) if auth else graph, files)
            yield name, edges, cycles


def main(argv: list[str] | None = None) -> int:
    show_edges = "--edges" in (sys.argv[1:] if argv is None else argv)
    failed = False
    for name, edges, cycles in configurations():
        if show_edges:
            for f in sorted(edges):
                print(f"  {f} -> {', '.join(sorted(edges[f])) or '(leaf)'}")
        for c in cycles:
            print(f"{name}: cycle: " + " -> ".join(c), file=sys.stderr)
        n_edges = sum(len(d) for d in edges.values())
        print(f"{name}: {len(edges)} files, {n_edges} file edges: " +
              ("no cycle" if not cycles else f"{len(cycles)} cycle(s)"))
        failed |= bool(cycles)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
