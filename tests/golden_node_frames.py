"""Readers of the committed golden node-frame files (firmware_c/tests/golden/*.txt), without the C code that
wrote them, and the reference their decoded estimates must equal: tests/test_golden_frames.py (the plain
profile) and tests/test_golden_co_frames.py (the CANopen profile) check the files with them."""

from __future__ import annotations

import cantools
import numpy as np

from fleetlab.data.features_int import featurise_int
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
