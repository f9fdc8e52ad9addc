"""The committed golden node frames (firmware_c/tests/golden/node_frames_example.txt), decoded without the C
code that wrote them: every target's frames are compared with this file, so a packing error regenerated into
it would pass on every CPU. Each line carries one transmitted frame three ways: "<id> <dlc> <data hex> |
<SLCAN text> | <COBS packet hex>". The three must agree; the frames are decoded with cantools from the DBC
and compared with the torch integer reference (fleetlab.export.intref) for the inputs that
firmware_c/target/node_frames.c feeds the node.

The CANopen profile's golden file (co_frames_example.txt) is decoded with the python `canopen` package by
tests/test_golden_co_frames.py; both read their files with tests/golden_node_frames.py."""

from __future__ import annotations

import numpy as np
import pytest

from fleetlab.data.features_int import FLAG_FEATURES_INPUT, FLAG_SATURATION
from fleetlab.export.bundle import load_bundle
from fleetlab.export.intref import argmax_lowest, q_logits_of

from golden_node_frames import (BUNDLE, DBC, GOLDEN, NO_FLOAT_CLASS, assert_windows_equal_the_reference, decode,
                                golden_frames, golden_line, node_frames_stream)


@pytest.fixture(scope="module")
def decoded():
    return decode()


def test_every_line_is_one_frame_in_three_agreeing_encodings(decoded):
    frames, count, estimates, _ = decoded
    assert count == len(frames) > 3000
    assert all(len(e["logits"]) == 3 for e in estimates)


def test_feature_set_estimates_equal_the_torch_integer_reference(decoded):
    """The first part: every bundle vector sent as four FEATURES frames."""
    b = load_bundle(BUNDLE)
    q_inputs = np.load(BUNDLE / "vectors.npz")["q_inputs"]
    logits, sat = q_logits_of(b.qparams, q_inputs, return_saturations=True)
    est = decoded[2][: len(q_inputs)]
    assert [e["window_counter"] for e in est] == list(range(len(q_inputs)))
    assert [e["logits"] for e in est] == logits.tolist()
    assert [e["slip_class"] for e in est] == argmax_lowest(logits).tolist()
    assert [e["saturations"] for e in est] == sat.tolist()
    assert [e["flags"] for e in est] == [FLAG_FEATURES_INPUT | (FLAG_SATURATION if s else 0) for s in sat]
    assert {(e["n_samples"], e["slip_class_f32"]) for e in est} == {(0, NO_FLOAT_CLASS)}


def test_telemetry_windows_equal_the_integer_features_and_reference(decoded):
    """The second part: 250 telemetry samples, two closed windows, features by fleetlab.data.features_int."""
    n_vectors = len(np.load(BUNDLE / "vectors.npz")["q_inputs"])
    est = decoded[2][n_vectors:]
    ref = assert_windows_equal_the_reference(est, node_frames_stream(), np.arange(250))
    assert len(est) == 2


def test_closing_status_frames_count_what_the_node_received(decoded):
    _, _, estimates, status = decoded
    n_vectors = len(np.load(BUNDLE / "vectors.npz")["q_inputs"])
    last = dict(status[-3:])
    assert list(last) == ["STATUS_MODEL", "STATUS_RX", "STATUS_LOSS"]
    manifest_hash = int(load_bundle(BUNDLE).manifest["content_hash"][:8], 16)
    assert last["STATUS_MODEL"]["model_hash"] == manifest_hash
    assert last["STATUS_MODEL"]["windows_done"] == len(estimates) == n_vectors + 2
    assert last["STATUS_RX"] == {"frames_received": 4 * n_vectors + 3 * 250, "frames_rejected": 0}
    assert last["STATUS_LOSS"] == {"samples_dropped": 0, "windows_flagged": 0}
    # the periodic status frames between: same hash, windows_done rising
    models = [v for name, v in status if name == "STATUS_MODEL"]
    assert {m["model_hash"] for m in models} == {manifest_hash}
    done = [m["windows_done"] for m in models]
    assert done == sorted(done) and len(done) > 1


def test_a_wrong_golden_is_caught(tmp_path):
    """The checks can fail: one logit byte changed in all three encodings of a line decodes to a logit the
    reference does not give; changed in the data column alone, the line's encodings disagree."""
    from fleetlab.host_tools.wire.dbc import Frame

    lines = GOLDEN.read_text().splitlines(keepends=True)
    can_id, dlc, data = lines[1].split("|")[0].split()
    assert int(can_id) == DBC.get_message_by_name("SLIP_LOGITS_01").frame_id
    f = Frame(int(can_id), bytes([bytes.fromhex(data)[0] ^ 1]) + bytes.fromhex(data)[1:])
    bad = tmp_path / "golden.txt"
    bad.write_text("".join(lines[:1] + [golden_line(f)] + lines[2:]))
    got = decode(bad)[2][0]["logits"]
    want = q_logits_of(load_bundle(BUNDLE).qparams, np.load(BUNDLE / "vectors.npz")["q_inputs"][:1])[0].tolist()
    assert got != want and got[1:] == want[1:]
    bad.write_text("".join(lines[:1] + [lines[1].replace(data, f.data.hex(), 1)] + lines[2:]))
    with pytest.raises(AssertionError, match="line 2"):
        golden_frames(bad)
