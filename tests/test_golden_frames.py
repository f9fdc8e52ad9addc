"""The committed golden node frames (firmware_c/tests/golden/node_frames_example.txt), decoded without the C
code that wrote them: every target's frames are compared with this file, so a packing error regenerated into
it would pass on every CPU. Each line carries one transmitted frame three ways: "<id> <dlc> <data hex> |
<SLCAN text> | <COBS packet hex>". The three must agree; the frames are decoded with cantools from the DBC
and compared with the torch integer reference (fleetlab.export.intref) for the inputs that
firmware_c/target/node_frames.c feeds the node.

The CANopen profile's golden file (co_frames_example.txt) is decoded with the python `canopen` package by
tests/test_golden_co_frames.py, which reads it with golden_lines() here."""

from __future__ import annotations

import cantools
import numpy as np
import pytest

from fleetlab.data.features_int import FLAG_FEATURES_INPUT, FLAG_SATURATION, featurise_int
from fleetlab.export.bundle import load_bundle
from fleetlab.export.intref import argmax_lowest, q_logits_of
from fleetlab.host_tools.wire.serial_framing import decode_packet, parse_slcan_line
from fleetlab.paths import repo_root

REPO = repo_root()
GOLDEN = REPO / "firmware_c" / "tests" / "golden" / "node_frames_example.txt"
BUNDLE = REPO / "firmware_c" / "bundles" / "example"
DBC = cantools.database.load_file(str(REPO / "dbc" / "slipest.dbc"))
NO_FLOAT_CLASS = 255  # the fixed-point-only node (slipest_q) sends no float class


def golden_lines(path=GOLDEN) -> tuple[list[tuple[list[str], int, bytes]], int]:
    """(leading fields, id, data) of every line, after checking that its SLCAN and COBS forms carry the same
    frame; and the frame count of the closing line. The leading fields are those before the id (the CANopen
    golden's tick and direction; none in the plain one)."""
    lines = path.read_text().splitlines()
    assert lines[-1].startswith("frames=") and lines[-1].endswith(" END"), lines[-1]
    frames = []
    for n, line in enumerate(lines[:-1], 1):
        head, slcan, packet = (part.strip() for part in line.split("|"))
        *lead, can_id, dlc, data = head.split()
        data = bytes.fromhex(data)
        assert int(dlc) == len(data), f"line {n}: dlc {dlc}, {len(data)} bytes"
        for other in (parse_slcan_line(slcan.encode()), decode_packet(bytes.fromhex(packet)[:-1])):
            assert (other.can_id, other.data) == (int(can_id), data), f"line {n}: {other}"
        assert packet.endswith("00") and "00" not in [packet[i:i + 2] for i in range(0, len(packet) - 2, 2)]
        frames.append((lead, int(can_id), data))
    return frames, int(lines[-1].split("=")[1].split()[0])


def golden_frames(path=GOLDEN) -> tuple[list[tuple[int, bytes]], int]:
    """(id, data) of every line of the plain profile's golden file, and its closing frame count."""
    lines, count = golden_lines(path)
    return [(can_id, data) for _, can_id, data in lines], count


def golden_line(frame, lead: str = "") -> str:
    """The golden-file line of a frame (as firmware_c/target/frame_print.c writes it), after `lead`."""
    from fleetlab.host_tools.wire.serial_framing import encode_packet, slcan_line

    return (f"{lead}{frame.can_id} {len(frame.data)} {frame.data.hex()} | {slcan_line(frame)[:-1].decode()} | "
            f"{encode_packet(frame).hex()}\n")


def node_frames_stream(n: int = 250) -> np.ndarray:
    """The raw telemetry samples of node_frames.c (its main(), second loop: 250 of them; co_frames.c sends
    more of the same formula), channels in DBC order: wheel_speed, motor_current, acc_x, acc_y, acc_z, roll,
    pitch."""
    i = np.arange(n)
    w1 = [1000 + (i * 7) % 300 - 150 * k for k in range(3)]
    w2 = [200 - i % 50 + 11 * k for k in range(3)]
    w3 = 9810 - (i % 13) * 2  # IMU (k = 1) only
    return np.stack([w1[0], w2[0], w1[1], w2[1], w3, w1[2], w2[2]], axis=1).astype(np.int16)


def decode(path=GOLDEN):
    frames, count = golden_frames(path)
    estimates, status = [], []
    for can_id, data in frames:
        msg = DBC.get_message_by_frame_id(can_id)
        values = msg.decode(data, decode_choices=False, scaling=False)
        if msg.name == "SLIP_ESTIMATE":
            estimates.append(dict(values))
        elif msg.name == "SLIP_LOGITS_01":
            estimates[-1]["logits"] = [values["logit_0"], values["logit_1"]]
        elif msg.name == "SLIP_LOGITS_2":
            assert values["window_counter"] == estimates[-1]["window_counter"]
            estimates[-1]["logits"].append(values["logit_2"])
        else:
            assert msg.name.startswith("STATUS_"), msg.name
            status.append((msg.name, dict(values)))
    return frames, count, estimates, status


def assert_windows_equal_the_reference(est: list[dict], samples: np.ndarray, counters: np.ndarray):
    """The decoded estimates of telemetry windows equal the integer features (fleetlab.data.features_int) and
    the torch integer reference's logits for those samples, field by field; returns the features."""
    ref = featurise_int(samples, counters)
    logits, sat = q_logits_of(load_bundle(BUNDLE).qparams, ref.features, return_saturations=True)
    assert len(est) == len(ref.features)
    assert [e["window_counter"] for e in est] == ref.window_index.tolist()
    assert [e["logits"] for e in est] == logits.tolist()
    assert [e["slip_class"] for e in est] == argmax_lowest(logits).tolist()
    assert [e["n_samples"] for e in est] == ref.n_samples.tolist()
    assert [e["saturations"] for e in est] == (sat + ref.saturations).tolist()
    assert [e["flags"] for e in est] == ref.flags.tolist()
    return ref


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
