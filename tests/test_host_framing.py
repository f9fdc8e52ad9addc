"""Wire formats of the host tools: CRC-16, COBS packets, SLCAN lines, DBC codecs."""

from __future__ import annotations

import random

import cantools
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlab.host_tools.wire import dbc
from fleetlab.host_tools.wire.dbc import Frame, OutputAssembler, StatusReport, WindowEstimate
from fleetlab.host_tools.wire.serial_framing import (
    PacketDecoder,
    Rejected,
    SlcanLineReader,
    crc16,
    decode_packet,
    encode_bad_crc_packet,
    encode_length_mismatch_packet,
    encode_packet,
    parse_slcan_line,
    slcan_line,
    slcan_malformed_line,
)

frames = st.builds(Frame, st.integers(0, 0x7FF), st.binary(min_size=0, max_size=8))


def test_crc16_ccitt_false_check_value():
    # the catalogue check value of CRC-16/CCITT-FALSE over "123456789"
    assert crc16(b"123456789") == 0x29B1


def test_packet_layout_is_cobs_of_id_dlc_data_crc():
    f = Frame(0x101, bytes([1, 0, 2, 0, 0, 0, 3, 4]))
    pkt = encode_packet(f)
    assert pkt.endswith(b"\x00") and b"\x00" not in pkt[:-1]
    from cobs import cobs

    payload = cobs.decode(pkt[:-1])
    assert payload[:3] == bytes([0x01, 0x01, 8])
    assert payload[3:11] == f.data
    assert int.from_bytes(payload[11:], "little") == crc16(payload[:11])


@settings(max_examples=200, deadline=None)
@given(st.lists(frames, min_size=1, max_size=20), st.data())
def test_decoder_recovers_frames_in_any_chunking(fs, data):
    stream = b"".join(encode_packet(f) for f in fs)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    dec, out, prev = PacketDecoder(), [], 0
    for c in cuts + [len(stream)]:
        out += dec.feed(stream[prev:c])
        prev = c
    assert out == fs


def test_decoder_rejects_bad_crc_and_length_and_garbage_then_resyncs():
    good = Frame(0x100, bytes(6))
    stream = (encode_bad_crc_packet(good) + encode_length_mismatch_packet(good) + b"\x05\x01\x00"
              + b"\x01" * 40 + b"\x00" + encode_packet(good))
    out = PacketDecoder().feed(stream)
    reasons = [o.reason for o in out if isinstance(o, Rejected)]
    assert reasons == ["crc", "length", "cobs", "oversize"]
    assert out[-1] == good


def test_short_packet_is_rejected():
    from cobs import cobs

    assert isinstance(decode_packet(cobs.encode(b"\x01\x02")), Rejected)


@settings(max_examples=200, deadline=None)
@given(frames)
def test_slcan_roundtrip(f):
    line = slcan_line(f)
    assert line.endswith(b"\r") and line[:1] == b"t"
    assert parse_slcan_line(line[:-1]) == f


def test_slcan_reader_splits_lines_acks_and_errors():
    f = Frame(0x200, bytes(range(8)))
    r = SlcanLineReader()
    out = r.feed(b"\r" + slcan_line(f)[:7]) + r.feed(slcan_line(f)[7:] + b"\a" + slcan_malformed_line(f))
    assert out[0] is None and out[1] == f
    assert isinstance(out[2], Rejected) and out[2].reason == "nak"
    assert isinstance(out[3], Rejected) and out[3].reason == "malformed"


# --- DBC -----------------------------------------------------------------------------------


def test_struct_codecs_agree_with_cantools_for_every_message():
    db = cantools.database.load_file(str(dbc.DBC_PATH))
    rng = random.Random(1)
    for msg in db.messages:
        c = dbc.codec(msg.name)
        assert c.frame_id == msg.frame_id and c.length == msg.length
        for _ in range(50):
            raw = {}
            for s in msg.signals:
                lo = -(1 << (s.length - 1)) if s.is_signed else 0
                hi = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
                raw[s.name] = rng.randint(lo, hi)
            ours = c.encode(*(raw[n] for n in c.signals))
            theirs = db.encode_message(msg.frame_id, raw, scaling=False, strict=False)
            assert ours.data == theirs, msg.name
            assert c.decode_dict(ours.data) == db.decode_message(msg.frame_id, theirs, scaling=False)


def test_telemetry_and_feature_frames_carry_raw_values():
    raw = np.array([1000, -250, 12, -34, 9810, 17, -3], dtype=np.int16)
    w, imu, att = dbc.telemetry_frames(70000, raw)
    db = dbc.database()
    assert db.decode_message(w.can_id, w.data, scaling=False) == {"sample_counter": 70000 & 0xFFFF,
                                                                  "wheel_speed": 1000, "motor_current": -250}
    assert db.decode_message(att.can_id, att.data, scaling=False)["pitch"] == -3
    q = np.arange(-6, 6, dtype=np.int16)
    f3 = dbc.feature_frames(7, q)[3]
    assert db.decode_message(f3.can_id, f3.data, scaling=False) == {
        "window_counter": 7, "acc_z_std": 3, "pitch_mean": 4, "roll_mean": 5}


def test_encode_out_of_range_names_the_frame():
    with pytest.raises(ValueError, match="TELEM_WHEEL"):
        dbc.telemetry_frames(0, [40000, 0, 0, 0, 0, 0, 0])


def test_output_assembler_pairs_frames_and_counts_problems():
    cs = dbc.codecs()
    est = cs["SLIP_ESTIMATE"].encode(5, 2, 2, 0x01, 97, 0)
    l01 = cs["SLIP_LOGITS_01"].encode(-7, 123456)
    l2 = cs["SLIP_LOGITS_2"].encode(99, 5)
    a = OutputAssembler()
    assert a.feed(est) is None and a.feed(l01) is None
    got = a.feed(l2)
    assert isinstance(got, WindowEstimate) and got.logits == (-7, 123456, 99) and got.n_samples == 97
    assert a.feed(cs["SLIP_LOGITS_2"].encode(1, 6)) is None and a.errors  # logits without estimate
    assert a.feed(cs["STATUS_MODEL"].encode(0xDEADBEEF, 0x100, 10)) is None
    assert a.feed(cs["STATUS_RX"].encode(300, 2)) is None
    rep = a.feed(cs["STATUS_LOSS"].encode(1, 1))
    assert isinstance(rep, StatusReport) and rep.frames_received == 300 and rep.model_hash == 0xDEADBEEF
    n = len(a.errors)
    a.feed(Frame(0x123, b"\x00"))
    assert len(a.errors) == n + 1
