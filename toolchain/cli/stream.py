"""`fleetlab stream`: stream telemetry or features to the estimator over CAN or serial
(the streaming loop is `fleetlab.host_tools.stream`)."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from ..data.features_int import SAMPLES_PER_WINDOW
from fleetlab.host_tools.emulator import EmulatorProcess, build, find_artifact
from fleetlab.host_tools.links import CanBusLink, Link, link_class, open_can_bus
from fleetlab.host_tools.sources import LOG_SUFFIXES, FeatureSource, TelemetrySource, resolve
from fleetlab.host_tools.stream import TrafficLog, stream, timed_frames
from fleetlab.host_tools.wire.dbc import WindowEstimate
from . import options
from .dbc_option import add_dbc_option, apply_dbc_option
from ..paths import default_bundle


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
                       help="sim | vectors | 'fleetlab data import' folder (its raw samples) | folder of window CSVs | "
                       "python-can log file (default sim)")
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
        options.no_progress(q)
        add_dbc_option(q)


def _source_of(args) -> TelemetrySource | FeatureSource | Path:
    p = Path(args.source)
    if p.suffix.lower() in LOG_SUFFIXES:
        if not p.is_file():
            raise OSError(f"{p}: no such log file")
        return p
    return resolve(args.source, args.seed, args.scale, args.bundle or default_bundle())


def _print_estimate(e: WindowEstimate) -> None:
    cls = "invalid" if e.slip_class == 255 else str(e.slip_class)
    print(f"window {e.window_counter:5d}  class {cls:>7}  f32 {e.slip_class_f32:3d}  flags {e.flags:#04x}  "
          f"n {e.n_samples:3d}  sat {e.saturations}  logits {e.logits}")


def run(args: argparse.Namespace) -> int:
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
    skipped: Counter = Counter()  # a replayed log's frames that are not sent again
    try:
        total = None
        if not isinstance(source, Path):
            per = 3 * SAMPLES_PER_WINDOW if isinstance(source, TelemetrySource) else 4
            total = per * (min(args.limit, source.n_windows) if args.limit else source.n_windows)
        stats = stream(link, timed_frames(source, args.limit, skipped), args.realtime, log, args.wait,
                       None if args.quiet else _print_estimate, total, progress=not args.no_progress)
    finally:
        log.close()
        link.close()
        if emu is not None:
            emu.stop()
    print(f"sent {stats.frames_sent} frames ({stats.windows_sent} windows) in {stats.wall_s:.2f} s; "
          f"received {len(stats.estimates)} estimates")
    if skipped:
        print(f"log {source}: not sent again: " + ", ".join(f"{n} {what}" for what, n in sorted(skipped.items())))
    st = stats.status  # the node's counters since this stream's start (it may have run before)
    if st is not None:
        print(f"estimator: frames received {st.frames_received}, rejected {st.frames_rejected}, samples dropped "
              f"{st.samples_dropped}, windows flagged {st.windows_flagged}, windows done {st.windows_done}, "
              f"model {st.model_hash:08x}")
        if stats.node_start is not None and stats.node_start.frames_received > 1:  # not a fresh node
            tot = stats.node_status
            print(f"estimator totals since its start: frames received {tot.frames_received}, windows done "
                  f"{tot.windows_done} (the counters above are this stream's)")
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
