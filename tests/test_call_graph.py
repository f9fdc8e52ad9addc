"""The CANopen node's C files call each other without a cycle (issue 27): folded onto files, GCC's call
graph runs slipest_co.c -> slipest_co_sdo.c -> slipest_co_od_access.c -> slipest_co_model.c, and the
model lifecycle (slipest_co_model.c) calls no other CANopen file. `python scripts/check_call_graph.py`
prints the same check."""

from __future__ import annotations

import sys
from pathlib import Path

from fleetlab.assurance.stack import StackGraph, compile_graph

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import check_call_graph  # noqa: E402


def test_canopen_files_call_each_other_without_a_cycle() -> None:
    edges, cycles = check_call_graph.co_file_cycles(compile_graph(q_only=False))
    assert cycles == [], cycles
    assert edges["slipest_co_model.c"] == set()  # the lifecycle is a leaf
    assert edges["slipest_co.c"] == {"slipest_co_sdo.c", "slipest_co_model.c"}
    assert "slipest_cobs.c" not in edges


def test_the_check_finds_a_file_cycle() -> None:
    """The fold can fail: two functions in different files calling each other's file make a cycle."""
    g = StackGraph(calls={"a": {"b"}, "b": {"c"}, "c": {"a2"}},
                   owner={"a": "slipest_co.c", "a2": "slipest_co.c", "b": "slipest_co_sdo.c",
                          "c": "slipest_co_od_access.c"})
    edges = g.file_edges(check_call_graph.co_files())
    assert StackGraph(calls=edges).cycles()
