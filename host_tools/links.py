"""Links from the host to an estimator: SLCAN and COBS serial over a (pseudo-)terminal,
python-can buses by name, and an in-process estimator (the C library through ctypes)
attached to a python-can virtual bus.

Every link writes wire items in order and delivers what the estimator answers on a
queue filled by a reader thread, so a full pty buffer never deadlocks the host: the
writer blocks (flow control) while the reader keeps draining.

Links are registered by name (`register_link`, `link_class`), as python-can registers its
bus interfaces: `fleetlab emulate --link NAME` and `fleetlab stream` both pick their link
class here, so a new link is one class with one decorator.
"""

from __future__ import annotations

import itertools
import os
import queue
import socket
import threading
import time
from pathlib import Path
from typing import ClassVar, Sequence

import can
import serial

from .binding import CEstimator
from .wire.dbc import Frame
from .wire.items import WireItem
from .wire.serial_framing import (
    PacketDecoder,
    Rejected,
    encode_bad_crc_packet,
    encode_length_mismatch_packet,
    encode_packet,
    slcan_line,
    slcan_malformed_line,
)
from fleetlab.errors import InputError

RxItem = tuple[Frame | Rejected, float]

_LINKS: dict[str, type["Link"]] = {}
# Old spelling kept as an alias because tests use `--link serial` (and older docs did).
ALIASES = {"serial": "cobs"}


def register_link(cls: type["Link"]) -> type["Link"]:
    """Class decorator: make `cls` available under `cls.kind`."""
    if cls.kind in _LINKS or cls.kind in ALIASES:
        raise InputError(f"link {cls.kind!r} is registered already")
    _LINKS[cls.kind] = cls
    return cls


def link_class(name: str) -> type["Link"]:
    """The link class registered under `name` (or one of its aliases)."""
    kind = ALIASES.get(name, name)
    if kind not in _LINKS:
        raise InputError(f"unknown link {name!r}; choose from {', '.join(_LINKS)}")
    return _LINKS[kind]


def canonical_link(name: str) -> str:
    return link_class(name).kind


def estimator_links() -> tuple[str, ...]:
    """Links that reach fleetlab's own estimator: the emulator over a pty, or the library in-process."""
    return tuple(k for k, c in _LINKS.items() if c.emulator_protocol is not None or c.in_process)


def to_message(frame: Frame) -> can.Message:
    return can.Message(arbitration_id=frame.can_id, data=frame.data, dlc=len(frame.data), is_extended_id=False)


def from_message(msg: can.Message) -> Frame | Rejected:
    if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.dlc > 8:
        return Rejected("not a classic data frame", bytes(msg.data))
    return Frame(msg.arbitration_id, bytes(msg.data))


def open_can_bus(interface: str, channel: str | None, **kwargs) -> can.BusABC:
    """A python-can bus by name, with a clear error when the interface cannot exist here."""
    if interface == "socketcan":
        try:
            socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        except (AttributeError, OSError) as e:
            raise OSError(
                f"socketcan: this kernel has no SocketCAN support (AF_CAN socket: {e}); load the can/vcan "
                "modules (modprobe vcan; ip link add dev vcan0 type vcan; ip link set up vcan0) or use "
                "--interface virtual/slcan"
            ) from None
        if channel and not Path(f"/sys/class/net/{channel}").exists():
            raise OSError(f"socketcan: no network interface {channel!r} (create it: ip link add dev {channel} type vcan)")
    if interface == "slcan":
        kwargs.setdefault("sleep_after_open", 0)
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except can.CanError as e:
        where = f"on {channel!r}" if channel is not None else "(no --channel given)"
        raise OSError(f"{interface} bus {where}: {e}") from None


class Link:
    """Base: `write(items)` in order; answers arrive on `rx` as (Frame | Rejected, time)."""

    kind: ClassVar[str] = "link"  # registry name
    emulator_protocol: ClassVar[str | None] = None  # the C emulator's `--link` for this framing, if it speaks it
    in_process: ClassVar[bool] = False  # the estimator is the C library loaded into this process
    name = "link"  # this instance, e.g. "slcan:/dev/pts/3"
    corrupt_kinds: frozenset[str] = frozenset()

    @classmethod
    def over_port(cls, port: str, full_speed: bool = False, **options) -> "Link":
        """Open this link on a serial port or pty (e.g. a started emulator's). `full_speed`:
        write many items per call, to measure the link rather than per-call overhead."""
        raise InputError(f"the {cls.kind} link does not run over a serial port")

    def __init__(self) -> None:
        self.rx: queue.SimpleQueue[RxItem] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_written = 0
        self.reader_error: BaseException | None = None

    def _start_reader(self) -> None:
        self._thread = threading.Thread(target=self._reader_guard, name=f"{self.name}-rx", daemon=True)
        self._thread.start()

    def _reader_guard(self) -> None:
        try:
            self._reader()
        except Exception as e:  # the link went away (e.g. emulator killed): report, don't crash
            if not self._stop.is_set():
                self.reader_error = e

    def _reader(self) -> None:
        raise NotImplementedError

    def write(self, items: Sequence[WireItem]) -> None:
        raise NotImplementedError

    def _check_corrupt(self, item: WireItem) -> None:
        if item.corrupt is not None and item.corrupt not in self.corrupt_kinds:
            raise InputError(f"{self.name} link cannot carry a {item.corrupt!r} item")

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@register_link
class CanBusLink(Link):
    """Any python-can bus (slcan, virtual, socketcan, ...)."""

    kind = "can"

    def __init__(self, bus: can.BusABC, name: str) -> None:
        super().__init__()
        self.bus, self.name = bus, name
        self._start_reader()

    def _reader(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.05)
            if msg is not None:
                self.rx.put((from_message(msg), time.perf_counter()))

    def write(self, items: Sequence[WireItem]) -> None:
        for item in items:
            self._check_corrupt(item)
            self.bus.send(to_message(item.frame))

    def close(self) -> None:
        super().close()
        try:
            self.bus.shutdown()
        except (OSError, can.CanError):
            pass  # the other end may already be gone


@register_link
class SlcanLink(CanBusLink):
    """python-can's slcan interface on a serial port or pty; malformed lines go to the raw port.

    batched=False sends each frame with `bus.send` (a write and a drain per frame, as
    python-can does); batched=True writes the same SLCAN lines through the bus's own
    serial port many at a time, which measures the link rather than per-call overhead.
    """

    kind = "slcan"
    emulator_protocol = "slcan"
    corrupt_kinds = frozenset({"bad_crc"})

    @classmethod
    def over_port(cls, port: str, full_speed: bool = False, **options) -> "SlcanLink":
        return cls(port, batched=full_speed, **options)

    def __init__(self, port: str, bitrate: int | None = 500000, batched: bool = False) -> None:
        super().__init__(open_can_bus("slcan", port, bitrate=bitrate), f"slcan:{port}")
        self.batched = batched

    def _line(self, item: WireItem) -> bytes:
        if item.corrupt is not None:
            self._check_corrupt(item)
            return slcan_malformed_line(item.frame)
        return slcan_line(item.frame)

    def write(self, items: Sequence[WireItem]) -> None:
        port = self.bus.serialPortOrig  # type: ignore[attr-defined]
        if self.batched:
            data = b"".join(self._line(it) for it in items)
            port.write(data)
            self.bytes_written += len(data)
            return
        for item in items:
            if item.corrupt is not None:
                port.write(self._line(item))
            else:
                self.bus.send(to_message(item.frame))


@register_link
class CobsLink(Link):
    """COBS + CRC-16 packets over pyserial (pty or real port), written in chunks for speed."""

    kind = "cobs"
    emulator_protocol = "cobs"
    corrupt_kinds = frozenset({"bad_crc", "length_mismatch"})
    CHUNK = 256  # packets per write() call

    def __init__(self, port: str, baudrate: int = 921600) -> None:
        super().__init__()
        self.name = f"cobs:{port}"
        try:
            self.port = serial.Serial(port, baudrate=baudrate, timeout=0.05, write_timeout=None)
        except serial.SerialException as e:
            raise OSError(f"serial port {port}: {e}") from None
        self.decoder = PacketDecoder()
        self._start_reader()

    @classmethod
    def over_port(cls, port: str, full_speed: bool = False, **options) -> "CobsLink":
        return cls(port, **options)  # always written in chunks

    def _render(self, item: WireItem) -> bytes:
        if item.corrupt is None:
            return encode_packet(item.frame)
        self._check_corrupt(item)
        if item.corrupt == "bad_crc":
            return encode_bad_crc_packet(item.frame)
        return encode_length_mismatch_packet(item.frame)

    def write(self, items: Sequence[WireItem]) -> None:
        for i in range(0, len(items), self.CHUNK):
            data = b"".join(self._render(it) for it in items[i : i + self.CHUNK])
            self.port.write(data)
            self.bytes_written += len(data)

    def _reader(self) -> None:
        while not self._stop.is_set():
            data = self.port.read(max(1, self.port.in_waiting))
            if data:
                t = time.perf_counter()
                for res in self.decoder.feed(data):
                    self.rx.put((res, t))

    def close(self) -> None:
        super().close()
        try:
            self.port.close()
        except OSError:
            pass


# --- in-process estimator: the C library (fleetlab.host_tools.binding) on a virtual bus ---


class InprocEstimatorNode:
    """A CEstimator attached to a python-can bus: every frame in, its answers out."""

    def __init__(self, estimator: CEstimator, bus: can.BusABC) -> None:
        self.est, self.bus = estimator, bus
        self.handled = 0  # frames taken off the bus (read by the host for flow control)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="slipest-inproc", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.05)
            if msg is None:
                continue
            self.handled += 1
            f = from_message(msg)
            if isinstance(f, Rejected):
                self.est.link_error()
                continue
            for out in self.est.handle(f):
                self.bus.send(to_message(out))

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=2)
        self.bus.shutdown()


_channel_ids = itertools.count()


@register_link
class InprocLink(CanBusLink):
    """Host side of a python-can virtual bus shared with an in-process C estimator."""

    kind = "inproc"
    in_process = True

    def __init__(self, lib_path: Path | str, channel: str | None = None) -> None:
        channel = channel or f"fleetlab-inproc-{os.getpid()}-{next(_channel_ids)}"
        self.estimator = CEstimator(lib_path)
        self.node = InprocEstimatorNode(self.estimator, can.Bus(interface="virtual", channel=channel))
        super().__init__(can.Bus(interface="virtual", channel=channel), f"inproc:{channel}")
        self.channel = channel
        self.sent = 0

    # A virtual bus queues without limit; like a controller's receive FIFO, keep at most
    # this many frames in flight so full-speed latency measures the estimator, not a backlog.
    MAX_IN_FLIGHT = 512

    def write(self, items: Sequence[WireItem]) -> None:
        for item in items:
            self._check_corrupt(item)
            while self.sent - self.node.handled >= self.MAX_IN_FLIGHT and self.node.thread.is_alive():
                time.sleep(0.0001)
            self.bus.send(to_message(item.frame))
            self.sent += 1

    def restart(self) -> None:
        """The in-process equivalent of killing and restarting the emulator: a fresh node."""
        self.node.close()
        self.estimator.reset()
        self.node = InprocEstimatorNode(self.estimator, can.Bus(interface="virtual", channel=self.channel))
        self.sent = 0

    def close(self) -> None:
        self.node.close()
        super().close()
