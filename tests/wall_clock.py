"""The rule "no wall clock in assertions" (issue 31), as a check over the tests' source: a comparison whose
operand reads a clock (time.time(), perf_counter, monotonic and their _ns forms), directly or through a name
assigned from one in the same function, is a finding unless its line says it is a safety net:

    deadline = time.monotonic() + 5  # safety net: a hung emulator ends the wait, the assertions then fail
    while time.monotonic() < deadline:  # safety net

A safety net bounds a wait that ends on an event (a count reached, an answer read, EOF); what the test then
asserts is about the event. Counts against a node's own tick or a simulated clock
(fleetlab.host_tools.pacing.SimulatedClock) read no clock and pass."""

from __future__ import annotations

import ast
from pathlib import Path

CLOCKS = {"time", "time_ns", "perf_counter", "perf_counter_ns", "monotonic", "monotonic_ns"}
MARKER = "# safety net"


def _reads_clock(node: ast.AST, tainted: set[str]) -> bool:
    for n in ast.walk(node):
        if isinstance(n, ast.Call):
            f = n.func
            if (isinstance(f, ast.Attribute) and f.attr in CLOCKS and isinstance(f.value, ast.Name)
                    and f.value.id == "time") or (isinstance(f, ast.Name) and f.id in CLOCKS - {"time"}):
                return True
        if isinstance(n, (ast.Name, ast.Attribute)) and ast.unparse(n) in tainted:
            return True
    return False


def _tainted(scope: ast.AST) -> set[str]:
    """Names (and dotted attributes) assigned, anywhere in the scope, from a value that reads a clock."""
    tainted: set[str] = set()
    assigns = [n for n in ast.walk(scope) if isinstance(n, (ast.Assign, ast.AugAssign, ast.AnnAssign))]
    while True:
        before = len(tainted)
        for a in assigns:
            if a.value is not None and _reads_clock(a.value, tainted):
                for t in a.targets if isinstance(a, ast.Assign) else [a.target]:
                    tainted |= {ast.unparse(e) for e in ast.walk(t) if isinstance(e, (ast.Name, ast.Attribute))}
        if len(tainted) == before:
            return tainted


def findings(source: str, name: str = "<source>") -> list[str]:
    """'name:line: comparison' for every clock comparison not marked as a safety net."""
    tree = ast.parse(source)
    lines = source.splitlines()
    out = []
    scopes = [tree] + [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    for scope in scopes:
        tainted = _tainted(scope)
        for node in ast.walk(scope):
            if not isinstance(node, ast.Compare) or not _reads_clock(node, tainted):
                continue
            span = lines[node.lineno - 1 : node.end_lineno]
            if not any(MARKER in line for line in span):
                out.append(f"{name}:{node.lineno}: {ast.unparse(node)}")
    return sorted(set(out))


def scan(folder: Path) -> list[str]:
    return [f for path in sorted(folder.glob("*.py")) for f in findings(path.read_text(), path.name)]
