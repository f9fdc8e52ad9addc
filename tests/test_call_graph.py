"""The library's C files call each other without a cycle (issues 27 and 43), in every configuration CMake builds
(layer table on and off, image authentication on and off): folded onto files, GCC's call graph of every
firmware_c/src/*.c file has no cycle. The CANopen files run slipest_co.c -> slipest_co_sdo.c ->
slipest_co_od_access.c -> slipest_co_model.c, and the image reader slipest_image_buffer.c ->
slipest_image_stream.c -> one visitor per format. `python scripts/check_call_graph.py` prints the same check."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from fleetlab.assurance.stack import StackGraph, compile_graph

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import check_call_graph  # noqa: E402


@pytest.fixture(scope="module")
def graphs() -> dict[bool, StackGraph]:
    """The full library's call graph with the layer table on (True) and off (False)."""
    return {lt: compile_graph(q_only=False, layer_table=lt) for lt in (True, False)}


def test_canopen_files_call_each_other_without_a_cycle(graphs) -> None:
    edges, cycles = check_call_graph.co_file_cycles(graphs[True])
    assert cycles == [], cycles
    assert edges["slipest_co_model.c"] == set()  # the lifecycle is a leaf
    assert edges["slipest_co.c"] == {"slipest_co_sdo.c", "slipest_co_model.c"}
    assert "slipest_cobs.c" not in edges


@pytest.mark.parametrize("layer_table", [True, False])
@pytest.mark.parametrize("auth", [False, True])
def test_every_library_file_calls_without_a_cycle(graphs, layer_table, auth) -> None:
    graph = check_call_graph.with_auth(graphs[layer_table]) if auth else graphs[layer_table]
    files = check_call_graph.library_files(layer_table)
    edges, cycles = check_call_graph.file_cycles(graph, files)
    assert cycles == [], cycles
    assert ("slipest_image_table.c" in edges) == layer_table and ("slipest_infer_table_q.c" in edges) == layer_table
    # the image reader along its seams: the whole-buffer reads on the stream, the stream on one visitor per
    # format, the visitors calling no image file
    assert edges["slipest_image_buffer.c"] == {"slipest_image_stream.c"}
    visitors = {"slipest_image_v1.c"} | ({"slipest_image_table.c"} if layer_table else set())
    assert visitors <= edges["slipest_image_stream.c"]
    for v in visitors:
        assert not {f for f in edges[v] if f.startswith("slipest_image")}, (v, edges[v])
    # the kernels: the entry point (with the SN-S kernel) calls the table kernel, which calls no library file
    if layer_table:
        assert edges["slipest_infer_q.c"] == {"slipest_infer_table_q.c"}
        assert edges["slipest_infer_table_q.c"] == set()


def test_authentication_reaches_the_hmac_through_the_store(graphs) -> None:
    """With authentication on, the store's indirect calls reach the functions SLIPEST_STORE_AUTH_HMAC_SHA256
    names, so a cycle through them could not hide behind the function pointers."""
    callbacks = check_call_graph.auth_callbacks()
    assert callbacks == ["slipest_hmac_sha256_init", "slipest_hmac_sha256_update", "slipest_hmac_sha256_final"]
    graph = check_call_graph.with_auth(graphs[True])
    reached = set().union(*(d for s, d in graph.calls.items() if graph.owner.get(s) == check_call_graph.STORE))
    assert set(callbacks) <= reached


def test_the_check_finds_a_file_cycle() -> None:
    """The fold can fail: two functions in different files calling each other's file make a cycle."""
    g = StackGraph(calls={"a": {"b"}, "b": {"c"}, "c": {"a2"}},
                   owner={"a": "slipest_co.c", "a2": "slipest_co.c", "b": "slipest_co_sdo.c",
                          "c": "slipest_co_od_access.c"})
    edges = g.file_edges(check_call_graph.co_files())
    assert StackGraph(calls=edges).cycles()


def test_the_check_finds_the_old_image_reader_cycle(graphs) -> None:
    """The cycle issue 43 removed, planted back into the real graph: the format-2 visitor calling up into the
    stream for a whole-buffer read (as slipest_image_read_table() did from slipest_image_table.c) is found."""
    graph = graphs[True]
    calls = {s: set(d) for s, d in graph.calls.items()}
    calls.setdefault("slipest_image_v2_header", set()).add("slipest_image_stream_feed")
    planted = StackGraph(calls=calls, owner=graph.owner)
    _, cycles = check_call_graph.file_cycles(planted, check_call_graph.library_files(True))
    assert any({"slipest_image_stream.c", "slipest_image_table.c"} <= set(c) for c in cycles), cycles
