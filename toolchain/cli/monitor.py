"""`fleetlab monitor`: watch slip estimates and status frames on a CAN bus (or replay a log);
the decoding is `fleetlab.host_tools.monitor`."""

from __future__ import annotations

import argparse
from pathlib import Path

import can

from fleetlab.host_tools.links import open_can_bus
from fleetlab.host_tools.monitor import monitor_bus, monitor_log
from .dbc_option import add_dbc_option, apply_dbc_option


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="transport", metavar="TRANSPORT", required=True)
    c = sub.add_parser("can", help="listen on a python-can bus", description="Listen on a python-can bus and "
                       "decode every frame with the DBC (dbc/slipest.dbc, or --dbc), or replay a python-can log (--replay).")
    c.add_argument("--interface", default="virtual", help="python-can interface (default virtual)")
    c.add_argument("--channel", default=None, help="bus channel (vcan0, /dev/ttyACM0, ...)")
    c.add_argument("--bitrate", type=int, default=None, help="bitrate for slcan/socketcan")
    c.add_argument("--replay", type=Path, default=None, metavar="LOG",
                   help="decode a python-can log (.log/.asc/.blf) instead of a live bus")
    c.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C)")
    c.add_argument("--count", type=int, default=0, help="stop after this many estimates (0: no limit)")
    c.add_argument("--log", type=Path, default=None, metavar="FILE", help="also log every frame (python-can format)")
    c.add_argument("--all", action="store_true", help="print every decoded frame, not only estimates and status")
    add_dbc_option(c)


def run(args: argparse.Namespace) -> int:
    apply_dbc_option(args)
    if args.replay:
        stats = monitor_log(args.replay, show_all=args.all)
    else:
        kw = {"bitrate": args.bitrate} if args.bitrate else {}
        bus = open_can_bus(args.interface, args.channel, **kw)
        logger = can.Logger(str(args.log)) if args.log else None
        try:
            stats = monitor_bus(bus, args.duration, args.count, print, logger, args.all)
        except KeyboardInterrupt:
            stats = None
        finally:
            if logger is not None:
                logger.stop()
            bus.shutdown()
        if stats is None:
            return 130
    print(f"{stats.frames} frames: {len(stats.estimates)} estimates, {len(stats.statuses)} status reports, "
          f"{stats.unknown} unknown/undecodable, {len(stats.problems)} problems")
    d = stats.counters()  # the node may have run long before the monitor: counted from the first status seen
    if d is not None:
        print(f"estimator while watched (first to last status): windows done {d.windows_done}, frames received "
              f"{d.frames_received}, rejected {d.frames_rejected}, samples dropped {d.samples_dropped}, "
              f"windows flagged {d.windows_flagged}")
    return 0
