"""What the estimator must answer, and the bit-for-bit comparison of what it did answer.

`EstimatorModel` replays the estimator behaviour rules (docs/firmware.md, the shared
brief) on the exact sequence of wire items the host sent: frame validity, sample
assembly from the three TELEM_* frames, FEATURES sets, CONTROL commands. It predicts
the status counters and, through `fleetlab.data.features_int.featurise_int`, every
window's integer features; the expected logits come from the torch integer reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from fleetlab.data import features_int as fi
from fleetlab.export.intref import argmax_lowest

from ..wire.dbc import (
    CONTROL_RESET,
    CONTROL_STATUS,
    FEATURE_FRAME_NAMES,
    TELEM_NAMES,
    Frame,
    StatusReport,
    WindowEstimate,
    codec,
    dbc_length,
    frame_id,
)
from ..wire.items import WireItem


@dataclass
class ExpectedWindow:
    window_index: int  # on the segment's grid (telemetry) or the FEATURES window_counter
    feat_q: np.ndarray  # int16 (12,)
    feat_f: np.ndarray | None  # float features the C float path sees (physical units)
    n_samples: int
    flags: int
    saturations: int
    trigger_item: int  # index of the wire item after which the estimator emits this window

    @property
    def window_counter(self) -> int:
        return self.window_index & 0xFFFF


@dataclass
class Counters:
    frames_received: int = 0
    frames_rejected: int = 0
    samples_dropped: int = 0
    windows_flagged: int = 0
    windows_done: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)




def _delta16(a: int, b: int) -> int:
    """Signed 16-bit difference a - b in -32768..32767."""
    d = (a - b) & 0xFFFF
    return d - 0x10000 if d >= 0x8000 else d


class EstimatorModel:
    """Host-side replay of the estimator rules for one estimator lifetime (a segment).

    Feed every wire item in send order with `feed(item, index)`; `status_snapshot()`
    gives the counters the estimator must report at that point (CONTROL 2), and
    `windows()` the windows it must emit.
    """

    def __init__(self) -> None:
        # input IDs of the DBC in use (read here, not at import: `--dbc` may select another DBC)
        self._telem_ids = {frame_id(n): i for i, n in enumerate(TELEM_NAMES)}
        self._feat_ids = {frame_id(n): i for i, n in enumerate(FEATURE_FRAME_NAMES)}
        self._input_ids = set(self._telem_ids) | set(self._feat_ids) | {frame_id("CONTROL")}
        self.counters = Counters()
        self.rejected_by_reason: dict[str, int] = {}
        self._cur_counter: int | None = None
        self._cur_parts: dict[int, tuple[int, ...]] = {}
        self._samples: list[tuple[int, ...]] = []  # completed samples (raw int16 x7)
        self._sample_counters: list[int] = []
        self._sample_item: list[int] = []  # wire index that completed each sample
        self._feat_wc: int | None = None
        self._feat_parts: dict[int, tuple[int, int, int]] = {}
        self._feat_windows: list[ExpectedWindow] = []
        self._tele_cache: tuple[int, fi.IntWindows, list[ExpectedWindow]] | None = None
        # grids closed by CONTROL reset: the estimator keeps its counters across them
        self._done_epochs: list[tuple[fi.IntWindows, list[ExpectedWindow]]] = []

    # -- frame rules ------------------------------------------------------------------------
    def _reject(self, reason: str) -> None:
        self.counters.frames_rejected += 1
        self.rejected_by_reason[reason] = self.rejected_by_reason.get(reason, 0) + 1

    def feed(self, item: WireItem, index: int) -> None:
        self.counters.frames_received += 1
        if item.corrupt is not None:
            self._reject(item.corrupt)
            return
        f = item.frame
        if f.can_id not in self._input_ids:
            self._reject("unknown_id")
            return
        if len(f.data) != dbc_length(f.can_id):
            self._reject("wrong_length")
            return
        if f.can_id in self._telem_ids:
            self._telemetry(self._telem_ids[f.can_id], f, index)
        elif f.can_id in self._feat_ids:
            self._features(self._feat_ids[f.can_id], f, index)
        else:
            command, _arg = codec("CONTROL").decode(f.data)
            if command == CONTROL_RESET:
                self._reset()
            elif command != CONTROL_STATUS:
                self._reject("bad_command")

    def _reset(self) -> None:
        """CONTROL 1: new grid at the next sample; assembly and FEATURES set cleared, counters kept.
        An open window is discarded (it was never emitted)."""
        if self._samples:
            self._done_epochs.append(self._telemetry_windows())
        self._samples, self._sample_counters, self._sample_item = [], [], []
        self._tele_cache = None
        self._cur_counter, self._cur_parts = None, {}
        self._feat_wc, self._feat_parts = None, {}

    def _telemetry(self, part: int, f: Frame, index: int) -> None:
        values = codec(TELEM_NAMES[part]).decode(f.data)
        counter = values[0]
        if self._cur_counter is not None:
            d = _delta16(counter, self._cur_counter)
            if d < 0:
                self._reject("late")
                return
            if d == 0:
                if part in self._cur_parts:
                    self._reject("duplicate")
                    return
            else:
                self._cur_parts = {}  # an incomplete sample is abandoned: its slot goes missing
        self._cur_counter = counter
        self._cur_parts[part] = values[1:]
        if len(self._cur_parts) == 3:
            p = self._cur_parts
            self._samples.append(p[0] + p[1] + p[2])
            self._sample_counters.append(counter)
            self._sample_item.append(index)
            # the parts stay: any further frame of this counter is a duplicate

    def _features(self, part: int, f: Frame, index: int) -> None:
        wc, *vals = codec(FEATURE_FRAME_NAMES[part]).decode(f.data)
        if self._feat_wc is not None and wc != self._feat_wc:
            for _ in self._feat_parts:
                self._reject("features_incomplete")
            self._feat_parts = {}
        elif part in self._feat_parts:
            self._reject("duplicate")
            return
        self._feat_wc = wc
        self._feat_parts[part] = tuple(vals)  # type: ignore[assignment]
        if len(self._feat_parts) == 4:
            q = np.array(sum((self._feat_parts[i] for i in range(4)), ()), dtype=np.int16)
            self._feat_windows.append(
                ExpectedWindow(wc, q, q * fi.FEATURE_LSB, 0, fi.FLAG_FEATURES_INPUT, 0, index)
            )
            self._feat_wc, self._feat_parts = None, {}

    # -- predictions ------------------------------------------------------------------------
    def _telemetry_windows(self) -> tuple[fi.IntWindows, list[ExpectedWindow]]:
        n = len(self._samples)
        if self._tele_cache is not None and self._tele_cache[0] == n:
            return self._tele_cache[1], self._tele_cache[2]
        samples = np.array(self._samples, dtype=np.int64).reshape(n, 7)
        counters = np.array(self._sample_counters, dtype=np.int64)
        iw = fi.featurise_int(samples, counters)
        out: list[ExpectedWindow] = []
        if n:
            _, slots = fi._unwrap(counters)  # every completed sample is ahead of the previous one
            spw = fi.SAMPLES_PER_WINDOW
            win = slots // spw
            sums = np.zeros((len(iw.window_index), 7), np.int64)
            sumsq = np.zeros_like(sums)
            pos = {int(w): i for i, w in enumerate(iw.window_index)}
            trig: dict[int, int] = {}
            for k in range(n):
                w = int(win[k])
                if w in pos:
                    sums[pos[w]] += samples[k]
                    sumsq[pos[w]] += samples[k] * samples[k]
                # window w is emitted when its last slot fills, or when a later window's sample arrives
                if slots[k] % spw == spw - 1:
                    trig.setdefault(w, self._sample_item[k])
                for earlier in range(int(win[k - 1]) if k else w, w):
                    trig.setdefault(earlier, self._sample_item[k])
            ok = iw.n_samples > 0
            feat_f = np.zeros((len(iw.window_index), 12))
            if ok.any():
                feat_f[ok] = fi.features_float_from_int_sums(sums[ok], sumsq[ok], iw.n_samples[ok])
            for i, w in enumerate(iw.window_index):
                out.append(
                    ExpectedWindow(int(w), iw.features[i], feat_f[i], int(iw.n_samples[i]), int(iw.flags[i]),
                                   int(iw.saturations[i]), trig.get(int(w), -1))
                )
        self._tele_cache = (n, iw, out)
        return iw, out

    def _all_epochs(self) -> list[tuple[fi.IntWindows, list[ExpectedWindow]]]:
        return self._done_epochs + [self._telemetry_windows()]

    def windows(self) -> list[ExpectedWindow]:
        """Every window the estimator must have emitted so far, in emission order."""
        tele = [w for _, ws in self._all_epochs() for w in ws]
        return sorted(tele + self._feat_windows, key=lambda w: w.trigger_item)

    def status_snapshot(self) -> Counters:
        epochs = self._all_epochs()
        c = Counters(**self.counters.as_dict())
        c.samples_dropped = sum(iw.samples_dropped for iw, _ in epochs)
        c.windows_flagged = sum(iw.windows_flagged for iw, _ in epochs)
        c.windows_done = sum(len(ws) for _, ws in epochs) + len(self._feat_windows)
        return c


# --- comparison ------------------------------------------------------------------------------


@dataclass
class WindowVerdict:
    expected: ExpectedWindow
    got: WindowEstimate | None
    ref_logits: np.ndarray | None  # torch integer reference, int64 (3,)
    ref_saturations: int = 0  # features + network saturation events the estimator must report
    problems: list[str] = field(default_factory=list)

    @property
    def bit_exact(self) -> bool:
        return self.got is not None and not self.problems


def argmax_low(x: np.ndarray) -> int:
    """Class of one logit vector by the bundle's tie rule (ties to the lowest class)."""
    return int(argmax_lowest(np.atleast_2d(x))[0])


def compare_windows(
    expected: list[ExpectedWindow],
    got: list[WindowEstimate],
    q_logits: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    f32_logits: Callable[[np.ndarray], np.ndarray] | None = None,
    f32_tie_margin: float = 1e-4,
) -> tuple[list[WindowVerdict], list[WindowEstimate]]:
    """Match reported windows to expected ones (by window_counter, in order) and check each field.

    q_logits: int16 (N,12) -> (int logits (N,3), saturations (N,)), the torch integer reference.
    f32_logits: float (N,12) physical units -> float (N,3), the float model; a float class that
    differs only where the float model's top-2 margin is below `f32_tie_margin` is excused.
    Returns the verdicts and the reported windows that no expected window explains.
    """
    valid = [w for w in expected if not w.flags & fi.FLAG_INVALID]
    ref, ref_sat = q_logits(np.stack([w.feat_q for w in valid])) if valid else (np.zeros((0, 3)), np.zeros(0))
    ref_by_id = {id(w): np.asarray(r, dtype=np.int64) for w, r in zip(valid, ref)}
    sat_by_id = {id(w): int(s) + w.saturations for w, s in zip(valid, ref_sat)}
    fl_by_id: dict[int, np.ndarray] = {}
    if f32_logits is not None and valid:
        fl = f32_logits(np.stack([w.feat_f for w in valid]).astype(np.float32))
        fl_by_id = {id(w): np.asarray(r, dtype=np.float64) for w, r in zip(valid, fl)}
    verdicts: list[WindowVerdict] = []
    gi = 0
    unexplained: list[WindowEstimate] = []
    for exp in expected:
        # skip (and keep) reported windows that do not belong here
        while gi < len(got) and got[gi].window_counter != exp.window_counter and _later_match(got, gi, exp):
            unexplained.append(got[gi])
            gi += 1
        g = got[gi] if gi < len(got) and got[gi].window_counter == exp.window_counter else None
        if g is not None:
            gi += 1
        v = WindowVerdict(exp, g, ref_by_id.get(id(exp)), sat_by_id.get(id(exp), 0))
        if g is None:
            v.problems.append("missing")
        else:
            _check(v, exp, g, fl_by_id.get(id(exp)), f32_tie_margin)
        verdicts.append(v)
    unexplained.extend(got[gi:])
    return verdicts, unexplained


def _later_match(got: list[WindowEstimate], gi: int, exp: ExpectedWindow) -> bool:
    return any(g.window_counter == exp.window_counter for g in got[gi + 1 : gi + 4])


def _check(v: WindowVerdict, exp: ExpectedWindow, g: WindowEstimate, fl: np.ndarray | None, margin: float) -> None:
    p = v.problems
    # bit1 (saturation) and the count cover the features and the network's fixed-point path
    sat = fi.FLAG_SATURATION
    want_flags = (exp.flags & ~sat) | (sat if v.ref_saturations > 0 else 0)
    if g.flags != want_flags:
        p.append(f"flags {g.flags:#04x} != {want_flags:#04x}")
    if g.saturations != min(v.ref_saturations, 0xFFFF):
        p.append(f"saturations {g.saturations} != {v.ref_saturations}")
    if g.n_samples != min(exp.n_samples, 255):
        p.append(f"n_samples {g.n_samples} != {exp.n_samples}")
    if exp.flags & fi.FLAG_INVALID:
        if g.slip_class != 255 or (g.logits is not None and any(g.logits)):
            p.append("invalid window reported with a class/logits")
        return
    r = v.ref_logits
    assert r is not None
    if g.logits is None or tuple(int(x) for x in r) != tuple(g.logits):
        p.append(f"logits {g.logits} != reference {tuple(int(x) for x in r)}")
    if g.slip_class != argmax_low(r):
        p.append(f"class {g.slip_class} != reference {argmax_low(r)}")
    if fl is not None and g.slip_class_f32 != argmax_low(fl):
        top = np.sort(fl)[::-1]
        if top[0] - top[1] >= margin:
            p.append(f"float class {g.slip_class_f32} != float model {argmax_low(fl)}")


def compare_status(expected: Counters, got: StatusReport | None) -> list[str]:
    """Differences between predicted and reported counters (empty when they agree)."""
    if got is None:
        return ["no status report received"]
    out = []
    for k in ("frames_received", "frames_rejected", "samples_dropped", "windows_flagged", "windows_done"):
        e, r = getattr(expected, k), getattr(got, k)
        if k == "windows_done":
            e &= 0xFFFF
        if e != r:
            out.append(f"{k}: estimator {r}, expected {e}")
    return out
