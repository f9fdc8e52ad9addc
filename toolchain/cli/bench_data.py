"""`fleetlab bench data`: the options; the measurement is `fleetlab.data.bench`."""

from __future__ import annotations

import argparse
import json

from ..data.bench import measure, text
from ..errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("--samples", type=int, default=2_000_000, help="raw samples per featurise call (default 2,000,000)")
    parser.add_argument("--repeats", type=int, default=5, help="featurise repeats; the best is reported (default 5)")
    parser.add_argument("--sim-scale", type=float, default=1.0,
                        help="scenario scale for the batched simulation timing (default 1.0, the full scenario)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the random trace and the scenario (default 1)")


def run(args: argparse.Namespace) -> int:
    if args.samples < 100 or args.repeats < 1:
        raise InputError("--samples must be >= 100 and --repeats >= 1")
    if not 0 < args.sim_scale <= 10:
        raise InputError(f"--sim-scale must be in (0, 10], got {args.sim_scale}")
    result = measure(args.samples, args.repeats, args.sim_scale, args.seed)
    print(json.dumps(result) if args.json else text(result))
    return 0
