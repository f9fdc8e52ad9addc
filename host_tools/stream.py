"""`fleetlab stream can|serial`: stream telemetry or features to an estimator and show its answers.

Sources: `sim` (raw telemetry from the simulator, TELEM frames), `vectors` (a bundle's test
vectors, FEATURES frames), a folder of window CSVs (FEATURES frames) or a python-can log
(.log candump / .asc / .blf; only the frames the HOST sends per the DBC are replayed).
Real time (`--realtime`: 50 Hz samples, or the log's own timing) or as fast as possible.
Everything sent and received can be logged with `--log FILE` in python-can's formats.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import can
from tqdm import tqdm

from fleetlab.data.features_int import SAMPLES_PER_WINDOW

from .wire.items import WireItem
from .wire.dbc import (
    CONTROL_RESET,
    CONTROL_STATUS,
    Frame,
    OutputAssembler,
    StatusReport,
    WindowEstimate,
    add_dbc_option,
    apply_dbc_option,
    control_frame,
    database,
    feature_frames,
    telemetry_frames,
)
from .links import CanBusLink, Link, link_class, open_can_bus, to_message
from .wire.serial_framing import Rejected
from .sources import LOG_SUFFIXES, FeatureSource, TelemetrySource, log_frames, resolve

SAMPLE_RATE_HZ = 50.0
WINDOW_PERIOD_S = SAMPLES_PER_WINDOW / SAMPLE_RATE_HZ


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="transport", metavar="TRANSPORT", required=True)
    c = sub.add_parser("can", help="stream over a python-can bus (virtual, slcan, socketcan, ...)",
                       description="Stream over a python-can bus. --interface virtual attaches an in-process C "
                                   "estimator (ctypes) to the same virtual channel; --interface slcan --channel "
                                   "emulator starts the C emulator and talks SLCAN to it over its pty.")
    c.add_argument("--interface", default="virtual", help="python-can interface name (default virtual)")
    c.add_argument("--channel", default=None,
                   help="bus channel (vcan0, /dev/ttyACM0, ...); with slcan, 'emulator' starts the C emulator")
    c.add_argument("--bitrate", type=int, default=500000, help="CAN bitrate for slcan/socketcan (default 500000)")
    c.add_argument("--no-estimator", action="store_true",
                   help="with --interface virtual: do not attach the in-process estimator")
    s = sub.add_parser("serial", help="stream COBS+CRC packets over a serial port or pty",
                       description="Stream COBS + CRC-16 framed frames over pyserial. --port emulator starts the "
                                   "C emulator and uses its pty.")
    s.add_argument("--port", required=True, help="serial port or pty path, or 'emulator'")
    s.add_argument("--baudrate", type=int, default=921600, help="baud rate of a real port (default 921600)")
    for q in (c, s):
        q.add_argument("--source", default="sim",
                       help="sim | vectors | folder of window CSVs | python-can log file (default sim)")
        q.add_argument("--bundle", type=Path, default=None,
                       help="export bundle (for --source vectors and for a started emulator)")
        q.add_argument("--realtime", action="store_true",
                       help="pace like the rover: 50 Hz samples / one feature set per 2 s window / log timing")
        q.add_argument("--limit", type=int, default=0, metavar="WINDOWS", help="stop after this many windows")
        q.add_argument("--log", type=Path, default=None, metavar="FILE",
                       help="log every frame sent and received (python-can format by suffix: .log .asc .blf ...)")
        q.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
        q.add_argument("--scale", type=float, default=0.08, help="simulator scenario scale (default 0.08)")
        q.add_argument("--wait", type=float, default=5.0, help="seconds to wait for the last answers (default 5)")
        q.add_argument("--quiet", action="store_true", help="do not print every estimate")
        add_dbc_option(q)


@dataclass
class StreamStats:
    frames_sent: int = 0
    windows_sent: int = 0
    estimates: list[WindowEstimate] = field(default_factory=list)
    status: StatusReport | None = None
    rx_errors: list[str] = field(default_factory=list)
    wall_s: float = 0.0


def timed_frames(source: TelemetrySource | FeatureSource | Path, limit: int = 0) -> Iterator[tuple[Frame, float | None, bool]]:
    """(frame, due time in s from the start or None, closes a window) for any source."""
    if isinstance(source, Path):
        senders = {m.frame_id for m in database().messages if "HOST" in m.senders}
        t0 = None
        for frame, ts in log_frames(source):
            if frame.can_id not in senders:
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
           wait_s: float = 5.0, on_estimate=None, total: int | None = None, progress: bool = True) -> StreamStats:
    """Send CONTROL reset, the frames, CONTROL status; collect every answer."""
    stats = StreamStats()
    asm = OutputAssembler()

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
                stats.status = out

    def send(frame: Frame) -> None:
        link.write([WireItem(frame)])
        log(frame, False)
        stats.frames_sent += 1

    t0 = time.perf_counter()
    send(control_frame(CONTROL_RESET))
    bar = tqdm(total=total, unit="frame", desc=f"stream {link.name}", disable=not progress, unit_scale=True)
    for frame, due, closes in frames:
        if realtime and due is not None:
            delay = t0 + due - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        send(frame)
        stats.windows_sent += int(closes)
        bar.update(1)
        if stats.frames_sent % 64 == 0:
            drain()
    bar.close()
    sent_before_status = stats.frames_sent
    send(control_frame(CONTROL_STATUS))
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        drain()
        if stats.status is not None and stats.status.frames_received >= sent_before_status + 1:
            break
        time.sleep(0.005)
    stats.rx_errors.extend(asm.errors)
    stats.wall_s = time.perf_counter() - t0
    return stats


def _source_of(args) -> TelemetrySource | FeatureSource | Path:
    p = Path(args.source)
    if p.suffix.lower() in LOG_SUFFIXES:
        if not p.is_file():
            raise OSError(f"{p}: no such log file")
        return p
    from .emulator import default_bundle

    return resolve(args.source, args.seed, args.scale, args.bundle or default_bundle())


def _print_estimate(e: WindowEstimate) -> None:
    cls = "invalid" if e.slip_class == 255 else str(e.slip_class)
    print(f"window {e.window_counter:5d}  class {cls:>7}  f32 {e.slip_class_f32:3d}  flags {e.flags:#04x}  "
          f"n {e.n_samples:3d}  sat {e.saturations}  logits {e.logits}")


def run(args: argparse.Namespace) -> int:
    from .emulator import EmulatorProcess, build, find_artifact

    apply_dbc_option(args)
    source = _source_of(args)
    emu = None
    if args.transport == "can":
        if args.interface == "virtual" and not args.no_estimator:
            lib = find_artifact(build(args.bundle), "libslipest_host.so")
            link: Link = link_class("inproc")(lib, channel=args.channel)
        elif args.interface == "slcan":
            channel = args.channel
            if channel in (None, "emulator"):
                emu = EmulatorProcess.for_bundle(args.bundle, link_class("slcan").emulator_protocol)
                channel = emu.start()
            link = link_class("slcan").over_port(channel, bitrate=args.bitrate)
        else:
            kw = {"bitrate": args.bitrate} if args.interface not in ("virtual",) else {}
            link = CanBusLink(open_can_bus(args.interface, args.channel, **kw), f"{args.interface}:{args.channel}")
    else:  # the serial transport carries the COBS link
        port = args.port
        if port == "emulator":
            emu = EmulatorProcess.for_bundle(args.bundle, link_class("cobs").emulator_protocol)
            port = emu.start()
        link = link_class("cobs").over_port(port, baudrate=args.baudrate)
    log = TrafficLog(args.log)
    try:
        total = None
        if not isinstance(source, Path):
            per = 3 * SAMPLES_PER_WINDOW if isinstance(source, TelemetrySource) else 4
            total = per * (min(args.limit, source.n_windows) if args.limit else source.n_windows)
        stats = stream(link, timed_frames(source, args.limit), args.realtime, log, args.wait,
                       None if args.quiet else _print_estimate, total, progress=True)
    finally:
        log.close()
        link.close()
        if emu is not None:
            emu.stop()
    print(f"sent {stats.frames_sent} frames ({stats.windows_sent} windows) in {stats.wall_s:.2f} s; "
          f"received {len(stats.estimates)} estimates")
    st = stats.status
    if st is not None:
        print(f"estimator: frames received {st.frames_received}, rejected {st.frames_rejected}, samples dropped "
              f"{st.samples_dropped}, windows flagged {st.windows_flagged}, windows done {st.windows_done}, "
              f"model {st.model_hash:08x}")
    for e in stats.rx_errors[:10]:
        print(f"PROBLEM: {e}")
    if args.log:
        print(f"traffic logged to {args.log}")
    if st is None:
        print("PROBLEM: no status answer from the estimator")
        return 1
    lost = stats.frames_sent - st.frames_received
    if lost:
        print(f"PROBLEM: {lost} frames sent but not received by the estimator")
    return 0 if (st is not None and not lost and not stats.rx_errors) else 1
