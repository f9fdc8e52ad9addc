"""Worst-case stack of every public entry point on Cortex-M4, from GCC's own numbers.

Each library file is cross-compiled with the target's flags plus ``-fstack-usage
-fcallgraph-info=su``; the .ci files give every function's frame size and its call edges.
The worst case of a function is its frame plus the worst case of its deepest callee. A cycle
in the call graph would make that unbounded, so the graph is checked for cycles first (no
recursion proof); a frame GCC marks dynamic, or a call to a function with no frame size
(a libc routine), is listed, not silently counted as zero.

    fleetlab assure stack [--bundle DIR] [--full]
"""
from __future__ import annotations

import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from fleetlab.host_tools.firmware import targets as target_registry
from .sources import LAYER_TABLE_SOURCES, fw, generate_dbc, include_dirs, library_sources, need, public_headers, run

KERNEL_OPT = "-O3"   # firmware_c/cmake/target.cmake: inference kernels
FRAME_OPT = "-Os"    # ... and per-frame code
KERNELS = ("slipest_infer_q.c", "slipest_infer_table_q.c", "slipest_infer_f32.c", "slipest_features_f32.c")

_NODE = re.compile(r'node: \{ title: "(?P<title>[^"]+)" label: "(?P<label>[^"]*)"')
_EDGE = re.compile(r'edge: \{ sourcename: "(?P<src>[^"]+)" targetname: "(?P<dst>[^"]+)"')
_SIZE = re.compile(r"\\n(\d+) bytes \(([a-z,]+)\)$")
# stack an `asm` statement takes below sp, which -fstack-usage does not see; the C source states it next to
# the function, in a comment "asm-stack(FUNCTION): N bytes", and it is added to the function's frame
_ASM_STACK = re.compile(r"asm-stack\((\w+)\): (\d+) bytes")


@dataclass
class StackGraph:
    frame: dict = field(default_factory=dict)      # title -> bytes
    qualifier: dict = field(default_factory=dict)  # title -> static / dynamic / dynamic,bounded
    calls: dict = field(default_factory=dict)      # title -> set of titles
    owner: dict = field(default_factory=dict)      # title -> name of the source file that defines it

    def file_edges(self, files: set[str]) -> dict[str, set[str]]:
        """The call graph folded onto source files: which of `files` calls into which other of them."""
        out: dict[str, set[str]] = {f: set() for f in files}
        for src, dsts in self.calls.items():
            a = self.owner.get(src)
            for dst in dsts:
                b = self.owner.get(dst)
                if a in files and b in files and a != b:
                    out[a].add(b)
        return out

    def cycles(self) -> list[list[str]]:
        """Every back edge found by an iterative DFS, as the cycle it closes."""
        found, state = [], {}
        for root in sorted(self.calls.keys() | self.frame.keys()):
            if root in state:
                continue
            stack = [(root, iter(sorted(self.calls.get(root, ()))))]
            path = [root]
            state[root] = "open"
            while stack:
                node, it = stack[-1]
                nxt = next(it, None)
                if nxt is None:
                    state[node] = "done"
                    stack.pop()
                    path.pop()
                elif state.get(nxt) == "open":
                    found.append(path[path.index(nxt):] + [nxt])
                elif nxt not in state:
                    state[nxt] = "open"
                    path.append(nxt)
                    stack.append((nxt, iter(sorted(self.calls.get(nxt, ())))))
        return found

    def worst(self, fn: str) -> tuple[int, list[str], set[str]]:
        """(bytes, deepest call chain, callees without a known frame) — needs an acyclic graph."""
        memo: dict[str, tuple[int, list[str], set[str]]] = {}
        order, seen = [], set()
        todo = [(fn, False)]
        while todo:  # post-order without recursion
            node, expanded = todo.pop()
            if expanded:
                order.append(node)
                continue
            if node in seen:
                continue
            seen.add(node)
            todo.append((node, True))
            todo.extend((c, False) for c in self.calls.get(node, ()))
        for node in order:
            unknown = set() if node in self.frame else {node}
            best, chain = 0, []
            for c in sorted(self.calls.get(node, ())):  # of equal callees the first by name: the same report every run
                b, ch, u = memo[c]
                unknown |= u
                if b > best:
                    best, chain = b, ch
            memo[node] = (self.frame.get(node, 0) + best, [node] + chain, unknown)
        return memo[fn]


# the QEMU cost image's stack painter measures these wrappers (firmware_c/target/bench_target.c)
BENCH_WRAPPERS = {"stack_q": "one_q", "stack_node_window": "node_last_frame"}


def compile_graph(bundle: Path | None = None, q_only: bool = True, with_bench: bool = False,
                  layer_table: bool = True) -> StackGraph:
    """GCC's call graph of the library as CMake builds it; layer_table=False: SLIPEST_LAYER_TABLE=0, without the
    sources CMake then leaves out (LAYER_TABLE_SOURCES)."""
    gcc = need("arm-none-eabi-gcc")
    graph = StackGraph()
    with tempfile.TemporaryDirectory() as tmp:
        gen = generate_dbc(Path(tmp) / "generated", bundle)
        incs = [f"-I{d}" for d in include_dirs(bundle, gen.parent)]
        defs = (["-DSLIPEST_Q_ONLY"] if q_only else []) + ([] if layer_table else ["-DSLIPEST_LAYER_TABLE=0"])
        bench = fw() / "target" / "bench_target.c"
        lib = [f for f in library_sources(include_float=not q_only) if layer_table or f.name not in LAYER_TABLE_SOURCES]
        for i, src in enumerate([*lib, gen] + ([bench] if with_bench else [])):
            opt = KERNEL_OPT if src.name in KERNELS else FRAME_OPT
            extra = []
            if src == bench:  # as target.cmake builds the cost image
                opt = KERNEL_OPT
                extra = ["-fno-shrink-wrap", '-DSLIPEST_VECTORS_PATH="unused"', f"-I{fw() / 'target'}", f"-I{fw() / 'common'}"]
            obj = Path(tmp) / f"{i}_{src.stem}.o"
            # the reference target's flags: the CPU whose painted stack bench c measures
            run([gcc, *target_registry.reference().cpu_flags, "-std=c99", opt, "-ffunction-sections", "-fdata-sections", *defs, *incs, *extra,
                 "-fstack-usage", "-fcallgraph-info=su", "-c", src, "-o", obj], check=True, cwd=tmp)
            text = obj.with_suffix(".ci").read_text()
            for m in _NODE.finditer(text):
                size = _SIZE.search(m["label"])
                if size:
                    graph.frame[m["title"]] = int(size[1])
                    graph.qualifier[m["title"]] = size[2]
                    graph.owner[m["title"]] = src.name
            for m in _EDGE.finditer(text):
                graph.calls.setdefault(m["src"], set()).add(m["dst"])
            for m in _ASM_STACK.finditer(Path(src).read_text()):
                for title in graph.frame:
                    if graph.owner.get(title) == src.name and (title == m[1] or title.endswith(":" + m[1])):
                        graph.frame[title] += int(m[2])
    return graph


def bench_bounds(bundle: Path | None = None) -> dict[str, int]:
    """Stack bound of each measured wrapper of the cost image (its frame plus the library call),
    keyed like fleetlab.host_tools.firmware.measure.target_costs, so bound and measurement compare 1:1."""
    graph = compile_graph(bundle, q_only=True, with_bench=True)
    out = {}
    for key, fn in BENCH_WRAPPERS.items():
        title = next(t for t in graph.frame if t == fn or t.endswith(":" + fn))
        out[key] = graph.worst(title)[0]
    return out


def public_functions() -> list[str]:
    names = set()
    for h in public_headers():
        names |= set(re.findall(r"^\s*(?:const\s+)?[\w ]+?\**\s*\b(slipest_\w+)\s*\(", h.read_text(), re.M))
    return sorted(names)


@dataclass
class StackRow:
    function: str
    bytes: int
    chain: list[str]
    unknown: set[str]
    dynamic: bool


def analyse(bundle: Path | None = None, q_only: bool = True) -> tuple[list[StackRow], list[list[str]]]:
    graph = compile_graph(bundle, q_only)
    cycles = graph.cycles()
    rows = []
    if cycles:
        return rows, cycles
    for fn in public_functions():
        if fn not in graph.frame:
            continue  # declared but not in this library variant (e.g. the f32 path in slipest_q)
        b, chain, unknown = graph.worst(fn)
        dyn = any(graph.qualifier.get(c, "static") != "static" for c in chain)
        rows.append(StackRow(fn, b, [c.rsplit(":", 1)[-1] for c in chain], unknown, dyn))
    return rows, cycles


def table(rows: list[StackRow]) -> str:
    out = ["| Entry point | Worst-case stack (bytes) | Deepest chain | Calls without a frame size |",
           "|---|---:|---|---|"]
    for r in sorted(rows, key=lambda r: -r.bytes):
        out.append(f"| {r.function} | {r.bytes}{' (dynamic frame)' if r.dynamic else ''} | "
                   f"{' → '.join(r.chain)} | {', '.join(sorted(r.unknown)) or '—'} |")
    return "\n".join(out)
