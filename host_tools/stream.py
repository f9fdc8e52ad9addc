"""`fleetlab stream can|serial`: stream telemetry or features to an estimator and show its answers.

Sources: `sim` (raw telemetry from the simulator, TELEM frames), `vectors` (a bundle's test
vectors, FEATURES frames), a folder of window CSVs (FEATURES frames) or a python-can log
(.log candump / .asc / .blf; only the frames the HOST sends per the DBC are replayed).
Real time (`--realtime`: 50 Hz samples, or the log's own timing) or as fast as possible.
Everything sent and received can be logged with `--log FILE` in python-can's formats.

The estimator's STATUS counters count over its whole life (a node that ran before, and will run after, this
command). A stream first asks for the status (CONTROL 2) and takes the answer as its baseline: every counter it
reports or checks is the difference from that baseline, modulo the counter's width in the DBC (so across a wrap).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Iterator

import can
from tqdm import tqdm

from fleetlab.data.features_int import SAMPLES_PER_WINDOW

from .links import Link, to_message
from .pacing import Pacer, WallClock
from .sources import FeatureSource, TelemetrySource, log_frames
from .wire.dbc import (
    CONTROL_RESET,
    CONTROL_STATUS,
    Frame,
    OutputAssembler,
    StatusReport,
    WindowEstimate,
    control_frame,
    database,
    feature_frames,
    telemetry_frames,
)
from .wire.items import WireItem
from .wire.serial_framing import Rejected

SAMPLE_RATE_HZ = 50.0
WINDOW_PERIOD_S = SAMPLES_PER_WINDOW / SAMPLE_RATE_HZ


# the STATUS counters (StatusReport fields) and their DBC messages; model_hash and lib_version are not counters
STATUS_COUNTERS = {"windows_done": "STATUS_MODEL", "frames_received": "STATUS_RX", "frames_rejected": "STATUS_RX",
                   "samples_dropped": "STATUS_LOSS", "windows_flagged": "STATUS_LOSS"}


def counter_delta(now: int, start: int, bits: int = 32) -> int:
    """How much a `bits`-wide counter rose from `start` to `now`, across a wrap (less than one full turn)."""
    return (now - start) % (1 << bits)


def status_counter_bits() -> dict[str, int]:
    """Width in bits of each STATUS counter, from the DBC in use (windows_done is 16 bits, the others 32)."""
    db = database()
    return {name: db.get_message_by_name(msg).get_signal_by_name(name).length
            for name, msg in STATUS_COUNTERS.items()}


def status_delta(now: StatusReport | None, start: StatusReport | None) -> StatusReport | None:
    """`now` with every counter read as the difference from `start` (None: `now` as reported, i.e. counted from
    the node's start)."""
    if now is None or start is None:
        return now
    bits = status_counter_bits()
    return replace(now, **{k: counter_delta(getattr(now, k), getattr(start, k), bits[k]) for k in STATUS_COUNTERS})


@dataclass
class StreamStats:
    frames_sent: int = 0  # the stream's frames: CONTROL reset, the source's frames, CONTROL status
    windows_sent: int = 0
    estimates: list[WindowEstimate] = field(default_factory=list)
    node_start: StatusReport | None = None  # the node's answer to the status request before the stream (baseline)
    node_status: StatusReport | None = None  # the node's last STATUS report as sent (its lifetime counters)
    rx_errors: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    pacer: Pacer | None = None  # the real-time schedule kept (a realtime stream only)

    @property
    def status(self) -> StatusReport | None:
        """The node's last STATUS report with its counters counted from the baseline: what this stream caused.
        The baseline's answer counts the status request itself, so after the final status request
        `status.frames_received == frames_sent` when no frame was lost."""
        return status_delta(self.node_status, self.node_start)


def timed_frames(source: TelemetrySource | FeatureSource | Path, limit: int = 0,
                 skipped: Counter | None = None) -> Iterator[tuple[Frame, float | None, bool]]:
    """(frame, due time in s from the start or None, closes a window) for any source. A log's frames that
    the host does not send (the estimator's answers, other nodes' traffic) are not sent again: they are
    counted in `skipped`."""
    if isinstance(source, Path):
        senders = {m.frame_id for m in database().messages if "HOST" in m.senders}
        t0 = None
        for frame, ts in log_frames(source, skipped):
            if frame.can_id not in senders:
                if skipped is not None:
                    skipped["frames the host does not send"] += 1
                continue
            t0 = ts if t0 is None else t0
            yield frame, ts - t0, False
        return
    if isinstance(source, TelemetrySource):
        n = source.n_windows if not limit else min(limit, source.n_windows)
        for i in range(n * SAMPLES_PER_WINDOW):
            fs = telemetry_frames(i, source.samples_q[i])
            for j, f in enumerate(fs):
                yield f, i / SAMPLE_RATE_HZ, j == 2 and i % SAMPLES_PER_WINDOW == SAMPLES_PER_WINDOW - 1
        return
    n = source.n_windows if not limit else min(limit, source.n_windows)
    for w in range(n):
        for j, f in enumerate(feature_frames(w, source.feat_q[w])):
            yield f, w * WINDOW_PERIOD_S, j == 3


class TrafficLog:
    """python-can Logger for both directions (format chosen by the file suffix)."""

    def __init__(self, path: Path | None):
        self.logger = can.Logger(str(path)) if path else None

    def __call__(self, frame: Frame, rx: bool) -> None:
        if self.logger is not None:
            msg = to_message(frame)
            msg.timestamp, msg.is_rx = time.time(), rx
            self.logger(msg)

    def close(self) -> None:
        if self.logger is not None:
            self.logger.stop()


def stream(link: Link, frames: Iterable[tuple[Frame, float | None, bool]], realtime: bool, log: TrafficLog,
           wait_s: float = 5.0, on_estimate=None, total: int | None = None, progress: bool = True,
           clock=None) -> StreamStats:
    """Ask for the node's status (its answer is the baseline of the counters), then send CONTROL reset, the
    frames, CONTROL status; collect every answer. A realtime stream sends each frame at its due time on `clock`
    (the wall clock unless a test gives fleetlab.host_tools.pacing's SimulatedClock). The node may have run
    before: `stats.status` counts from the baseline (`stats.node_status` is the node's report as sent)."""
    stats = StreamStats()
    asm = OutputAssembler()
    awaiting_baseline = True

    def discard_pending() -> None:
        """Answers queued before this command (a previous command's, an interrupted one's) are not ours."""
        while True:
            try:
                link.rx.get_nowait()
            except Exception:
                return

    def drain() -> None:
        while True:
            try:
                item, t = link.rx.get_nowait()
            except Exception:
                return
            if isinstance(item, Rejected):
                stats.rx_errors.append(f"undecodable answer ({item.reason})")
                continue
            log(item, True)
            out = asm.feed(item, t)
            if isinstance(out, WindowEstimate):
                stats.estimates.append(out)
                if on_estimate:
                    on_estimate(out)
            elif isinstance(out, StatusReport):
                if awaiting_baseline:
                    stats.node_start = out  # the answer to the status request sent before the stream
                else:
                    stats.node_status = out

    def send(frame: Frame) -> None:
        link.write([WireItem(frame)])
        log(frame, False)
        stats.frames_sent += 1

    t0 = time.perf_counter()
    discard_pending()
    # the baseline: not one of the stream's frames (not in frames_sent), but counted by the node in its answer
    request = control_frame(CONTROL_STATUS)
    link.write([WireItem(request)])
    log(request, False)
    deadline = time.monotonic() + wait_s
    while stats.node_start is None and time.monotonic() < deadline:
        drain()
        if stats.node_start is None:
            time.sleep(0.002)
    awaiting_baseline = False
    if stats.node_start is None:
        stats.rx_errors.append(f"no answer to the status request within {wait_s:g} s: the counters are the "
                               "node's totals, not this stream's")
    if realtime:
        stats.pacer = Pacer(clock or WallClock())  # the schedule starts after the baseline's round trip
    send(control_frame(CONTROL_RESET))
    # closed before any error of the source (a malformed log) is printed, so that it gets a line of its own
    with tqdm(total=total, unit="frame", desc=f"stream {link.name}", disable=not progress, unit_scale=True) as bar:
        for frame, due, closes in frames:
            if stats.pacer is not None and due is not None:
                stats.pacer.wait(due)
            send(frame)
            stats.windows_sent += int(closes)
            bar.update(1)
            if stats.frames_sent % 64 == 0:
                drain()
    send(control_frame(CONTROL_STATUS))
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        drain()
        # the answer to the final request (periodic reports come before it, with fewer frames counted)
        st = stats.status
        if st is not None and st.frames_received >= stats.frames_sent:
            break
        time.sleep(0.005)
    stats.rx_errors.extend(asm.errors)
    stats.wall_s = time.perf_counter() - t0
    return stats
