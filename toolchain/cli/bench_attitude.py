"""`fleetlab bench attitude`: the options; the measurement is `fleetlab.data.attitude_bench`."""

from __future__ import annotations

import argparse
import json

from ..data.attitude_bench import measure, table


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=1, help="scenario seed (default 1)")
    parser.add_argument("--scale", type=float, default=0.5,
                        help="scenario scale: number and length of the traverses (default 0.5: 27 traverses of "
                        "235 to 290 s, each also on flat ground)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def run(args: argparse.Namespace) -> int:
    result = measure(args.seed, args.scale)
    print(json.dumps(result) if args.json else table(result))
    return 0
