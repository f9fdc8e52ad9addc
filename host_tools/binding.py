"""The C estimator library (libslipest_host.so) through ctypes: one `slipest_node_t` per
`CEstimator`. Sizes (context, frame, output capacity) are read from the library, never copied."""

from __future__ import annotations

import ctypes
from pathlib import Path

from fleetlab.canopen_od import objects as od

from .wire.dbc import Frame


class CFrame(ctypes.Structure):
    _fields_ = [("id", ctypes.c_uint32), ("dlc", ctypes.c_uint8), ("data", ctypes.c_uint8 * 8)]


class CCounters(ctypes.Structure):
    _fields_ = [(n, ctypes.c_uint32) for n in od.ESTIMATOR_COUNTERS]  # slipest_counters_t


class CEstimator:
    """One estimator node (`slipest_node_t`) from libslipest_host.so."""

    def __init__(self, lib_path: Path | str) -> None:
        lib = ctypes.CDLL(str(lib_path))
        lib.slipest_node_size.restype = ctypes.c_size_t
        lib.slipest_frame_size.restype = ctypes.c_size_t
        # the node runs the model the library was built with (its bundle): pointers to const structs
        lib.slipest_bundle_model_q.restype = ctypes.c_void_p
        lib.slipest_bundle_model_f32.restype = ctypes.c_void_p
        lib.slipest_node_init.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        lib.slipest_node_model_q.argtypes = [ctypes.c_void_p]
        lib.slipest_node_model_q.restype = ctypes.c_void_p
        lib.slipest_model_hash32.argtypes = [ctypes.c_void_p]
        lib.slipest_node_handle.argtypes = [ctypes.c_void_p, ctypes.POINTER(CFrame), ctypes.POINTER(CFrame),
                                            ctypes.c_size_t]
        lib.slipest_node_link_error.argtypes = [ctypes.c_void_p]
        lib.slipest_node_counters.argtypes = [ctypes.c_void_p, ctypes.POINTER(CCounters)]
        lib.slipest_model_hash32.restype = ctypes.c_uint32
        lib.slipest_node_max_out.restype = ctypes.c_size_t
        if lib.slipest_frame_size() != ctypes.sizeof(CFrame):
            raise OSError(f"{lib_path}: slipest_frame_t is {lib.slipest_frame_size()} bytes, ctypes expects "
                          f"{ctypes.sizeof(CFrame)}")
        self.lib = lib
        self._ctx = ctypes.create_string_buffer(lib.slipest_node_size())
        self._in = CFrame()
        self.max_out = int(lib.slipest_node_max_out())  # SLIPEST_NODE_MAX_OUT, from the library itself
        self._out = (CFrame * self.max_out)()
        self.reset()

    def reset(self) -> None:
        """A fresh node, as after a power cycle."""
        r = self.lib.slipest_node_init(self._ctx, self.lib.slipest_bundle_model_q(), self.lib.slipest_bundle_model_f32())
        if r < 0:
            raise OSError(f"slipest_node_init failed ({r})")

    def handle(self, frame: Frame) -> list[Frame]:
        self._in.id = frame.can_id
        self._in.dlc = len(frame.data)
        ctypes.memmove(self._in.data, frame.data, len(frame.data))
        n = self.lib.slipest_node_handle(self._ctx, ctypes.byref(self._in), self._out, self.max_out)
        if n <= 0:
            return []  # rejected frames are counted by the node itself
        return [Frame(o.id, bytes(o.data[: o.dlc])) for o in self._out[:n]]

    def link_error(self) -> None:
        self.lib.slipest_node_link_error(self._ctx)

    def counters(self) -> dict[str, int]:
        c = CCounters()
        self.lib.slipest_node_counters(self._ctx, ctypes.byref(c))
        return {n: getattr(c, n) for n, _ in CCounters._fields_}

    @property
    def model_hash32(self) -> int:
        return int(self.lib.slipest_model_hash32(self.lib.slipest_node_model_q(self._ctx)))
