"""Fault injection: turn a clean stream of samples (or feature vectors) into wire items.

The stream is cut into segments, one per estimator lifetime: a `restart` fault ends a
segment mid-window (the host asks for the status, kills the emulator, starts it again
and resumes at the next window boundary of its own grid). Every segment starts with
CONTROL reset and ends with CONTROL status, so the estimator's counters can be checked
against `compare.EstimatorModel` for each lifetime.

`--inject-rate R` is the probability that a window carries one fault (kind drawn
uniformly from the requested kinds). The first window of a segment and the last window
of the stream stay clean, and faults sit away from window edges, so each fault affects
exactly one window and its effect is attributable.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import can
import numpy as np

from ..wire.items import WireItem
from ..wire.dbc import CONTROL_RESET, CONTROL_STATUS, Frame, by_id, control_frame, feature_frames, telemetry_frames

KINDS = (
    "bad_crc",
    "wrong_length",
    "unknown_id",
    "dropped_sample",
    "reordered_samples",
    "duplicated_frame",
    "restart",
)
# Effect each fault must have on the estimator: (frames_rejected, samples_dropped, window flagged)
EFFECTS: dict[str, tuple[int, int, bool]] = {
    "bad_crc": (1, 1, True),  # the corrupted frame replaces the real one: its sample goes missing
    "wrong_length": (1, 1, True),
    "unknown_id": (1, 0, False),  # an extra frame; the window stays bit-exact
    "dropped_sample": (0, 1, True),
    "reordered_samples": (3, 1, True),  # sample k+1 before k: k's three frames arrive late
    "duplicated_frame": (1, 0, False),
    "restart": (0, 0, False),
}
FEATURE_KINDS = ("bad_crc", "wrong_length", "unknown_id", "duplicated_frame", "restart")
UNKNOWN_ID = 0x7E5  # preferred ID for unknown_id faults (not in the repo's DBC)


def unknown_id() -> int:
    """An 11-bit ID the DBC in use does not define (a rover DBC may have moved a frame to 0x7E5)."""
    known = set(by_id())
    return next(i for i in [UNKNOWN_ID, *range(0x7FF, -1, -1)] if i not in known)

SAMPLES_PER_WINDOW = 100


def parse_kinds(spec: str | None, link: str, features_source: bool = False) -> list[str]:
    """'all' or a comma list -> kinds; kinds that the link/source cannot carry are refused."""
    if not spec:
        return []
    allowed = list(FEATURE_KINDS if features_source else KINDS)
    if link == "inproc":
        allowed.remove("bad_crc")  # a CAN frame on a bus has no byte-level CRC to corrupt
    if spec.strip() == "all":
        return allowed
    kinds = [k.strip() for k in spec.split(",") if k.strip()]
    for k in kinds:
        if k not in KINDS:
            raise ValueError(f"--inject: unknown fault kind {k!r} (choose from {', '.join(KINDS)} or 'all')")
        if k not in allowed:
            where = "the features source" if features_source else f"--link {link}"
            raise ValueError(f"--inject: fault {k!r} cannot be carried by {where}")
    return kinds


@dataclass
class Fault:
    kind: str
    segment: int
    window: int  # window index on the segment's grid
    frames_rejected: int
    samples_dropped: int
    flags_window: bool
    detected: bool = False


@dataclass
class Segment:
    """Wire items sent to one estimator lifetime, and why it ended."""

    items: list[WireItem] = field(default_factory=list)
    ends_with_restart: bool = False
    samples_lost_to_restart: int = 0  # samples of the window cut short (sent or skipped)
    samples_skipped_by_restart: int = 0  # of those, the ones the host never sent
    windows_lost_to_restart: int = 0
    n_source_units: int = 0  # samples (telemetry) or feature vectors sent


@dataclass
class Plan:
    segments: list[Segment]
    faults: list[Fault]

    @property
    def n_frames(self) -> int:
        return sum(len(s.items) for s in self.segments)


def _window_faults(n_windows: int, kinds: list[str], rate: float, rng: np.random.Generator) -> dict[int, str]:
    if not kinds or rate <= 0:
        return {}
    if not 0 <= rate <= 1:
        raise ValueError(f"--inject-rate must be in [0, 1], got {rate}")
    out = {}
    prev_restart = True  # window 0 opens a segment
    for w in range(n_windows - 1):  # the last window stays clean
        if prev_restart:
            prev_restart = False
            continue
        if rng.random() < rate:
            out[w] = kinds[int(rng.integers(len(kinds)))]
            prev_restart = out[w] == "restart"
    return out


FRAME_LEVEL = ("bad_crc", "wrong_length", "unknown_id", "duplicated_frame")


def _with_frame_fault(kind: str, fs, part: int, fidx: int) -> list[WireItem]:
    """The frames `fs` of one sample or feature set as sent with a frame-level fault on frame `part`."""
    items: list[WireItem] = []
    for j, f in enumerate(fs):
        if j != part:
            items.append(WireItem(f))
        elif kind == "bad_crc":
            items.append(WireItem(f, corrupt="bad_crc", fault=fidx))
        elif kind == "wrong_length":
            items.append(WireItem(Frame(f.can_id, f.data[:-1]), fault=fidx))
        elif kind == "unknown_id":  # sent before the genuine frame
            items += [WireItem(Frame(unknown_id(), f.data), fault=fidx), WireItem(f)]
        else:  # duplicated_frame
            items += [WireItem(f), WireItem(f, fault=fidx)]
    return items


def plan_telemetry(
    samples_q: np.ndarray,
    kinds: list[str],
    rate: float,
    seed: int,
    restart_every: int = 0,
    counter_start: int = 0,
) -> Plan:
    """Wire items for int16 samples (n,7), n a multiple of 100 (whole windows)."""
    n = len(samples_q) - len(samples_q) % SAMPLES_PER_WINDOW
    n_win = n // SAMPLES_PER_WINDOW
    rng = np.random.default_rng(seed)
    faults_at = _window_faults(n_win, kinds, rate, rng)
    if restart_every > 0:
        for w in range(restart_every, n_win - 1, restart_every):
            faults_at.setdefault(w, "restart")
    frames = [telemetry_frames(counter_start + i, samples_q[i]) for i in range(n)]
    segments = [Segment()]
    faults: list[Fault] = []
    seg_w0 = 0  # first grid window of the current segment

    def begin(seg: Segment) -> None:
        seg.items.append(WireItem(control_frame(CONTROL_RESET)))

    begin(segments[0])
    for w in range(n_win):
        seg = segments[-1]
        kind = faults_at.get(w)
        base = w * SAMPLES_PER_WINDOW
        fidx = len(faults)
        if kind is not None:
            r, d, fl = EFFECTS[kind]
            faults.append(Fault(kind, len(segments) - 1, w - seg_w0, r, d, fl))
        # the faulty sample sits inside the window, away from its first and last two slots
        k = base + int(rng.integers(2, SAMPLES_PER_WINDOW - 3)) if kind else -1
        part = int(rng.integers(3)) if kind else 0
        stop = base + SAMPLES_PER_WINDOW
        if kind == "restart":
            stop = k
        i = base
        while i < stop:
            fs = frames[i]
            if i != k:
                seg.items.extend(WireItem(f) for f in fs)
            elif kind in FRAME_LEVEL:
                seg.items.extend(_with_frame_fault(kind, fs, part, fidx))
            elif kind == "dropped_sample":
                pass
            elif kind == "reordered_samples":
                seg.items.extend(WireItem(f) for f in frames[i + 1])
                seg.items.extend(WireItem(f, fault=fidx) for f in fs)
                i += 1
            i += 1
        seg.n_source_units += stop - base
        if kind == "restart":
            seg.items.append(WireItem(control_frame(CONTROL_STATUS)))
            seg.ends_with_restart = True
            seg.samples_lost_to_restart = SAMPLES_PER_WINDOW  # the window cut short is never emitted
            seg.samples_skipped_by_restart = base + SAMPLES_PER_WINDOW - k
            seg.windows_lost_to_restart = 1
            segments.append(Segment())
            begin(segments[-1])
            seg_w0 = w + 1
    segments[-1].items.append(WireItem(control_frame(CONTROL_STATUS)))
    return Plan(segments, faults)


def plan_features(
    feat_q: np.ndarray,
    kinds: list[str],
    rate: float,
    seed: int,
    restart_every: int = 0,
) -> Plan:
    """Wire items for int16 feature vectors (N,12): one FEATURES_0..3 set per vector."""
    n_win = len(feat_q)
    rng = np.random.default_rng(seed)
    faults_at = _window_faults(n_win, kinds, rate, rng)
    if restart_every > 0:
        for w in range(restart_every, n_win - 1, restart_every):
            faults_at.setdefault(w, "restart")
    segments = [Segment()]
    segments[0].items.append(WireItem(control_frame(CONTROL_RESET)))
    faults: list[Fault] = []
    wc0 = 0
    for w in range(n_win):
        seg = segments[-1]
        fs = feature_frames(w - wc0, feat_q[w])
        kind = faults_at.get(w)
        fidx = len(faults)
        # a duplicate of the last part would follow a completed set: duplicate parts 0..2 only
        part = int(rng.integers(3 if kind == "duplicated_frame" else 4))
        if kind is None:
            seg.items.extend(WireItem(f) for f in fs)
            seg.n_source_units += 1
            continue
        if kind in FRAME_LEVEL:
            # a corrupted part cannot complete its set: the other three are discarded when the next set starts
            rejected = 4 if kind in ("bad_crc", "wrong_length") else 1
            faults.append(Fault(kind, len(segments) - 1, w - wc0, rejected, 0, False))
            seg.items.extend(_with_frame_fault(kind, fs, part, fidx))
        elif kind == "restart":
            faults.append(Fault(kind, len(segments) - 1, w - wc0, 0, 0, False))
            seg.items.extend(WireItem(f) for f in fs[:2])  # half a set, then the estimator dies
            seg.items.append(WireItem(control_frame(CONTROL_STATUS)))
            seg.ends_with_restart = True
            seg.windows_lost_to_restart = 1
            segments.append(Segment())
            segments[-1].items.append(WireItem(control_frame(CONTROL_RESET)))
            wc0 = w + 1
            continue
        seg.n_source_units += 1
    segments[-1].items.append(WireItem(control_frame(CONTROL_STATUS)))
    return Plan(segments, faults)


# --- model uploads over CANopen (SDO to the DOMAIN 0x2000) ----------------------------------------
#
# Image faults change the bytes the master sends; wire faults change the SDO request frames on
# their way to the node (`SdoFaultBus`). Every kind ends with the old model active (activation is
# a separate, explicit command) and is reported by the node: an SDO abort code, an EMCY and a
# counter, or, where the block protocol repairs the fault itself, the node's count of sequence
# errors and an image that still passes every check.

UPLOAD_IMAGE_FAULTS = ("corrupt_image", "wrong_arch", "truncated", "stale_version")
UPLOAD_WIRE_FAULTS = ("drop_segment", "duplicate_segment", "reorder_segments", "corrupt_segment", "wrong_block_crc",
                      "abort_midway")
UPLOAD_FAULTS = UPLOAD_IMAGE_FAULTS + UPLOAD_WIRE_FAULTS
# only on a node built with an HMAC key (cmake -DSLIPEST_HMAC_KEY_FILE=...): the image is unsigned, or
# signed under another key
UPLOAD_KEYED_FAULTS = ("unsigned_image", "wrong_hmac")


@dataclass(frozen=True)
class UploadEffect:
    fails: bool  # the transfer must fail (else the protocol repairs the fault)
    abort_code: int | None  # SDO abort code the node sends (None: none, e.g. the master aborted)
    emcy: int | None  # EMCY error code the node must send
    counter: tuple[str, str]  # ("store" | "node", counter name) that must grow by one or more


UPLOAD_EFFECTS: dict[str, UploadEffect] = {
    "corrupt_image": UploadEffect(True, 0x08000020, 0x6300, ("store", "refused_crc")),
    "wrong_arch": UploadEffect(True, 0x08000020, 0x6300, ("store", "refused_arch")),
    "truncated": UploadEffect(True, 0x06070010, 0x6300, ("store", "refused_length")),
    "stale_version": UploadEffect(True, 0x08000020, 0x6300, ("store", "refused_version")),
    "unsigned_image": UploadEffect(True, 0x08000020, 0x6300, ("store", "refused_hmac")),
    "wrong_hmac": UploadEffect(True, 0x08000020, 0x6300, ("store", "refused_hmac")),
    # the block protocol repeats what a sequence error lost: counted, and the image arrives intact
    "drop_segment": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "duplicate_segment": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "reorder_segments": UploadEffect(False, None, None, ("node", "block_sequence_errors")),
    "corrupt_segment": UploadEffect(True, 0x05040004, None, ("store", "uploads_aborted")),
    "wrong_block_crc": UploadEffect(True, 0x05040004, None, ("store", "uploads_aborted")),
    # the master sends an abort and falls silent: the node drops the upload and counts the abort
    "abort_midway": UploadEffect(True, None, None, ("node", "sdo_aborts_received")),
}


def faulty_image(kind: str, image: bytes) -> bytes:
    """The image as an image fault leaves it (wire faults: unchanged)."""
    import struct
    import zlib

    if kind == "corrupt_image":  # one payload bit flipped after the CRC was computed
        b = bytearray(image)
        b[100] ^= 0x10
        return bytes(b)
    if kind == "wrong_arch":  # architecture id 2, with a CRC that matches: the arch check must refuse it
        b = bytearray(image)
        struct.pack_into("<H", b, 6, 2)
        body = len(b) - 36 - (32 if struct.unpack_from("<H", b, 12)[0] & 0x0002 else 0)
        struct.pack_into("<I", b, body, zlib.crc32(bytes(b[:body])))
        return bytes(b)
    if kind == "truncated":
        return image[:-50]
    if kind == "wrong_hmac":  # signed, but not under the key the node was provisioned with
        from fleetlab.export.model_image import sign_image

        return sign_image(image, bytes(32))
    return image


class SdoFaultBus(can.BusABC):
    """A python-can bus in front of the master's: SDO requests to `node_id` pass through a fault
    at the `at`-th sub-block segment of a block download (or the end request)."""

    def __init__(self, inner: can.BusABC, node_id: int, kind: str, at: int = 40) -> None:
        if kind not in UPLOAD_WIRE_FAULTS:
            raise ValueError(f"not a wire fault: {kind!r}")
        self.inner, self.kind, self.at = inner, kind, at
        self.cob = 0x600 + node_id
        self.segments = 0
        self.in_block = self.after_last = False
        self.fired = False
        self._held: can.Message | None = None
        self.channel_info = f"faults({kind}) on {getattr(inner, 'channel_info', '?')}"
        super().__init__(channel=None)

    def _recv_internal(self, timeout):
        return self.inner.recv(timeout), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.arbitration_id != self.cob:
            self.inner.send(msg, timeout)
            return
        first = msg.data[0]
        if not self.in_block:
            # only the frames of a block download are touched: other SDO traffic passes
            if (first & 0xE1) == 0xC0:  # block download initiate
                self.in_block, self.after_last = True, False
            self.inner.send(msg, timeout)
            return
        if first == 0x80 or (self.after_last and (first & 0xE3) == 0xC1):  # abort, or the end request
            self.in_block = False
            if self.kind == "abort_midway" and self.fired:
                return  # the master's link is dead
            if self.kind == "wrong_block_crc" and first != 0x80:
                data = bytearray(msg.data)
                data[1] ^= 0xFF  # CRC low byte
                msg = can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False)
                self.fired = True
            self.inner.send(msg, timeout)
            return
        self.after_last = bool(first & 0x80)
        if self.kind == "abort_midway" and self.fired:
            return
        if self.fired or self.kind == "wrong_block_crc":
            self.inner.send(msg, timeout)
            return
        self.segments += 1
        if self._held is not None:  # reorder: the held segment goes after the next one
            self.inner.send(msg, timeout)
            self.inner.send(self._held, timeout)
            self._held, self.fired = None, True
            return
        if self.segments != self.at:
            self.inner.send(msg, timeout)
            return
        if self.kind == "drop_segment":
            self.fired = True
        elif self.kind == "duplicate_segment":
            self.inner.send(msg, timeout)
            self.inner.send(msg, timeout)
            self.fired = True
        elif self.kind == "reorder_segments":
            self._held = msg
        elif self.kind == "corrupt_segment":
            data = bytearray(msg.data)
            data[3] ^= 0x01
            self.inner.send(can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False),
                            timeout)
            self.fired = True
        else:  # abort_midway: an abort instead of the segment, then silence (the master's link died)
            abort = bytearray(8)
            abort[0] = 0x80
            abort[4:8] = (0x08000000).to_bytes(4, "little")
            self.inner.send(can.Message(arbitration_id=msg.arbitration_id, data=bytes(abort), is_extended_id=False),
                            timeout)
            self.fired = True

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()

