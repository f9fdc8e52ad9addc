"""The master side of the slipest CANopen node, on the python `canopen` library.

`SlipestMaster` is a `canopen.Network` with the node added from its EDS: NMT, heartbeat, SDO
reads of identity and model, the model update by CiA 302-3 program download (clear 0x1F51 = 3, SDO block
download of the DOMAIN 0x1F50, start 0x1F51 = 1 on trial with the node's boot-up, confirm 0x1F51 = 0x80; the
flash status 0x1F57 says why a download was refused), rollback (0x2002 = 1, which 302-3 lacks), and the
estimates decoded from the TPDOs by canopen's own PDO maps.
`telemetry_rpdos` turns telemetry samples into the RPDO frames the node takes.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Callable

import can
import canopen
import numpy as np

from fleetlab.canopen_od import objects as od
from .wire.dbc import Frame, WindowEstimate, codec, telemetry_frames

ACTIVE_MODEL, ROLLBACK, COUNTERS, SLOTS, STORE_COUNTERS, UPLOAD = (
    od.IDX_ACTIVE_MODEL, od.IDX_ROLLBACK, od.IDX_COUNTERS, od.IDX_SLOTS, od.IDX_STORE_COUNTERS, od.IDX_UPLOAD)

# SDO abort codes (CiA 301) by meaning, as the node sends them (canopen_od/objects.py is their one source)
ABORT_NAMES = {code: doc for _, code, doc in od.ABORT_CODES}
# CiA 302-3 program control commands and flash status codes, by name (the same source)
PROGRAM_CONTROL = dict(od.PROGRAM_CONTROL)
FLASH_MEANINGS = {code: doc for _, code, doc in od.FLASH_STATUS}


def rpdo_cob_ids(node_id: int) -> dict[str, int]:
    """DBC telemetry frame name -> RPDO COB-ID of the node (from the object dictionary source)."""
    out = {}
    for direction, number, rec in od.PDOS:
        frame = od.PDO_RECORDS[rec][1]
        if direction == "rx" and frame is not None:
            out[frame] = od.pdo_cob_base(direction, number) + node_id
    return out


def telemetry_rpdos(samples_q: np.ndarray, node_id: int, first_counter: int = 0) -> list[Frame]:
    """RPDO1..3 frames of consecutive int16 samples (n,7): the DBC telemetry bytes on the
    node's RPDO COB-IDs."""
    ids = rpdo_cob_ids(node_id)
    by_dbc_id = {codec(name).frame_id: cob for name, cob in ids.items()}
    out: list[Frame] = []
    for k, raw in enumerate(np.asarray(samples_q)):
        for f in telemetry_frames(first_counter + k, raw):
            out.append(Frame(by_dbc_id[f.can_id], f.data))
    return out


class EstimateCollector:
    """Windows from TPDO1..3 through canopen's PDO maps (TPDO1 estimate, TPDO2 logits 0/1,
    TPDO3 logit 2 + window counter), and the model status from TPDO4."""

    def __init__(self, node: canopen.RemoteNode) -> None:
        self.estimates: list[WindowEstimate] = []
        self.arrival: list[float] = []  # time.monotonic() of each estimate's last frame
        self.model_status: list[tuple[int, int]] = []
        self._head: dict | None = None
        self._l01: tuple[int, int] | None = None
        self._lock = threading.Lock()
        tp = node.tpdo
        tp[1].add_callback(self._est)
        tp[2].add_callback(self._logits01)
        tp[3].add_callback(self._logit2)
        tp[4].add_callback(self._status)

    @staticmethod
    def _values(m) -> dict[str, int]:
        return {v.name.split(".", 1)[1]: v.raw for v in m.map}

    def _est(self, m) -> None:
        self._head = self._values(m)

    def _logits01(self, m) -> None:
        v = self._values(m)
        self._l01 = (v["logit_0"], v["logit_1"])

    def _logit2(self, m) -> None:
        v = self._values(m)
        h, l01 = self._head, self._l01
        self._head = self._l01 = None
        if h is None or l01 is None or h["window_counter"] != v["window_counter"]:
            return  # an incomplete window cannot be matched: the comparison will count it missing
        with self._lock:
            now = time.monotonic()
            self.estimates.append(WindowEstimate(h["window_counter"], h["slip_class"], h["slip_class_f32"], h["flags"],
                                                 h["n_samples"], h["saturations"], (l01[0], l01[1], v["logit_2"]), now))
            self.arrival.append(now)

    def _status(self, m) -> None:
        v = self._values(m)
        self.model_status.append((v["model_hash32"], v["model_version"]))

    def count(self) -> int:
        with self._lock:
            return len(self.estimates)

    def wait_for(self, n: int, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while self.count() < n and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.count() >= n


class SlipestMaster:
    """python `canopen` as the master of one slipest node on a python-can bus."""

    def __init__(self, bus: can.BusABC, eds: Path | str, node_id: int = 5) -> None:
        self.network = canopen.Network(bus)
        self.network.connect()
        self.node = canopen.RemoteNode(node_id, str(eds))
        self.network.add_node(self.node)
        # telemetry shares the bus with the SDO transfer: answers may queue behind RPDOs
        self.node.sdo.RESPONSE_TIMEOUT = 1.0
        self.node_id = node_id

    # -- NMT / identity / model -------------------------------------------------------------
    def identity(self) -> dict[str, int]:
        rec = self.node.sdo[0x1018]
        return {"vendor_id": rec[1].raw, "product_code": rec[2].raw, "revision": rec[3].raw, "serial": rec[4].raw}

    def active_model(self) -> dict:
        """version, hash32, sha256 (hex; None when the node has no model or does not know it: 32 zero bytes, or
        the "no data" abort of a node older than OD 2.0) and slot (None for the built-in model; 0xFE: none)."""
        rec = self.node.sdo[ACTIVE_MODEL]
        try:
            raw = bytes(rec[3].raw)
            sha = raw.hex() if any(raw) else None
        except canopen.SdoAbortedError as e:
            if e.code != od.ABORT["NO_DATA"]:
                raise
            sha = None
        slot = rec[4].raw
        return {"version": rec[1].raw, "hash32": rec[2].raw, "sha256": sha, "slot": None if slot == 0xFF else slot}

    def counters(self) -> dict[str, int]:
        rec = self.node.sdo[COUNTERS]
        return {name: rec[k].raw for k, name in enumerate(od.COUNTERS, start=1)}

    def store_counters(self) -> dict[str, int]:
        rec = self.node.sdo[STORE_COUNTERS]
        return {name: rec[k].raw for k, name in enumerate(od.STORE_COUNTERS, start=1)}

    def slots(self) -> list[dict[str, int]]:
        rec = self.node.sdo[SLOTS]
        return [{f: rec[(s * len(od.SLOT_FIELDS)) + k].raw for k, (f, _) in enumerate(od.SLOT_FIELDS, start=1)}
                for s in (0, 1)]

    def flash_status(self) -> dict:
        """0x1F57 sub 1: busy (a download open), the CiA 302-3 error code and its meaning, and the slipest status
        behind it (bits 16-23, two's complement)."""
        raw = self.node.sdo[od.IDX_FLASH_STATUS][1].raw
        code = (raw >> od.FLASH_CODE_SHIFT) & 0x7F
        st = (raw >> od.FLASH_SLIPEST_SHIFT) & 0xFF
        return {"busy": bool(raw & od.FLASH_BUSY), "code": code, "meaning": FLASH_MEANINGS.get(code, "CiA 302-3"),
                "slipest_status": st - 256 if st > 127 else st}

    def software_id(self) -> int:
        """0x1F56 sub 1: the running model's hash32."""
        return self.node.sdo[od.IDX_PROGRAM_SWID][1].raw

    def program_control(self, command: str) -> None:
        """0x1F51 sub 1 = a CiA 302-3 command: stop, start, reset, clear, confirm."""
        self.node.sdo[od.IDX_PROGRAM_CONTROL][1].raw = PROGRAM_CONTROL[command]

    def upload_status(self) -> dict[str, int]:
        rec = self.node.sdo[UPLOAD]
        return {"state": rec[1].raw, "last_store_status": rec[2].raw, "bytes_received": rec[3].raw}

    # -- model update ---------------------------------------------------------------------
    def upload(self, image: bytes, block: bool = True, progress: Callable[[int], None] | None = None,
               chunk: int = 7 * 127, clear: bool = True) -> None:
        """CiA 302-3: clear (0x1F51 = 3), then write `image` into the program data 0x1F50 (the inactive slot): SDO
        block download with CRC (or segmented). The running model keeps estimating meanwhile (the node clears the
        other slot, so it need not be stopped). Raises canopen.SdoAbortedError with the node's abort code on a
        refusal; flash_status() then names it."""
        if clear:
            self.clear()
        with self.node.sdo[od.IDX_PROGRAM_DATA][1].open("wb", size=len(image), block_transfer=block,
                                                        request_crc_support=True, buffering=0) as f:
            for i in range(0, len(image), chunk):
                part = image[i:i + chunk]
                view = memoryview(part)
                while len(view):
                    n = f.write(view)  # raw stream: may take fewer bytes than given
                    view = view[n:] if n else view
                if progress is not None:
                    progress(len(part))

    def activate(self, confirm: bool = True, timeout: float = 5.0) -> None:
        """CiA 302-3 start (0x1F51 = 1): the downloaded model runs on trial; the node answers, sends its boot-up
        and is PRE-OPERATIONAL (put into PRE-OPERATIONAL first: program control is refused otherwise). Then, with
        `confirm`, 0x80 makes it permanent; without, a reset or power cut brings the previous model back."""
        booted = threading.Event()
        cob = 0x700 + self.node_id

        def on_frame(_cob: int, data: bytearray, _ts: float) -> None:
            if len(data) == 1 and data[0] == 0:
                booted.set()

        if self.node.nmt.state != "PRE-OPERATIONAL":
            self.node.nmt.state = "PRE-OPERATIONAL"
            time.sleep(0.02)
        self.network.subscribe(cob, on_frame)
        try:
            self.program_control("start")
            if not booted.wait(timeout):
                raise canopen.SdoCommunicationError(f"no boot-up from node {self.node_id} after 0x1F51 start")
        finally:
            self.network.unsubscribe(cob, on_frame)
        if confirm:
            self.confirm()

    def clear(self) -> None:
        """0x1F51 = 3 (clear), a PRE-OPERATIONAL service: an OPERATIONAL node is set PRE-OPERATIONAL for it and back
        (RPDOs between the two NMT commands are not taken; a master streaming telemetry clears before it starts)."""
        operational = self.node.nmt.state == "OPERATIONAL"
        if operational:
            self.node.nmt.state = "PRE-OPERATIONAL"
            time.sleep(0.02)
        try:
            self.program_control("clear")
        finally:
            if operational:
                self.node.nmt.state = "OPERATIONAL"
                time.sleep(0.02)

    def confirm(self) -> None:
        """0x1F51 = 0x80: the model on trial becomes permanent (nothing to do when none is on trial)."""
        self.program_control("confirm")

    def rollback(self) -> None:
        """0x2002 = 1: back to the previous slot's model (CiA 302-3 has no rollback). A download is dropped by
        clear()."""
        self.node.sdo[ROLLBACK].raw = 1

    # -- CiA 301 store / restore parameters ---------------------------------------------------
    def store_parameters(self) -> None:
        """0x1010 sub 1 = "save": the writable communication parameters (objects.STORED_PARAMS: the heartbeat
        time) are kept in the node's NVM and are in force after every reset and power cycle."""
        self.node.sdo[od.IDX_STORE_PARAMS][1].raw = od.SIGNATURE_SAVE

    def restore_defaults(self) -> None:
        """0x1011 sub 1 = "load": the defaults are in force again after the next reset (until then the values
        stay as they are)."""
        self.node.sdo[od.IDX_RESTORE_PARAMS][1].raw = od.SIGNATURE_LOAD

    def close(self) -> None:
        self.network.disconnect()
