"""`fleetlab emulate`: run the C estimator in the host emulation loop and compare bit for bit
(the loop itself is `fleetlab.host_tools.emulate`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fleetlab.host_tools.emulate import (
    DEFAULT_SCALE,
    LINKS,
    REALTIME_FRAMES_PER_S,
    REALTIME_WINDOWS_PER_S,
    emulate,
    first_windows,
    soak_source,
)
from fleetlab.host_tools.estimates import check_path, write_estimates
from fleetlab.host_tools.sources import FeatureSource, TelemetrySource, resolve
from fleetlab.host_tools.verify import stream_faults as fault_mod
from .dbc_option import add_dbc_option, apply_dbc_option
from ..paths import default_bundle
from ..errors import InputError

EPILOG = """\
Output: a summary; with --json FILE the same as JSON: windows, bit_exact, mismatches,
flagged_windows, rejected_frames (estimator's count), dropped_frames (sent but never
received, uncounted), injected_faults, detected_faults, latency_us {p50, p99} (from the
frame that closes a window to its SLIP_ESTIMATE, full-speed stream), plus detail keys.
Exit status 0 only if every window is bit-exact, every status counter matches the host's
prediction, nothing was lost uncounted and every injected fault was detected.

Faults (--inject): bad_crc (serial: CRC inverted; slcan: malformed line), wrong_length,
unknown_id, dropped_sample, reordered_samples, duplicated_frame, restart (kill the
emulator mid-window, start it again, CONTROL reset, resume at the next window boundary).
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = EPILOG
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("--bundle", type=Path, default=None,
                   help="export bundle directory (default: the committed example bundle firmware_c/bundles/example)")
    p.add_argument("--source", default="sim",
                   help="'sim' (simulated raw telemetry, TELEM frames), 'vectors' (the bundle's test vectors, "
                        "FEATURES frames), a 'fleetlab data import' folder (its raw samples, TELEM frames) or a folder "
                        "of window CSV files (FEATURES frames); default sim")
    p.add_argument("--link", choices=LINKS, default="slcan",
                   help="slcan: python-can slcan bus on the emulator's pty; cobs (old name: serial): COBS+CRC packets on its pty; "
                        "inproc: the C library via ctypes on a python-can virtual bus (default slcan)")
    p.add_argument("--inject", default=None, metavar="KINDS",
                   help=f"faults to inject: comma list of {', '.join(fault_mod.KINDS)}, or 'all'")
    p.add_argument("--inject-rate", type=float, default=0.05, metavar="R",
                   help="probability that a window carries one fault (default 0.05)")
    p.add_argument("--restart-every", type=int, default=0, metavar="N",
                   help="also kill and restart the estimator every N windows (0: never)")
    p.add_argument("--soak", type=int, default=0, metavar="FRAMES",
                   help="throughput soak: stream at least FRAMES telemetry frames (simulator data, repeated) "
                        "at full speed and report frames/s and windows/s")
    p.add_argument("--max-windows", type=int, default=0, metavar="N",
                   help="stream only the first N windows of the source (0: all)")
    p.add_argument("--realtime", action="store_true",
                   help="pace like the rover (one sample = 3 frames every 20 ms, or one feature set per 2 s) "
                        "instead of full speed; latency then measures the estimator, not a queue")
    p.add_argument("--seed", type=int, default=0, help="simulator and fault-injection seed (default 0)")
    p.add_argument("--scale", type=float, default=DEFAULT_SCALE,
                   help=f"simulator scenario scale (default {DEFAULT_SCALE}, >= 500 windows)")
    p.add_argument("--json", type=Path, default=None, metavar="FILE", help="write the summary as JSON")
    p.add_argument("--estimates", type=Path, default=None, metavar="FILE",
                   help="write each window's estimate (start and end time, class, logits, saturations, source file): "
                        "FILE.csv, or FILE.mcap, a rosbag2 in the input log's time base with /slipest/estimate and "
                        "/diagnostics that opens beside the input bag (docs/your_rover.md)")
    p.add_argument("--timeout", type=float, default=20.0,
                   help="seconds to wait for the estimator's answers at the end of a lifetime (default 20)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_dbc_option(p)


def print_summary(s: dict) -> None:
    print(f"emulate over {s['link']} from {s['source']}")
    print(f"  windows {s['windows']}: bit-exact {s['bit_exact']}, mismatches {s['mismatches']} "
          f"(unflagged {s['mismatches_unflagged']}), flagged {s['flagged_windows']}, "
          f"unexplained {s['unexplained_windows']}")
    print(f"  frames sent {s['frames_sent']}, rejected {s['rejected_frames']}, lost uncounted {s['dropped_frames']}")
    print(f"  faults injected {s['injected_faults']}, detected {s['detected_faults']} {s['faults_by_kind'] or ''}")
    if s["restarts"]:
        print(f"  restarts {s['restarts']}: {s['samples_lost_to_restart']} samples "
              f"({s['samples_skipped_by_restart']} never sent) / {s['windows_lost_to_restart']} windows lost to restart")
    pace = "real-time" if s.get("realtime") else "full-speed"
    print(f"  latency p50 {s['latency_us']['p50']:.0f} us, p99 {s['latency_us']['p99']:.0f} us ({pace} stream)")
    print(f"  throughput {s['frames_per_s']:.0f} frames/s, {s['windows_per_s']:.1f} windows/s in {s['stream_s']:.2f} s "
          f"(real time needs {REALTIME_FRAMES_PER_S:.0f} frames/s, {REALTIME_WINDOWS_PER_S} windows/s: "
          f"x{s['frames_per_s'] / REALTIME_FRAMES_PER_S:.0f})")
    for p in s["status_problems"] + s["host_rx_errors"] + s["first_problems"]:
        print(f"  PROBLEM: {p}")


def run(args: argparse.Namespace) -> int:
    apply_dbc_option(args)
    bundle = args.bundle or default_bundle()
    if args.estimates is not None:
        check_path(args.estimates)
        if args.restart_every:
            raise InputError("--estimates writes the estimates of a plain replay (one estimator lifetime); "
                             "drop --restart-every")
    if args.soak:
        if args.source != "sim":
            raise InputError("--soak streams simulator telemetry; drop --source")
        source: TelemetrySource | FeatureSource = soak_source(args.soak, args.seed, args.scale)
    else:
        source = resolve(args.source, args.seed, args.scale, bundle)
    if args.max_windows < 0:
        raise InputError("--max-windows must be >= 0")
    if args.max_windows:
        source = first_windows(source, args.max_windows)
    kinds = fault_mod.parse_kinds(args.inject, args.link, isinstance(source, FeatureSource))
    if args.restart_every < 0:
        raise InputError("--restart-every must be >= 0")
    result = emulate(bundle, source, args.link, kinds, args.inject_rate, args.restart_every, args.seed,
                     args.timeout, progress=not args.no_progress, realtime=args.realtime)
    s = result.summary()
    print_summary(s)
    if args.estimates is not None:
        rows = write_estimates(args.estimates, result, source)
        print(f"  wrote {len(rows)} window estimates to {args.estimates}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(s, indent=2) + "\n")
    return 0 if result.ok() else 1
