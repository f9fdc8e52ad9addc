"""`fleetlab upload`: send a bundle's model image to a running slipest CANopen node, activate it
when asked, and read back the active model's version and hash.

The update is CiA 302-3 program download by python `canopen`: clear (0x1F51 = 3), an SDO block download
(CRC-checked) of the program data 0x1F50, start (0x1F51 = 1: the new model on trial, the node boots up) and,
unless asked not to, confirm (0x1F51 = 0x80); the flash status 0x1F57 names a refusal; the same CAN frames go over a CAN bus (any python-can interface: slcan adapter,
socketcan, ...) or over the serial link's COBS packets. Every frame of the transfer is counted
and its bits on a CAN bus are computed (stuff bits exactly), so the report states the bus time
at a given bit rate.

The node may have run long before the command and keeps running after it: its counters (0x2003, 0x2005, all
UNSIGNED32) are read at the start and reported as differences from there (across a wrap), with the totals beside.
"""

from __future__ import annotations

import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import can
import canopen

from fleetlab.canopen_od import objects as od
from .canopen_master import ABORT_NAMES, SlipestMaster
from .canopen_session import CanopenSession
from .status_codes import meanings
from .wire.can_bits import frame_bits
from fleetlab.errors import InputError


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
    confirmed: bool
    active_version: int
    active_hash32: str
    active_sha256: str | None
    windows_during_upload: int | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def counters_since(now: dict[str, int], start: dict[str, int]) -> dict[str, int]:
    """Each UNSIGNED32 counter's rise from `start` to `now` (across a wrap)."""
    return {k: (v - start.get(k, 0)) % (1 << 32) for k, v in now.items()}


# The kind of a refusal, by the slipest status the node gives it (byte 3 of its EMCY 0x6300 / 0x5000, or 0x2006
# sub 2); the status codes and their meanings are read from slipest_status.h (status_codes.meanings()).
REFUSAL_KINDS = {"STALE": "stale version", "AUTH": "authentication", "FORMAT": "format", "VERSION": "format",
                 "LENGTH": "size", "ARCH": "architecture", "CRC": "corrupted image", "HASH": "corrupted image",
                 "RANGE": "model check", "NONFINITE": "model check", "NVM": "the node's NVM failed"}
# the SDO aborts after which the node says why by EMCY and in 0x2006 sub 2 (a store call failed)
_STORE_ABORTS = (od.ABORT["STORE"], od.ABORT["LENGTH"], od.ABORT["HARDWARE"])
_EMCY_STORE = (od.EMCY["DATA_SET"], od.EMCY["HARDWARE"])


def refusal_status(master: SlipestMaster | None, emcy_from: int = 0) -> int | None:
    """The slipest status of the node's last refusal: byte 3 of its newest EMCY 0x6300 / 0x5000 in the master's
    EMCY log (from entry `emcy_from` on), else 0x2006 sub 2 (last store status) read by SDO; None when neither
    says (no master, or the node does not answer)."""
    if master is None:
        return None
    log = master.node.emcy.log[emcy_from:]
    for entry in reversed(log):
        if entry.code in _EMCY_STORE and entry.data:
            return int.from_bytes(entry.data[:1], "little", signed=True)
    try:
        st = master.flash_status()["slipest_status"]  # 0x1F57 bits 16-23
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError):
        return None
    return st or None


def explain(e: Exception, master: SlipestMaster | None = None, emcy_from: int = 0,
            image_bytes: int | None = None) -> str:
    """One line for an SDO failure: why the node refused (the kind and the meaning of the slipest status it gives
    by EMCY or in 0x2006 sub 2, when there is a master to ask), then the abort code and its meaning."""
    if not isinstance(e, canopen.SdoAbortedError):
        return f"no answer from the node: {e}"
    abort = f"SDO abort 0x{e.code:08X} ({ABORT_NAMES.get(e.code, 'see CiA 301')})"
    if e.code == od.ABORT["TOO_HIGH"] and image_bytes is not None:
        return (f"the node refused the image: size: {image_bytes} bytes is more than its slots take "
                f"(SLIPEST_STORE_IMAGE_MAX of its build); {abort}")
    st = refusal_status(master, emcy_from) if e.code in _STORE_ABORTS else None
    flash = _flash_text(master)
    if st is not None and st in meanings():
        name, meaning = meanings()[st]
        kind = REFUSAL_KINDS.get(name.removeprefix("SLIPEST_E_"), "refused")
        return f"the node refused the image: {kind}: {meaning} ({name} {st}); {flash}{abort}"
    return f"the node refused: {flash}{abort}"


def _flash_text(master: SlipestMaster | None) -> str:
    """'flash status N (meaning); ' from 0x1F57 when the node names an error there, else ''."""
    if master is None:
        return ""
    try:
        fs = master.flash_status()
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError, KeyError):
        return ""
    return f"0x1F57 flash status {fs['code']} ({fs['meaning']}); " if fs["code"] else ""


def upload_image(session: CanopenSession, tap: SdoTap, image: bytes, activate: bool, block: bool = True,
                 progress: Callable[[int], None] | None = None, confirm: bool = True,
                 clear: bool = True) -> UploadReport:
    """Upload (and activate: start, then confirm unless `confirm` is False) on an open session whose master bus is
    `tap`. A refusal is an OSError whose one line says why (explain())."""
    m = session.master
    tap.reset()
    emcy_from = len(m.node.emcy.log)
    t0 = time.perf_counter()
    try:
        m.upload(image, block=block, progress=progress, clear=clear)
        if activate:
            m.activate(confirm=confirm)
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as e:
        raise OSError(explain(e, m, emcy_from, len(image))) from None
    wall = time.perf_counter() - t0
    frames, bits = tap.frames, tap.bits
    model = m.active_model()
    return UploadReport(len(image), frames, bits, bits / 500_000, wall, activate, activate and confirm,
                        model["version"], f"{model['hash32']:08x}", model["sha256"])


NO_PREVIOUS_MODEL = ("no previous model to roll back to (none was active before this one, or an upload since has "
                     "taken its slot, even one the node then refused)")


def rollback_model(session: CanopenSession) -> dict:
    """0x2002 = 1: the node re-activates its previous model. Returns the active model after it (active_model());
    OSError with one line when there is none (NO_PREVIOUS_MODEL) or the node refuses otherwise."""
    m = session.master
    emcy_from = len(m.node.emcy.log)
    try:
        m.rollback()
    except canopen.SdoAbortedError as e:
        if e.code == od.ABORT["STATE"]:
            raise OSError(NO_PREVIOUS_MODEL) from None
        raise OSError(explain(e, m, emcy_from)) from None
    except canopen.SdoCommunicationError as e:
        raise OSError(explain(e)) from None
    return m.active_model()


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


def rehearse(session: CanopenSession, tap: SdoTap, image: bytes, new_bundle: Path, boot_bundle: Path,
             windows: int, seed: int = 1, scale: float = 0.3, block: bool = True,
             progress: Callable[[int], None] | None = None, confirm: bool = True) -> dict:
    """The after-landing update on a running node, checked: telemetry windows stream while the image
    is uploaded (every window must be answered, by the boot model, bit-exact), the image is started on trial
    between two windows (CiA 302-3 start: the node boots up into PRE-OPERATIONAL and is set OPERATIONAL again),
    then the next windows must equal the new model's torch integer reference. Only then, and with `confirm`, is
    the new model confirmed (0x1F51 = 0x80); a failed rehearsal leaves it on trial, so the next reset reverts it."""
    import numpy as np

    from fleetlab.data import features_int as fi

    from .canopen_master import EstimateCollector
    from .canopen_session import stream_telemetry
    from .sources import sim_source
    from .verify.reference import Reference

    samples = sim_source(seed, scale).samples_q
    if len(samples) < 2 * windows * fi.SAMPLES_PER_WINDOW:
        raise InputError(f"the simulator gave {len(samples) // fi.SAMPLES_PER_WINDOW} windows at scale {scale}; "
                         f"{2 * windows} needed")
    first = samples[: windows * fi.SAMPLES_PER_WINDOW]
    second = samples[windows * fi.SAMPLES_PER_WINDOW: 2 * windows * fi.SAMPLES_PER_WINDOW]
    m = session.master
    counters_start, store_start = m.counters(), m.store_counters()  # the node may have run before
    m.node.tpdo.read()
    col = EstimateCollector(m.node)
    try:
        m.clear()  # 0x1F51 = 3 while PRE-OPERATIONAL, before the telemetry streams: no window is lost to it
    except canopen.SdoAbortedError as e:
        raise OSError(explain(e, m)) from None
    m.node.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    before = m.active_model()
    sent: list[int] = []
    streamer = threading.Thread(target=lambda: sent.append(stream_telemetry(session, first, col)), daemon=True)
    streamer.start()
    if not col.wait_for(2, 20):
        rejected = counters_since(m.counters(), counters_start)["frames_rejected"]
        if rejected:
            raise OSError(f"the node rejected {rejected} telemetry frames of this rehearsal and sent no estimates: "
                          "its sample counter is past this rehearsal's (which starts at 0), as on a node that ran "
                          "before; reset it (NMT reset node) to rehearse on it")
        raise OSError("the node sends no estimates (is it operational?)")
    t0 = time.monotonic()
    report = upload_image(session, tap, image, activate=False, block=block, progress=progress, clear=False)
    t1 = time.monotonic()
    streamer.join(60)
    if not sent or not col.wait_for(sent[0], 20):
        raise OSError(f"windows lost during the upload: {col.count()} estimates for {sent[0] if sent else '?'} windows")
    during = sum(1 for t in col.arrival if t0 <= t <= t1)
    phase1 = np.array([e.logits for e in col.estimates])
    exact1 = phase1.shape == (windows, 3) and bool(np.array_equal(
        phase1, Reference.load(boot_bundle).q_logits(fi.featurise_int(first).features)[0]))
    mid_counters = m.counters()
    try:
        m.activate(confirm=False)  # between two windows, on trial: the next window is the new model's
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as e:
        raise OSError(explain(e, m)) from None
    after = m.active_model()
    post_counters = m.counters()  # the start restarted the node's application: its counters begin again
    m.node.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    n1 = col.count()
    n = stream_telemetry(session, second, col, first_counter=len(first))
    if not col.wait_for(n1 + n, 20):
        raise OSError(f"windows lost after activation: {col.count() - n1} of {n}")
    phase2 = np.array([e.logits for e in col.estimates[n1:]])
    counters, store = m.counters(), m.store_counters()
    ref2 = Reference.load(new_bundle).q_logits(fi.featurise_int(second).features)[0]
    new_exact = bool(np.array_equal(phase2, ref2))
    confirmed = False
    if new_exact and exact1 and n1 == windows and confirm:
        m.node.nmt.state = "PRE-OPERATIONAL"  # program control is a PRE-OPERATIONAL service
        time.sleep(0.02)
        m.confirm()
        confirmed = True
        m.node.nmt.state = "OPERATIONAL"
    since = counters_since(mid_counters, counters_start)
    since2 = counters_since(counters, post_counters)
    return {
        "upload": report.as_dict() | {"windows_during_upload": during},
        "before": {"version": before["version"], "hash32": f"{before['hash32']:08x}"},
        "after": {"version": after["version"], "hash32": f"{after['hash32']:08x}", "sha256": after["sha256"]},
        "windows_streamed_during_upload_phase": windows,
        "windows_answered_during_upload_phase": n1,
        "boot_model_bit_exact": exact1,
        "windows_after_activation": int(len(phase2)),
        "new_model_bit_exact": new_exact,
        "confirmed": confirmed,
        # what this rehearsal did to the node's counters (it may have run before; the start restarts them), and
        # the node's totals
        "store_counters": counters_since(store, store_start),
        "counters": {k: since[k] + since2.get(k, 0) for k in since},
        "store_counters_total": store,
        "counters_total": counters,
    }
