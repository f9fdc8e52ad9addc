"""The CAN interface from `slipest.dbc`: cantools database plus fast typed codecs.

The DBC is the single source of truth. cantools parses it; because every signal
in it is byte-aligned little-endian, each message maps onto a `struct` layout,
which we derive from the cantools signal list at load time (and check against
cantools in the tests). That keeps 100k+ frames/s encodable in pure Python.

A rover may use its own CAN IDs: point `$FLEETLAB_DBC` (or `--dbc FILE` of
`fleetlab emulate|stream|monitor`) at a copy of the DBC with other frame IDs. Such a
DBC must keep every message name, length and signal layout of the repo's DBC
(`check_layout`, in `dbc/layout.py`); the C build takes the same file as `-DSLIPEST_DBC=...` and runs
that check as a script to refuse an incompatible one (docs/can_interface.md).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cantools
import numpy as np

from fleetlab.dbc import DBC_PATH, check_layout
from fleetlab.dbc import load as _load
from fleetlab.errors import InputError

DBC_ENV = "FLEETLAB_DBC"  # environment variable naming another DBC (other CAN IDs, same layout)

# Frame names used by the host tools (IDs come from the DBC).
TELEM_NAMES = ("TELEM_WHEEL", "TELEM_IMU", "TELEM_ATTITUDE")
FEATURE_FRAME_NAMES = ("FEATURES_0", "FEATURES_1", "FEATURES_2", "FEATURES_3")
CONTROL_RESET = 1
CONTROL_STATUS = 2


@dataclass(frozen=True, slots=True)
class Frame:
    """One classic CAN frame as carried by every link (11-bit ID, 0..8 data bytes)."""

    can_id: int
    data: bytes

    def __post_init__(self) -> None:
        if not 0 <= self.can_id <= 0x7FF:
            raise InputError(f"CAN ID 0x{self.can_id:X} is not an 11-bit identifier")
        if len(self.data) > 8:
            raise InputError(f"frame 0x{self.can_id:03X}: {len(self.data)} data bytes (classic CAN allows 8)")


@dataclass(frozen=True)
class MessageCodec:
    """struct layout of one DBC message, derived from its cantools signals."""

    name: str
    frame_id: int
    length: int
    signals: tuple[str, ...]
    fmt: struct.Struct

    def encode(self, *values: int) -> Frame:
        try:
            return Frame(self.frame_id, self.fmt.pack(*values))
        except struct.error as e:
            raise InputError(f"{self.name}: cannot encode {dict(zip(self.signals, values))}: {e}") from None

    def decode(self, data: bytes) -> tuple[int, ...]:
        if len(data) != self.length:
            raise InputError(f"{self.name} (0x{self.frame_id:03X}): {len(data)} data bytes, DBC says {self.length}")
        return self.fmt.unpack(data)

    def decode_dict(self, data: bytes) -> dict[str, int]:
        return dict(zip(self.signals, self.decode(data)))


_STRUCT_CODES = {(8, False): "B", (8, True): "b", (16, False): "H", (16, True): "h", (32, False): "I", (32, True): "i"}


def _codec_of(msg: cantools.database.can.Message, source: str) -> MessageCodec:
    fmt, pos, names = "<", 0, []
    for sig in sorted(msg.signals, key=lambda s: s.start):
        if sig.byte_order != "little_endian" or sig.start % 8 or (sig.length, sig.is_signed) not in _STRUCT_CODES:
            raise InputError(f"{source}: {msg.name}.{sig.name} is not a byte-aligned little-endian integer")
        if sig.start < pos:
            raise InputError(f"{source}: {msg.name}.{sig.name} overlaps another signal")
        fmt += "x" * ((sig.start - pos) // 8) + _STRUCT_CODES[(sig.length, sig.is_signed)]
        pos = sig.start + sig.length
        names.append(sig.name)
    fmt += "x" * (msg.length - pos // 8)
    return MessageCodec(msg.name, msg.frame_id, msg.length, tuple(names), struct.Struct(fmt))


# --- which DBC: the repo's, $FLEETLAB_DBC, or one chosen with use_dbc() --------------------

_active: Path | None = None  # resolved on first use (hot paths must not re-read the environment)


def dbc_path() -> Path:
    """The DBC in use: the one given to `use_dbc`, else `$FLEETLAB_DBC`, else the repo's."""
    global _active
    if _active is None:
        env = os.environ.get(DBC_ENV, "").strip()
        _active = _checked(Path(env)) if env else DBC_PATH
    return _active


def use_dbc(path: Path | str | None) -> Path:
    """Use `path` in this process and in the processes it starts (`$FLEETLAB_DBC` is set too);
    None: back to the repo's DBC (`$FLEETLAB_DBC` is cleared)."""
    global _active
    if path is None:
        os.environ.pop(DBC_ENV, None)
        _active = None
        return dbc_path()
    _active = _checked(Path(path))
    os.environ[DBC_ENV] = str(_active)
    return _active


def _checked(path: Path) -> Path:
    path = path.expanduser().resolve()
    if not path.is_file():
        raise OSError(f"{path}: no such DBC file (--dbc / ${DBC_ENV})")
    if path != DBC_PATH.resolve():
        try:
            check_layout(_load(path), path.name)
        except ValueError as e:
            # dbc/ imports nothing of fleetlab (CMake runs it bare), so its refusals are plain ValueErrors: a
            # rover's DBC that cannot be read or breaks the layout is the user's input
            raise InputError(str(e)) from None
    return path


def database() -> cantools.database.can.Database:
    return _load(dbc_path())


@lru_cache(maxsize=4)
def _codecs_for(path: Path) -> dict[str, MessageCodec]:
    return {m.name: _codec_of(m, path.name) for m in _load(path).messages}


@lru_cache(maxsize=4)
def _by_id_for(path: Path) -> dict[int, MessageCodec]:
    return {c.frame_id: c for c in _codecs_for(path).values()}


def codecs() -> dict[str, MessageCodec]:
    """Codec of every DBC message, by name."""
    return _codecs_for(dbc_path())


def codec(name: str) -> MessageCodec:
    return codecs()[name]


def by_id() -> dict[int, MessageCodec]:
    return _by_id_for(dbc_path())


def frame_id(name: str) -> int:
    return codec(name).frame_id


def dbc_length(can_id: int) -> int | None:
    """DBC data length of a known ID, None for an ID the DBC does not define."""
    c = by_id().get(can_id)
    return None if c is None else c.length


# --- host -> estimator -------------------------------------------------------------------


def telemetry_frames(counter: int, raw: np.ndarray | tuple[int, ...]) -> tuple[Frame, Frame, Frame]:
    """The three TELEM_* frames of one sample (raw int16 values in RAW_CHANNELS order)."""
    w, c, ax, ay, az, roll, pitch = (int(v) for v in raw)
    counter &= 0xFFFF
    cs = codecs()
    return (
        cs["TELEM_WHEEL"].encode(counter, w, c),
        cs["TELEM_IMU"].encode(counter, ax, ay, az),
        cs["TELEM_ATTITUDE"].encode(counter, roll, pitch),
    )


def feature_frames(window_counter: int, feat_q: np.ndarray | tuple[int, ...]) -> tuple[Frame, Frame, Frame, Frame]:
    """FEATURES_0..3 of one int16 feature vector (FEATURE_NAMES order, raw LSB units)."""
    f = [int(v) for v in feat_q]
    if len(f) != 12:
        raise InputError(f"a feature vector has 12 values, got {len(f)}")
    wc = window_counter & 0xFFFF
    cs = codecs()
    return tuple(cs[name].encode(wc, *f[3 * i : 3 * i + 3]) for i, name in enumerate(FEATURE_FRAME_NAMES))  # type: ignore[return-value]


def control_frame(command: int, argument: int = 0) -> Frame:
    return codec("CONTROL").encode(command, argument)


# --- estimator -> host -------------------------------------------------------------------


@dataclass
class WindowEstimate:
    """One window as reported by the estimator (SLIP_ESTIMATE + both logits frames)."""

    window_counter: int
    slip_class: int
    slip_class_f32: int
    flags: int
    n_samples: int
    saturations: int
    logits: tuple[int, int, int] | None = None
    t_recv: float = 0.0


@dataclass
class StatusReport:
    model_hash: int
    lib_version: int
    windows_done: int
    frames_received: int
    frames_rejected: int
    samples_dropped: int
    windows_flagged: int


class OutputAssembler:
    """Turns the estimator's output frames into WindowEstimate / StatusReport objects.

    Problems (a logits frame without its estimate, a window counter that does not
    match, a wrong length or an unknown ID) are counted in `errors`, never dropped silently.
    """

    def __init__(self) -> None:
        cs = codecs()
        self._est, self._l01, self._l2 = cs["SLIP_ESTIMATE"], cs["SLIP_LOGITS_01"], cs["SLIP_LOGITS_2"]
        self._sm, self._srx, self._sloss = cs["STATUS_MODEL"], cs["STATUS_RX"], cs["STATUS_LOSS"]
        self._pending: WindowEstimate | None = None
        self._l01_vals: tuple[int, int] | None = None
        self._status: dict[str, int] = {}
        self.errors: list[str] = []

    def feed(self, frame: Frame, t: float = 0.0) -> WindowEstimate | StatusReport | None:
        cid, data = frame.can_id, frame.data
        known = by_id().get(cid)
        if known is None or known.name not in ("SLIP_ESTIMATE", "SLIP_LOGITS_01", "SLIP_LOGITS_2",
                                                "STATUS_MODEL", "STATUS_RX", "STATUS_LOSS"):
            self.errors.append(f"unexpected frame 0x{cid:03X} from the estimator")
            return None
        if len(data) != known.length:
            self.errors.append(f"{known.name}: {len(data)} bytes, DBC says {known.length}")
            return None
        if cid == self._est.frame_id:
            if self._pending is not None:
                self.errors.append(f"SLIP_ESTIMATE window {self._pending.window_counter} without its logits")
            wc, cls, cls32, flags, n, sat = self._est.decode(data)
            self._pending, self._l01_vals = WindowEstimate(wc, cls, cls32, flags, n, sat, t_recv=t), None
        elif cid == self._l01.frame_id:
            if self._pending is None:
                self.errors.append("SLIP_LOGITS_01 without a SLIP_ESTIMATE")
            else:
                self._l01_vals = self._l01.decode(data)
        elif cid == self._l2.frame_id:
            l2, wc = self._l2.decode(data)
            est, l01 = self._pending, self._l01_vals
            self._pending, self._l01_vals = None, None
            if est is None or l01 is None:
                self.errors.append(f"SLIP_LOGITS_2 window {wc} without its estimate/logits 0-1")
            elif wc != est.window_counter:
                self.errors.append(f"SLIP_LOGITS_2 window {wc} follows SLIP_ESTIMATE window {est.window_counter}")
            else:
                est.logits = (l01[0], l01[1], l2)
                return est
        elif cid == self._sm.frame_id:
            self._status = dict(self._sm.decode_dict(data))
        elif cid == self._srx.frame_id:
            self._status.update(self._srx.decode_dict(data))
        elif cid == self._sloss.frame_id:
            self._status.update(self._sloss.decode_dict(data))
            needed = ("model_hash", "frames_received")
            if not all(k in self._status for k in needed):
                self.errors.append("STATUS_LOSS without STATUS_MODEL/STATUS_RX before it")
                self._status = {}
                return None
            report = StatusReport(**self._status)
            self._status = {}
            return report
        return None
