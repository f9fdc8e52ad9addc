"""Bits a classic CAN frame (11-bit identifier, data frame) takes on the wire, stuff bits counted
exactly: SOF, identifier, RTR, IDE, r0, DLC, data, CRC-15 (ISO 11898-1) are bit-stuffed (a
complement bit after five equal bits); CRC delimiter, ACK slot and delimiter, EOF (7) and the
3-bit intermission are not. Used to state an upload's bus time at a given bit rate."""

from __future__ import annotations
from fleetlab.errors import InputError


def _crc15(bits: list[int]) -> int:
    crc = 0
    for b in bits:
        nxt = b ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= 0x4599
    return crc


def frame_bits(can_id: int, data: bytes) -> int:
    """Bits on the bus for one standard data frame, including stuff bits and the intermission."""
    if not 0 <= can_id <= 0x7FF or len(data) > 8:
        raise InputError("a classic CAN data frame: 11-bit identifier, 0..8 data bytes")
    bits = [0]  # SOF
    bits += [(can_id >> (10 - i)) & 1 for i in range(11)]
    bits += [0, 0, 0]  # RTR (data frame), IDE (standard), r0
    bits += [(len(data) >> (3 - i)) & 1 for i in range(4)]
    for byte in data:
        bits += [(byte >> (7 - i)) & 1 for i in range(8)]
    crc = _crc15(bits)
    bits += [(crc >> (14 - i)) & 1 for i in range(15)]
    stuffed, run, last = 0, 0, None
    for b in bits:
        if b == last:
            run += 1
        else:
            run, last = 1, b
        if run == 5:  # a stuff bit of the opposite value follows and starts a new run
            stuffed += 1
            run, last = 1, 1 - b
    return len(bits) + stuffed + 1 + 2 + 7 + 3  # CRC delimiter, ACK slot + delimiter, EOF, intermission
