"""`fleetlab bench link`: the options; the measurement is `fleetlab.host_tools.bench_link`."""

from __future__ import annotations

import argparse
import json

from ..errors import InputError
from fleetlab.host_tools.bench_link import measure, text
from fleetlab.host_tools.emulate import LINKS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--link", choices=LINKS, default="slcan", help="link to measure (default slcan)")
    parser.add_argument("--frames", type=int, default=30_000, help="frames of the full-speed soak (default 30,000)")
    parser.add_argument("--windows", type=int, default=3,
                        help="windows paced in real time for the latency (default 3: 6 s at 50 Hz)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def run(args: argparse.Namespace) -> int:
    if args.frames < 300 or args.windows < 1:
        raise InputError("--frames must cover one window (>= 300) and --windows must be >= 1")
    out, bit_exact = measure(args.link, args.frames, args.windows, args.seed, progress=not args.json)
    print(json.dumps(out) if args.json else text(out))
    return 0 if bit_exact else 1
