"""`fleetlab bench import`: the options; the measurement is `fleetlab.data.import_bench`."""

from __future__ import annotations

import argparse
import json

from ..data.import_bench import measure, text
from ..errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--minutes", type=float, default=10.0, help="length of the bag in minutes (default 10)")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="bag storage (default mcap)")
    parser.add_argument("--seed", type=int, default=1, help="traverse seed (default 1)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def run(args: argparse.Namespace) -> int:
    if not 0.1 <= args.minutes <= 120:
        raise InputError(f"--minutes must be in [0.1, 120], got {args.minutes}")
    out = measure(args.minutes, args.storage, args.seed)
    print(json.dumps(out) if args.json else text(out))
    return 0
