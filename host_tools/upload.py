"""`fleetlab upload`: send a bundle's model image to a running slipest CANopen node, activate it
when asked, and read back the active model's version and hash.

The transfer is an SDO block download (CRC-checked) of the DOMAIN object 0x2000 by python
`canopen`; the same CAN frames go over a CAN bus (any python-can interface: slcan adapter,
socketcan, ...) or over the serial link's COBS packets. Every frame of the transfer is counted
and its bits on a CAN bus are computed (stuff bits exactly), so the report states the bus time
at a given bit rate.
"""

from __future__ import annotations

import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import can
import canopen

from .canopen_master import ABORT_NAMES
from .canopen_session import CanopenSession
from .wire.can_bits import frame_bits


class SdoTap(can.BusABC):
    """Counts the SDO frames of one node (both directions) and their CAN bits on the way through."""

    def __init__(self, inner: can.BusABC, node_id: int) -> None:
        self.inner = inner
        self.ids = (0x600 + node_id, 0x580 + node_id)
        self.frames = self.bits = 0
        self._lock = threading.Lock()
        self.channel_info = getattr(inner, "channel_info", "tap")
        super().__init__(channel=None)

    def _count(self, msg: can.Message | None) -> None:
        if msg is not None and msg.arbitration_id in self.ids and not msg.is_extended_id:
            with self._lock:
                self.frames += 1
                self.bits += frame_bits(msg.arbitration_id, bytes(msg.data))

    def _recv_internal(self, timeout):
        msg = self.inner.recv(timeout)
        self._count(msg)
        return msg, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)
        self._count(msg)

    def reset(self) -> None:
        with self._lock:
            self.frames = self.bits = 0

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()


@dataclass
class UploadReport:
    image_bytes: int
    sdo_frames: int
    bus_bits: int
    bus_time_s_at_500k: float
    wall_time_s: float
    activated: bool
    active_version: int
    active_hash32: str
    active_sha256: str | None
    windows_during_upload: int | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def explain(e: Exception) -> str:
    """One line for an SDO failure: the abort code and its meaning."""
    if isinstance(e, canopen.SdoAbortedError):
        return f"the node refused: SDO abort 0x{e.code:08X} ({ABORT_NAMES.get(e.code, 'see CiA 301')})"
    return f"no answer from the node: {e}"


def upload_image(session: CanopenSession, tap: SdoTap, image: bytes, activate: bool, block: bool = True,
                 progress: Callable[[int], None] | None = None) -> UploadReport:
    """Upload (and activate) on an open session whose master bus is `tap`."""
    m = session.master
    tap.reset()
    t0 = time.perf_counter()
    try:
        m.upload(image, block=block, progress=progress)
        if activate:
            m.activate()
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as e:
        raise OSError(explain(e)) from None
    wall = time.perf_counter() - t0
    frames, bits = tap.frames, tap.bits
    model = m.active_model()
    return UploadReport(len(image), frames, bits, bits / 500_000, wall, activate, model["version"],
                        f"{model['hash32']:08x}", model["sha256"])


def open_tapped(link: str, eds: Path, node_id: int, **kwargs) -> tuple[CanopenSession, SdoTap]:
    taps: list[SdoTap] = []

    def wrap(bus: can.BusABC) -> can.BusABC:
        taps.append(SdoTap(bus, node_id))
        return taps[0]

    session = CanopenSession(link, eds, node_id, wrap_bus=wrap, **kwargs)
    return session, taps[0]


def read_image(bundle: Path) -> bytes:
    img = Path(bundle) / "model.img"
    if not img.is_file():
        raise OSError(f"{bundle}: no model.img (export the bundle with `fleetlab export` first)")
    return img.read_bytes()
