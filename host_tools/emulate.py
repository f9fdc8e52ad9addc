"""The host emulation loop behind `fleetlab emulate`: run the C estimator and compare bit for bit.

The host builds the emulator for a bundle (CMake), starts it on a pty (or loads the C
library in-process), streams a source through the chosen link at full speed, collects
every estimate, and checks each against the torch integer reference (logits, class,
saturations) and the float model (class). With `--inject`, faults are injected and the
estimator's status counters are checked against the host's prediction for every
estimator lifetime. Exit code 0 only when everything agrees and nothing was lost uncounted.
"""

from __future__ import annotations

import queue
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from fleetlab.data.features_int import FLAG_GAP, FLAG_INVALID, SAMPLES_PER_WINDOW

from .verify import stream_faults as fault_mod
from .verify.compare import EstimatorModel, WindowVerdict, compare_status, compare_windows
from .wire.dbc import (
    TELEM_NAMES,
    OutputAssembler,
    StatusReport,
    WindowEstimate,
    frame_id,
)
from .emulator import EmulatorProcess, build, default_bundle, find_artifact
from .pacing import Pacer, WallClock
from .links import ALIASES, InprocLink, Link, canonical_link, estimator_links, link_class
from .sources import FeatureSource, TelemetrySource, sim_source
from .verify.reference import Reference
from .wire.serial_framing import Rejected
from fleetlab.errors import InputError

LINKS = (*estimator_links(), *ALIASES)  # accepted by --link (aliases last)
DEFAULT_SCALE = 0.08
SAMPLE_RATE_HZ = 50.0
REALTIME_FRAMES_PER_S = 150.0  # 50 Hz rover, three telemetry frames per sample
REALTIME_WINDOWS_PER_S = 0.5
CHUNK = 64  # wire items per write; the reader thread drains answers meanwhile


@dataclass
class SegmentResult:
    verdicts: list[WindowVerdict]
    unexplained: list[WindowEstimate]
    status: StatusReport | None
    status_problems: list[str]
    expected_received: int
    frames_sent: int
    statuses: list[StatusReport] = field(default_factory=list)  # every STATUS report, periodic ones included
    pacer: Pacer | None = None  # the real-time schedule kept (a realtime run only)


@dataclass
class EmulationResult:
    link: str
    source: str
    segments: list[SegmentResult] = field(default_factory=list)
    faults: list[fault_mod.Fault] = field(default_factory=list)
    latencies_us: list[float] = field(default_factory=list)
    host_rx_errors: list[str] = field(default_factory=list)
    wall_s: float = 0.0  # whole run, including restarts and the comparison
    stream_s: float = 0.0  # writing frames until the last status answer arrived
    frames_sent: int = 0
    realtime: bool = False
    restarts: int = 0
    samples_lost_to_restart: int = 0
    samples_skipped_by_restart: int = 0
    windows_lost_to_restart: int = 0
    model_hash_problems: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        verdicts = [v for s in self.segments for v in s.verdicts]
        mism = [v for v in verdicts if not v.bit_exact]
        flagged = [v for v in verdicts if v.got is not None and v.got.flags & (FLAG_GAP | FLAG_INVALID)]
        unflagged_mism = [v for v in mism if not v.expected.flags & (FLAG_GAP | FLAG_INVALID)]
        rejected = sum(s.status.frames_rejected for s in self.segments if s.status)
        dropped = sum(max(0, s.expected_received - (s.status.frames_received if s.status else 0))
                      for s in self.segments)
        lat = np.array(self.latencies_us) if self.latencies_us else np.zeros(1)
        n_windows = len(verdicts)
        return {
            "windows": n_windows,
            "bit_exact": len(verdicts) - len(mism),
            "mismatches": len(mism),
            "flagged_windows": len(flagged),
            "rejected_frames": int(rejected),
            "dropped_frames": int(dropped),
            "injected_faults": len(self.faults),
            "detected_faults": sum(f.detected for f in self.faults),
            "latency_us": {"p50": float(np.percentile(lat, 50)), "p99": float(np.percentile(lat, 99))},
            "link": self.link,
            "source": self.source,
            "mismatches_unflagged": len(unflagged_mism),
            "unexplained_windows": sum(len(s.unexplained) for s in self.segments),
            "status_problems": [p for s in self.segments for p in s.status_problems] + self.model_hash_problems,
            "host_rx_errors": self.host_rx_errors[:20],
            "faults_by_kind": _faults_by_kind(self.faults),
            "restarts": self.restarts,
            "samples_lost_to_restart": self.samples_lost_to_restart,
            "samples_skipped_by_restart": self.samples_skipped_by_restart,
            "windows_lost_to_restart": self.windows_lost_to_restart,
            "frames_sent": self.frames_sent,
            "realtime": self.realtime,
            "samples_dropped_reported": sum(s.status.samples_dropped for s in self.segments if s.status),
            "wall_s": round(self.wall_s, 3),
            "stream_s": round(self.stream_s, 3),
            "frames_per_s": round(self.frames_sent / self.stream_s, 1) if self.stream_s else 0.0,
            "windows_per_s": round(n_windows / self.stream_s, 2) if self.stream_s else 0.0,
            "realtime_need": {"frames_per_s": REALTIME_FRAMES_PER_S, "windows_per_s": REALTIME_WINDOWS_PER_S},
            "first_problems": [f"window {v.expected.window_counter}: {'; '.join(v.problems)}" for v in mism[:10]],
        }

    def ok(self) -> bool:
        s = self.summary()
        return (s["mismatches"] == 0 and s["dropped_frames"] == 0 and s["unexplained_windows"] == 0
                and not s["status_problems"] and not self.host_rx_errors
                and s["detected_faults"] == s["injected_faults"])


def _faults_by_kind(faults: list[fault_mod.Fault]) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    for f in faults:
        d = out.setdefault(f.kind, {"injected": 0, "detected": 0})
        d["injected"] += 1
        d["detected"] += int(f.detected)
    return out


class _Endpoint:
    """The estimator at the other end of the link, and how to kill/restart it."""

    def __init__(self, link_kind: str, bundle: Path):
        self.cls = link_class(link_kind)
        self.emu: EmulatorProcess | None = None
        self.link: Link | None = None
        if self.cls.in_process:
            self.lib = find_artifact(build(bundle), "libslipest_host.so")
        else:
            assert self.cls.emulator_protocol is not None
            self.emu = EmulatorProcess.for_bundle(bundle, self.cls.emulator_protocol)

    def connect(self) -> Link:
        if self.cls.in_process:
            self.link = self.cls(self.lib)
        else:
            assert self.emu is not None
            self.link = self.cls.over_port(self.emu.start(), full_speed=True)
        return self.link

    def restart(self) -> Link:
        """Kill the estimator mid-stream and bring up a fresh one."""
        if self.cls.in_process:
            assert isinstance(self.link, InprocLink)
            self.link.restart()
            return self.link
        assert self.emu is not None and self.link is not None
        self.emu.kill()
        self.link.close()
        return self.connect()

    def close(self) -> None:
        if self.link is not None:
            self.link.close()
        if self.emu is not None:
            self.emu.stop()


def _drain(link: Link, asm: OutputAssembler, windows: list[WindowEstimate], statuses: list[StatusReport],
           errors: list[str]) -> None:
    while True:
        try:
            item, t = link.rx.get_nowait()
        except queue.Empty:
            return
        if isinstance(item, Rejected):
            errors.append(f"undecodable answer from the estimator ({item.reason}): {item.raw[:20]!r}")
            continue
        out = asm.feed(item, t)
        if isinstance(out, WindowEstimate):
            windows.append(out)
        elif isinstance(out, StatusReport):
            statuses.append(out)


def emulate(
    bundle: Path | str | None,
    source: TelemetrySource | FeatureSource,
    link_kind: str,
    kinds: list[str] | None = None,
    rate: float = 0.0,
    restart_every: int = 0,
    seed: int = 0,
    timeout: float = 20.0,
    progress: bool = True,
    realtime: bool = False,
    clock=None,
) -> EmulationResult:
    """Stream `source` (with the planned faults) to the node over `link_kind` and compare its answers with
    the reference. A realtime run sends one sample per period on `clock` (the wall clock unless a test gives
    fleetlab.host_tools.pacing's SimulatedClock); its schedule is kept in the segment results' pacers."""
    if link_kind not in LINKS:
        raise InputError(f"--link must be one of {', '.join(LINKS)}, got {link_kind!r}")
    link_kind = canonical_link(link_kind)
    bundle = Path(bundle) if bundle else default_bundle()
    ref = Reference.load(bundle)
    kinds = kinds or []
    if isinstance(source, TelemetrySource):
        plan = fault_mod.plan_telemetry(source.samples_q, kinds, rate, seed, restart_every)
    else:
        plan = fault_mod.plan_features(source.feat_q, kinds, rate, seed, restart_every)
    result = EmulationResult(link_kind, source.name, faults=plan.faults, realtime=realtime)
    endpoint = _Endpoint(link_kind, bundle)
    bar = tqdm(total=plan.n_frames, unit="frame", desc=f"emulate over {link_kind}", disable=not progress,
               unit_scale=True)
    t0 = time.perf_counter()
    try:
        link = endpoint.connect()
        for si, seg in enumerate(plan.segments):
            if si > 0:
                link = endpoint.restart()
                result.restarts += 1
            result.segments.append(_run_segment(link, seg, ref, timeout, bar, result, realtime, clock))
            result.samples_lost_to_restart += seg.samples_lost_to_restart
            result.samples_skipped_by_restart += seg.samples_skipped_by_restart
            result.windows_lost_to_restart += seg.windows_lost_to_restart
            result.frames_sent += len(seg.items)
    finally:
        result.wall_s = time.perf_counter() - t0
        bar.close()
        endpoint.close()
    _mark_detected(plan, result)
    return result


def _run_segment(link: Link, seg: fault_mod.Segment, ref: Reference, timeout: float, bar: tqdm,
                 result: EmulationResult, realtime: bool = False, clock=None) -> SegmentResult:
    model = EstimatorModel()
    asm = OutputAssembler()
    windows: list[WindowEstimate] = []
    statuses: list[StatusReport] = []
    errors: list[str] = []
    items = seg.items
    chunk_times: list[tuple[float, float]] = []  # (start, end) of each chunk's write
    item_chunk = np.zeros(len(items), dtype=np.int64)  # chunk index of every item
    item_sent: dict[int, float] = {}  # real time only: when each item's write began
    # real time: after the leading CONTROL reset, one chunk = one sample's three frames
    # (or one feature set) per period; otherwise chunks of CHUNK items at full speed
    if realtime:
        telem_ids = {frame_id(n) for n in TELEM_NAMES}
        telemetry = any(it.frame.can_id in telem_ids for it in items[1:4])
        step, period = (3, 1 / SAMPLE_RATE_HZ) if telemetry else (4, 2.0)
        starts = [0] + list(range(1, len(items), step))
    else:
        period, starts = 0.0, list(range(0, len(items), CHUNK))
    bounds = starts + [len(items)]
    t_start = time.perf_counter()
    pacer = Pacer(clock or WallClock()) if period else None
    for c in range(len(starts)):
        i, chunk = bounds[c], items[bounds[c] : bounds[c + 1]]
        item_chunk[bounds[c] : bounds[c + 1]] = c
        if pacer is not None:
            pacer.wait(c * period)
        ta = time.perf_counter()
        if realtime:
            # item by item, each write's start time kept: on a loaded host the estimate can be read back
            # before a chunk's write() returns, so the end of the chunk is no lower bound for its last item
            for j, it in enumerate(chunk):
                item_sent[i + j] = time.perf_counter()
                link.write([it])
        else:
            link.write(chunk)
        chunk_times.append((ta, time.perf_counter()))
        for j, it in enumerate(chunk):
            model.feed(it, i + j)
        _drain(link, asm, windows, statuses, errors)
        bar.update(len(chunk))
        if link.reader_error is not None:
            raise OSError(f"{link.name}: the link failed mid-stream: {link.reader_error}")
    expected_counters = model.status_snapshot()
    # the last item is CONTROL status: wait for the answer generated after it
    deadline = time.monotonic() + timeout
    final: StatusReport | None = None
    while time.monotonic() < deadline:
        _drain(link, asm, windows, statuses, errors)
        done = [s for s in statuses if s.frames_received >= expected_counters.frames_received]
        if done:
            final = done[0]
            break
        time.sleep(0.005)
    if final is None and statuses:
        final = statuses[-1]
    result.stream_s += time.perf_counter() - t_start
    expected = model.windows()
    verdicts, unexplained = compare_windows(expected, windows, ref.q_logits, ref.f32_logits)
    for v in verdicts:
        k = v.expected.trigger_item
        if v.got is not None and k >= 0:
            # real time: from the start of the trigger item's write; full speed: the k-th item of a chunk
            # left the host at about ta + (pos+1)/len * (tb - ta)
            c = int(item_chunk[k])
            ta, tb = chunk_times[c]
            t_sent = item_sent.get(k, ta + (k - bounds[c] + 1) / (bounds[c + 1] - bounds[c]) * (tb - ta))
            result.latencies_us.append(max(0.0, (v.got.t_recv - t_sent) * 1e6))
    problems = compare_status(expected_counters, final)
    if final is not None and ref.model_hash32 is not None and final.model_hash != ref.model_hash32:
        result.model_hash_problems.append(
            f"STATUS_MODEL hash {final.model_hash:08x} != bundle {ref.model_hash32:08x}")
    result.host_rx_errors.extend(errors + asm.errors)
    return SegmentResult(verdicts, unexplained, final, problems, expected_counters.frames_received, len(items),
                         statuses, pacer)


def _expected_at(items: list, positions: set[int]) -> dict[int, tuple[int, int]]:
    """(frames_rejected, samples_dropped) the estimator must report once it has received `p` items, for each
    p in positions (a STATUS report carries frames_received = p)."""
    model, out = EstimatorModel(), {0: (0, 0)}
    for i, it in enumerate(items):
        model.feed(it, i)
        if i + 1 in positions:
            c = model.status_snapshot()
            out[i + 1] = (c.frames_rejected, c.samples_dropped)
    return out


def _observed(f: fault_mod.Fault, fidx: int, items: list, seg: SegmentResult, cache: dict) -> bool:
    """Whether the node's own STATUS reports show the rejection or drop this fault caused: across the two
    reports around its frames (the node sends one every few windows and one on request at the end), its
    counters rose exactly as the replay of those frames predicts, and by at least this fault's own share."""
    where = [i for i, it in enumerate(items) if it.fault == fidx]
    if not where or f.frames_rejected + f.samples_dropped == 0:
        return False  # nothing on the wire or in the counters to observe
    got = {s.frames_received: (s.frames_rejected, s.samples_dropped) for s in seg.statuses}
    got[0] = (0, 0)  # a lifetime starts at zero (CONTROL reset is its first frame)
    before = max(p for p in got if p <= where[0])
    after = min((p for p in got if p > where[-1]), default=None)
    if after is None:
        return False
    if "expected" not in cache:
        cache["expected"] = _expected_at(items, set(got))
    want = cache["expected"]
    rose = [a - b for a, b in zip(got[after], got[before])]
    return (rose == [a - b for a, b in zip(want[after], want[before])]
            and rose[0] >= f.frames_rejected and rose[1] >= f.samples_dropped)


def _mark_detected(plan: fault_mod.Plan, result: EmulationResult) -> None:
    """A fault is detected when the estimator shows what it caused: the flag on the window it cut short,
    the rejected frame or dropped sample in the STATUS reports around it, or (restart) the next lifetime's
    counters starting from zero."""
    caches: dict[int, dict] = {}
    for fidx, f in enumerate(plan.faults):
        seg = result.segments[f.segment] if f.segment < len(result.segments) else None
        if seg is None or seg.status is None or seg.status_problems:
            continue
        if f.kind == "restart":
            # the next lifetime started from zero: its counters match a fresh estimator's
            nxt = result.segments[f.segment + 1] if f.segment + 1 < len(result.segments) else None
            f.detected = nxt is not None and nxt.status is not None and not nxt.status_problems
            continue
        if f.flags_window:
            wins = [v for v in seg.verdicts if v.expected.window_index == f.window]
            f.detected = bool(wins) and wins[0].got is not None and bool(wins[0].got.flags & FLAG_GAP)
        else:
            f.detected = _observed(f, fidx, plan.segments[f.segment].items, seg, caches.setdefault(f.segment, {}))


def soak_source(frames: int, seed: int, scale: float, base: TelemetrySource | None = None) -> TelemetrySource:
    """Simulator samples (or `base`) repeated until at least `frames` telemetry frames (whole windows)."""
    base = base or sim_source(seed, scale)
    n_samples = -(-frames // 3)
    n_samples = -(-n_samples // SAMPLES_PER_WINDOW) * SAMPLES_PER_WINDOW
    reps = -(-n_samples // len(base.samples_q))
    samples = np.tile(base.samples_q, (reps, 1))[:n_samples]
    return TelemetrySource(f"soak({frames} frames of {base.name})", samples, [("soak", n_samples // 100)])


def first_windows(source: TelemetrySource | FeatureSource, n: int) -> TelemetrySource | FeatureSource:
    if isinstance(source, TelemetrySource):
        traces, left = [], n
        for name, k in source.traces:
            if left > 0:
                traces.append((name, min(k, left)))
            left -= k
        starts = None if source.window_start_ns is None else source.window_start_ns[:n]
        return TelemetrySource(f"{source.name}[:{n} windows]", source.samples_q[: n * SAMPLES_PER_WINDOW], traces,
                               starts, source.trace_files)
    return FeatureSource(f"{source.name}[:{n} windows]", source.feat_q[:n])
