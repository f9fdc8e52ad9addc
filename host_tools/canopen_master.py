"""The master side of the slipest CANopen node, on the python `canopen` library.

`SlipestMaster` is a `canopen.Network` with the node added from its EDS: NMT, heartbeat, SDO
reads of identity and model, the model upload (SDO block download of the DOMAIN 0x2000),
activation and rollback, and the estimates decoded from the TPDOs by canopen's own PDO maps.
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

ACTIVE_MODEL, COMMAND, COUNTERS, SLOTS, STORE_COUNTERS, UPLOAD = (
    od.IDX_ACTIVE_MODEL, od.IDX_COMMAND, od.IDX_COUNTERS, od.IDX_SLOTS, od.IDX_STORE_COUNTERS, od.IDX_UPLOAD)

# SDO abort codes (CiA 301) by meaning, as the node sends them (canopen_od/objects.py is their one source)
ABORT_NAMES = {code: doc for _, code, doc in od.ABORT_CODES}


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

    def upload_status(self) -> dict[str, int]:
        rec = self.node.sdo[UPLOAD]
        return {"state": rec[1].raw, "last_store_status": rec[2].raw, "bytes_received": rec[3].raw}

    # -- model update ---------------------------------------------------------------------
    def upload(self, image: bytes, block: bool = True, progress: Callable[[int], None] | None = None,
               chunk: int = 7 * 127) -> None:
        """Write `image` into the DOMAIN 0x2000 (the inactive slot): SDO block download with CRC
        (or segmented). Raises canopen.SdoAbortedError with the node's abort code on a refusal."""
        with self.node.sdo[od.IDX_MODEL_IMAGE].open("wb", size=len(image), block_transfer=block,
                                                    request_crc_support=True, buffering=0) as f:
            for i in range(0, len(image), chunk):
                part = image[i:i + chunk]
                view = memoryview(part)
                while len(view):
                    n = f.write(view)  # raw stream: may take fewer bytes than given
                    view = view[n:] if n else view
                if progress is not None:
                    progress(len(part))

    def activate(self) -> None:
        self.node.sdo[COMMAND][1].raw = 1

    def rollback(self) -> None:
        self.node.sdo[COMMAND][2].raw = 1

    def abort_upload(self) -> None:
        self.node.sdo[COMMAND][3].raw = 1

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
