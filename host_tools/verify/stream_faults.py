"""Stream faults: turn a clean stream of samples (or feature vectors) into wire items.

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

import numpy as np

from ..wire.items import WireItem
from ..wire.dbc import CONTROL_RESET, CONTROL_STATUS, Frame, by_id, control_frame, feature_frames, telemetry_frames
from fleetlab.errors import InputError

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
            raise InputError(f"--inject: unknown fault kind {k!r} (choose from {', '.join(KINDS)} or 'all')")
        if k not in allowed:
            where = "the features source" if features_source else f"--link {link}"
            raise InputError(f"--inject: fault {k!r} cannot be carried by {where}")
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
        raise InputError(f"--inject-rate must be in [0, 1], got {rate}")
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
