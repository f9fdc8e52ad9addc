"""Byte-level framings of CAN frames: COBS+CRC-16 packets (serial link) and SLCAN lines.

Serial packet: COBS(payload) + 0x00, payload = can_id (u16 LE) + dlc (u8) + data[dlc]
+ CRC-16/CCITT-FALSE (u16 LE) over can_id+dlc+data.
SLCAN: `tIIILDD..\\r` for an 11-bit data frame; the adapter answers commands with `\\r`
(or `\\a` on error).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import crcmod.predefined
from cobs import cobs

from .dbc import Frame

crc16 = crcmod.predefined.mkCrcFun("crc-ccitt-false")

# Longest legal packet: COBS overhead 1 byte on a 13-byte payload, plus the delimiter.
MAX_PAYLOAD = 2 + 1 + 8 + 2
MAX_ENCODED = MAX_PAYLOAD + 2


def encode_payload(frame: Frame) -> bytes:
    body = struct.pack("<HB", frame.can_id, len(frame.data)) + frame.data
    return body + struct.pack("<H", crc16(body))


def encode_packet(frame: Frame) -> bytes:
    return cobs.encode(encode_payload(frame)) + b"\x00"


def encode_bad_crc_packet(frame: Frame) -> bytes:
    """The packet of `frame` with its CRC inverted (fault injection)."""
    payload = bytearray(encode_payload(frame))
    payload[-2] ^= 0xFF
    payload[-1] ^= 0xFF
    return cobs.encode(bytes(payload)) + b"\x00"


def encode_length_mismatch_packet(frame: Frame) -> bytes:
    """A packet whose dlc byte claims one byte more than it carries (valid CRC)."""
    body = struct.pack("<HB", frame.can_id, len(frame.data) + 1) + frame.data
    return cobs.encode(body + struct.pack("<H", crc16(body))) + b"\x00"


@dataclass(frozen=True)
class Rejected:
    """A packet or line that could not be decoded, with the reason."""

    reason: str  # 'cobs', 'short', 'crc', 'length', 'oversize', 'malformed'
    raw: bytes


class PacketDecoder:
    """Incremental COBS+CRC decoder: feed bytes, get Frames and Rejected packets.

    A run of bytes longer than any legal packet without a delimiter is rejected as
    'oversize' (once) and skipped up to the next 0x00, so a lost delimiter costs
    at most two packets, never a stall.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._oversize = False

    def feed(self, data: bytes) -> list[Frame | Rejected]:
        out: list[Frame | Rejected] = []
        start = 0
        while True:
            end = data.find(b"\x00", start)
            if end < 0:
                self._buf += data[start:]
                if len(self._buf) > MAX_ENCODED and not self._oversize:
                    out.append(Rejected("oversize", bytes(self._buf[:MAX_ENCODED])))
                    self._oversize = True
                if self._oversize:
                    self._buf.clear()
                return out
            chunk = bytes(self._buf) + data[start:end]
            self._buf.clear()
            start = end + 1
            if self._oversize:
                self._oversize = False  # the tail of an oversize run ends here
                continue
            if len(chunk) > MAX_ENCODED:
                out.append(Rejected("oversize", chunk[:MAX_ENCODED]))
            elif chunk:
                out.append(decode_packet(chunk))


def decode_packet(encoded: bytes) -> Frame | Rejected:
    """One COBS-encoded packet without its 0x00 delimiter."""
    try:
        payload = cobs.decode(encoded)
    except cobs.DecodeError:
        return Rejected("cobs", encoded)
    if len(payload) < 5:
        return Rejected("short", encoded)
    can_id, dlc = struct.unpack_from("<HB", payload)
    (crc,) = struct.unpack_from("<H", payload, len(payload) - 2)
    if crc16(payload[:-2]) != crc:
        return Rejected("crc", encoded)
    if len(payload) != 3 + dlc + 2 or dlc > 8 or can_id > 0x7FF:
        return Rejected("length", encoded)
    return Frame(can_id, payload[3 : 3 + dlc])


# --- SLCAN ---------------------------------------------------------------------------------


def slcan_line(frame: Frame) -> bytes:
    return b"t%03X%d%s\r" % (frame.can_id, len(frame.data), frame.data.hex().upper().encode())


def slcan_malformed_line(frame: Frame) -> bytes:
    """A line that looks like `frame` but carries a non-hex digit (fault injection)."""
    line = bytearray(slcan_line(frame))
    line[5 if len(frame.data) else 2] = ord("G")
    return bytes(line)


def parse_slcan_line(line: bytes) -> Frame | Rejected | None:
    """One SLCAN line without its `\\r`. None for a bare acknowledgement."""
    if not line:
        return None
    if line[:1] != b"t":
        return Rejected("malformed", line)
    try:
        can_id = int(line[1:4], 16)
        dlc = int(line[4:5], 16)
        hexdata = line[5:]
        if len(line) < 5 or dlc > 8 or len(hexdata) != 2 * dlc:
            return Rejected("malformed", line)
        return Frame(can_id, bytes.fromhex(hexdata.decode("ascii")))
    except ValueError:
        return Rejected("malformed", line)


class SlcanLineReader:
    """Incremental SLCAN reader: feed bytes, get Frames, Rejected lines and acks (None)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Frame | Rejected | None]:
        self._buf += data
        out: list[Frame | Rejected | None] = []
        while True:
            i = min((j for j in (self._buf.find(b"\r"), self._buf.find(b"\a")) if j >= 0), default=-1)
            if i < 0:
                if len(self._buf) > 64:
                    out.append(Rejected("oversize", bytes(self._buf)))
                    self._buf.clear()
                return out
            line, term = bytes(self._buf[:i]), self._buf[i : i + 1]
            del self._buf[: i + 1]
            if term == b"\a":
                out.append(Rejected("nak", line))
            else:
                out.append(parse_slcan_line(line))
