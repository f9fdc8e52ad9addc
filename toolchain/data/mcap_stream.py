"""Read an MCAP file front to back without its summary: the salvage path for a bag cut short.

A recorder that crashes leaves an MCAP file without its summary, index and footer, usually
in the middle of a chunk. `rosbags` (like any indexed reader) refuses such a file: it starts
from the footer. This reader starts from the magic instead and follows the records one after
the other (MCAP specification: opcode u8, length u64, content; strings u32-length-prefixed,
little endian), as far as they are whole:

- Schema and Channel records give the topics and message types, Message records the
  messages (channel, log time, CDR bytes), inside Chunk records or at the top level;
- a chunk cut short still gives its whole messages (uncompressed, zstd and lz4 chunks are
  decompressed as a stream, so the part that arrived is read);
- the first record that is cut short, or that does not parse (a wrong chunk CRC, a
  corrupt compressed stream), ends the read: everything before it is kept, and `Scan` says
  where and why it stopped.

The file is complete when the DataEnd record or the footer is reached.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from ..errors import InputError

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, content length
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct("<QQQI")  # message start time, end time, uncompressed size, uncompressed CRC-32


class NotMcap(InputError):
    """The file does not start like an MCAP file of the ROS 2 profile."""


class _Short(Exception):
    """A field runs past the bytes at hand."""


@dataclass(frozen=True)
class Channel:
    id: int
    topic: str
    msgtype: str  # the schema name, e.g. sensor_msgs/msg/Imu
    encoding: str  # the message encoding, 'cdr' for ROS 2


@dataclass
class Scan:
    """What a front-to-back read of one MCAP file found."""

    path: Path
    size: int  # bytes in the file
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)  # (channel id, log time ns, data)
    complete: bool = False  # reached the end of the data section (DataEnd record or footer)
    whole_bytes: int = 0  # file offset up to which every record was read whole
    chunks: int = 0  # whole chunks read
    cut_chunk_messages: int = 0  # messages read out of a chunk cut short
    stop: str = ""  # why the read stopped before the end of the data section

    @property
    def lost_bytes(self) -> int:
        return self.size - self.whole_bytes


class _Cursor:
    def __init__(self, buf: bytes | memoryview, pos: int = 0):
        self.buf, self.pos = buf, pos

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.buf):
            raise _Short
        out = bytes(self.buf[self.pos : self.pos + n])
        self.pos += n
        return out

    def unpack(self, st: struct.Struct) -> tuple:
        return st.unpack(self.take(st.size))

    def u16(self) -> int:
        return self.unpack(_U16)[0]

    def u32(self) -> int:
        return self.unpack(_U32)[0]

    def u64(self) -> int:
        return self.unpack(_U64)[0]

    def string(self) -> str:
        return self.take(self.u32()).decode("utf-8")


_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")


def _record(scan: Scan, schemas: dict[int, str], op: int, content: bytes) -> None:
    """Schema, Channel and Message records; every other kind is skipped."""
    c = _Cursor(content)
    if op == OP_SCHEMA:
        sid = c.u16()
        schemas[sid] = c.string()
    elif op == OP_CHANNEL:
        cid, sid = c.u16(), c.u16()
        topic, encoding = c.string(), c.string()
        scan.channels[cid] = Channel(cid, topic, schemas.get(sid, ""), encoding)
    elif op == OP_MESSAGE:
        cid, _seq, log_time, _pub = c.unpack(_MESSAGE_HEAD)
        scan.messages.append((cid, log_time, bytes(content[c.pos :])))


def _records(buf: bytes, scan: Scan, schemas: dict[int, str], cut: bool) -> int:
    """Parse the records of a chunk's (decompressed) data; with `cut`, the last one may be incomplete.
    Returns how many bytes of `buf` were whole records."""
    pos = 0
    while pos + _RECORD_HEAD.size <= len(buf):
        op, length = _RECORD_HEAD.unpack_from(buf, pos)
        end = pos + _RECORD_HEAD.size + length
        if end > len(buf):
            if cut:
                break
            raise InputError(f"a record inside a chunk runs past the chunk's end (opcode {op:#04x})")
        _record(scan, schemas, op, buf[pos + _RECORD_HEAD.size : end])
        pos = end
    if pos != len(buf) and not cut:
        raise InputError("a chunk ends inside a record header")
    return pos


def _decompress(compression: str, data: bytes, whole: bool) -> bytes:
    """Chunk records; a chunk cut short gives what its first bytes decompress to."""
    if compression == "":
        return data
    if compression == "zstd":
        from backports import zstd  # rosbags' own zstd (the stdlib's compression.zstd from Python 3.14)

        return zstd.decompress(data) if whole else zstd.ZstdDecompressor().decompress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data) if whole else lz4.frame.LZ4FrameDecompressor().decompress(data)
    raise InputError(f"chunk compression {compression!r} is not supported (none, zstd or lz4)")


def _chunk(scan: Scan, schemas: dict[int, str], content: bytes, whole: bool) -> int:
    """One chunk record's messages; `whole` False: the record was cut short at the end of the file.
    Returns how many bytes of `content` lie before the end of its last whole record (0 when compressed:
    the cut cannot be placed in the file then)."""
    c = _Cursor(content)
    _start, _end, size, crc = c.unpack(_CHUNK_HEAD)
    compression = c.string()
    length = c.u64()
    data = c.take(length) if whole else content[c.pos : c.pos + length]
    records = _decompress(compression, data, whole)
    if whole:
        if len(records) != size:
            raise InputError(f"chunk decompresses to {len(records)} bytes, its header says {size}")
        if crc and zlib.crc32(records) != crc:
            raise InputError("chunk CRC-32 does not match its records")
    parsed = _records(records, scan, schemas, cut=not whole)
    return c.pos + parsed if compression == "" else 0


def scan_mcap(path: Path | str) -> Scan:
    """Every whole Schema, Channel and Message record of an MCAP file, front to back (see the module doc)."""
    path = Path(path)
    buf = path.read_bytes()
    scan = Scan(path, len(buf))
    if buf[: len(MAGIC)] != MAGIC:
        raise NotMcap(f"{path}: not an MCAP file (no MCAP magic at its start)")
    pos = len(MAGIC)
    schemas: dict[int, str] = {}
    first = True
    while True:
        scan.whole_bytes = pos
        if pos + _RECORD_HEAD.size > len(buf):
            scan.stop = "the file ends inside a record header" if pos < len(buf) else "the file ends after a whole record"
            return scan
        op, length = _RECORD_HEAD.unpack_from(buf, pos)
        start, end = pos + _RECORD_HEAD.size, pos + _RECORD_HEAD.size + length
        if first:
            if op != OP_HEADER or end > len(buf):
                raise NotMcap(f"{path}: not an MCAP file (no header record after the magic)")
            profile = _Cursor(buf[start:end]).string()
            if profile != "ros2":
                raise NotMcap(f"{path}: an MCAP file of profile {profile!r}, not a ROS 2 bag ('ros2')")
            first = False
            pos = end
            continue
        if op in (OP_DATA_END, OP_FOOTER):
            scan.complete = True
            return scan
        if end > len(buf):
            if op == OP_CHUNK:
                before = len(scan.messages)
                try:
                    consumed = _chunk(scan, schemas, buf[start:], whole=False)
                    scan.whole_bytes = start + consumed if consumed else pos
                except Exception:  # noqa: BLE001 - its first bytes were not enough (any decompressor's error)
                    pass
                got = scan.cut_chunk_messages = len(scan.messages) - before
                scan.stop = (f"the file ends inside a chunk ({len(buf) - start} of its {length} bytes; "
                             f"{got} whole messages read out of it)")
            else:
                scan.stop = f"the file ends inside a record (opcode {op:#04x}, {len(buf) - start} of {length} bytes)"
            return scan
        try:
            if op == OP_CHUNK:
                _chunk(scan, schemas, buf[start:end], whole=True)
                scan.chunks += 1
            else:
                _record(scan, schemas, op, buf[start:end])
        except Exception as e:  # noqa: BLE001 - a record that does not parse (any decompressor's error): keep what came before it
            why = str(e) or "a field runs past the record's end"
            scan.stop = f"a damaged record at byte {pos} (opcode {op:#04x}: {why})"
            return scan
        pos = end
