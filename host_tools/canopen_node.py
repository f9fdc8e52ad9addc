"""The C CANopen node (slipest_co_t, libslipest_host.so) through ctypes, and its bridge onto a
python-can bus, so that python `canopen` can be the master of the real C node in this process.

`RamNvm` is an integrator NVM interface (slipest_nvm_t) backed by a bytearray: the model store
(slipest_store_t, A/B slots) runs on it exactly as on a rover's flash.
"""

from __future__ import annotations

import ctypes
import threading
import time
from pathlib import Path

import can

from .wire.dbc import Frame
from .binding import CFrame
from .status_codes import status
from fleetlab.errors import InputError

# slipest_nvm_t callbacks
_READ = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint32, ctypes.POINTER(ctypes.c_uint8), ctypes.c_uint32)
_WRITE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint32, ctypes.POINTER(ctypes.c_uint8),
                          ctypes.c_uint32)
_ERASE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint32)


class CNvm(ctypes.Structure):
    _fields_ = [("read", _READ), ("write", _WRITE), ("erase", _ERASE), ("sector_size", ctypes.c_uint32),
                ("n_sectors", ctypes.c_uint32), ("ctx", ctypes.c_void_p)]


def nvm_sectors(lib_path: Path | str, sector_size: int = 256) -> int:
    """Sectors the model store needs on an NVM of `sector_size`-byte sectors (two record sectors and two
    slots), read from the C library (slipest_store_nvm_sectors(), i.e. SLIPEST_STORE_NVM_SECTORS) so that
    the formula has one source. ValueError for a sector size the store does not accept."""
    f = ctypes.CDLL(str(lib_path)).slipest_store_nvm_sectors
    f.restype, f.argtypes = ctypes.c_uint32, [ctypes.c_uint32]
    n = int(f(sector_size))
    if n == 0:
        raise InputError(f"sector size {sector_size}: the model store does not accept it "
                         "(SLIPEST_STORE_SECTOR_MIN..SLIPEST_STORE_SECTOR_MAX in slipest_store.h)")
    return n


def store_image_max(lib_path: Path | str) -> int:
    """The largest model image the library's store (and so its CANopen DOMAIN and serial upload) accepts:
    SLIPEST_STORE_IMAGE_MAX of that build, read through slipest_store_image_max()."""
    f = ctypes.CDLL(str(lib_path)).slipest_store_image_max
    f.restype, f.argtypes = ctypes.c_uint32, []
    return int(f())


class RamNvm:
    """An NVM area in RAM (erased to 0xFF), with counts of the store's writes and erases. Strict as flash
    and as the C ram_nvm (firmware_c/common/ram_nvm.c): a write must be one whole, aligned, in-range
    sector that is erased; an erase one aligned, in-range sector. Anything else is refused (SLIPEST_E_NVM)."""

    def __init__(self, n_sectors: int, sector_size: int = 256) -> None:
        """`n_sectors`: the area's size, `nvm_sectors(lib)` for exactly what the store needs."""
        self.sector_size = sector_size
        self.n_sectors = n_sectors
        self.mem = bytearray(b"\xff" * (self.sector_size * self.n_sectors))
        self.writes = self.erases = 0
        # keep the ctypes callbacks alive as long as the interface
        self._cbs = (_READ(self._read), _WRITE(self._write), _ERASE(self._erase))
        self.struct = CNvm(*self._cbs, self.sector_size, self.n_sectors, None)

    def _read(self, _ctx, addr, buf, n):
        if addr + n > len(self.mem):
            return status()["SLIPEST_E_NVM"]
        ctypes.memmove(buf, bytes(self.mem[addr:addr + n]), n)
        return status()["SLIPEST_OK"]

    def _write(self, _ctx, addr, buf, n):
        if addr % self.sector_size or n != self.sector_size or addr + n > len(self.mem):
            return status()["SLIPEST_E_NVM"]
        if self.mem[addr:addr + n].count(0xFF) != n:  # programming flash only clears bits: erase first
            return status()["SLIPEST_E_NVM"]
        self.mem[addr:addr + n] = ctypes.string_at(buf, n)
        self.writes += 1
        return status()["SLIPEST_OK"]

    def _erase(self, _ctx, addr):
        if addr % self.sector_size or addr >= len(self.mem):
            return status()["SLIPEST_E_NVM"]
        self.mem[addr:addr + self.sector_size] = b"\xff" * self.sector_size
        self.erases += 1
        return status()["SLIPEST_OK"]


def now_ms() -> int:
    """The node's millisecond tick (the library reads no clock: the caller supplies it)."""
    return int(time.monotonic() * 1000) & 0xFFFFFFFF


class CCanopenNode:
    """One CANopen node (slipest_co_t) with its model store on a RamNvm."""

    def __init__(self, lib_path: Path | str, node_id: int = 5, serial: int = 1, nvm: RamNvm | None = None,
                 builtin: bool = True) -> None:
        """`builtin`: the node gets the library's built-in model (as the emulator); False: none, as a flight image
        that links no model (it then runs the store's active slot, or no model at all)."""
        lib = ctypes.CDLL(str(lib_path))
        vp, fp = ctypes.c_void_p, ctypes.POINTER(CFrame)
        for name, res, args in (
            ("slipest_co_size", ctypes.c_size_t, []),
            ("slipest_co_store_size", ctypes.c_size_t, []),
            ("slipest_bundle_model_q", vp, []),
            ("slipest_bundle_model_f32", vp, []),
            ("slipest_bundle_sha256", vp, []),
            ("slipest_co_set_builtin_sha256", None, [vp, vp]),
            ("slipest_store_open", ctypes.c_int, [vp, ctypes.POINTER(CNvm), vp]),
            ("slipest_co_init", ctypes.c_int, [vp, ctypes.c_uint8, ctypes.c_uint32, vp, vp, vp, ctypes.c_uint32, fp,
                                               ctypes.c_size_t]),
            ("slipest_co_handle", ctypes.c_int, [vp, fp, ctypes.c_uint32, fp, ctypes.c_size_t]),
            ("slipest_co_tick", ctypes.c_int, [vp, ctypes.c_uint32, fp, ctypes.c_size_t]),
            ("slipest_co_counter", ctypes.c_uint32, [vp, ctypes.c_uint]),
            ("slipest_co_nmt_state", ctypes.c_uint8, [vp]),
            ("slipest_co_max_out", ctypes.c_size_t, []),
        ):
            f = getattr(lib, name)
            f.restype, f.argtypes = res, args
        self.lib, self.node_id, self.serial, self.builtin = lib, node_id, serial, builtin
        self.nvm = nvm
        self.max_out = int(lib.slipest_co_max_out())
        self._out = (CFrame * self.max_out)()
        self._in = CFrame()
        self.lock = threading.Lock()  # the node is one context: one caller at a time
        self.boot()

    def boot(self) -> list[Frame]:
        """Power-on: open the store on the NVM (its active slot, if any) and start the node;
        returns the boot-up frame."""
        with self.lock:
            self._co = ctypes.create_string_buffer(self.lib.slipest_co_size())
            self._store = None
            if self.nvm is not None:
                self._store = ctypes.create_string_buffer(self.lib.slipest_co_store_size())
                st = self.lib.slipest_store_open(self._store, ctypes.byref(self.nvm.struct), None)
                if st not in (status()["SLIPEST_OK"], status()["SLIPEST_E_STATE"], status()["SLIPEST_E_NVM"]):
                    raise OSError(f"slipest_store_open failed ({st})")
            mq, mf = ((self.lib.slipest_bundle_model_q(), self.lib.slipest_bundle_model_f32()) if self.builtin
                      else (None, None))
            n = self.lib.slipest_co_init(self._co, self.node_id, self.serial, self._store, mq, mf, now_ms(),
                                         self._out, self.max_out)
            if n < 0:
                raise OSError(f"slipest_co_init failed ({n})")
            # the built-in model's sha256, known at build time (0x2001 sub 3 while it runs)
            if self.builtin:
                self.lib.slipest_co_set_builtin_sha256(self._co, self.lib.slipest_bundle_sha256())
            return self._frames(n)

    def _frames(self, n: int) -> list[Frame]:
        return [Frame(o.id, bytes(o.data[: o.dlc])) for o in self._out[:max(n, 0)]]

    def handle(self, frame: Frame, t_ms: int | None = None) -> list[Frame]:
        with self.lock:
            self._in.id = frame.can_id
            self._in.dlc = len(frame.data)
            ctypes.memmove(self._in.data, frame.data, len(frame.data))
            n = self.lib.slipest_co_handle(self._co, ctypes.byref(self._in), now_ms() if t_ms is None else t_ms,
                                           self._out, self.max_out)
            return self._frames(n)

    def tick(self, t_ms: int | None = None) -> list[Frame]:
        with self.lock:
            n = self.lib.slipest_co_tick(self._co, now_ms() if t_ms is None else t_ms, self._out, self.max_out)
            return self._frames(n)

    def counter(self, number: int) -> int:
        with self.lock:
            return int(self.lib.slipest_co_counter(self._co, number))

    @property
    def nmt_state(self) -> int:
        with self.lock:
            return int(self.lib.slipest_co_nmt_state(self._co))


class CanopenBridge:
    """Runs a CCanopenNode on a python-can bus: every frame in, its answers out, plus the tick
    (heartbeat, SDO timeout) every few milliseconds. `frames_in` counts frames taken off the bus."""

    TICK_S = 0.002

    def __init__(self, node: CCanopenNode, bus: can.BusABC, boot_frames: list[Frame] | None = None) -> None:
        self.node, self.bus = node, bus
        self.frames_in = 0
        self._stop = threading.Event()
        for f in boot_frames or []:
            self._send(f)
        self.thread = threading.Thread(target=self._run, name="slipest-canopen", daemon=True)
        self.thread.start()

    def _send(self, f: Frame) -> None:
        self.bus.send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False))

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=self.TICK_S)
            if msg is not None and not (msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id):
                self.frames_in += 1
                for f in self.node.handle(Frame(msg.arbitration_id, bytes(msg.data))):
                    self._send(f)
            for f in self.node.tick():
                self._send(f)

    def power_cycle(self) -> None:
        """Restart the node as after a power loss (the NVM keeps its bytes)."""
        for f in self.node.boot():
            self._send(f)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=2)
        self.bus.shutdown()
