"""`fleetlab bench c`: the options; the builds and measurements are `fleetlab.host_tools.firmware.bench`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fleetlab.host_tools.firmware.bench import bench, format_result, list_targets, targets_text
from fleetlab.host_tools.firmware.targets import reference


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--bundle", type=Path, default=None, help="export bundle (default: the example bundle)")
    parser.add_argument("--build-dir", type=Path, default=None,
                        help="where the host and target builds go, reused when present (default: bench/ under "
                             "the build root: build/ in a clone, else the user's cache folder)")
    parser.add_argument("--iterations", type=int, default=2000,
                        help="onnxruntime/torch inferences per timing round (3 rounds, interleaved with the C bench)")
    parser.add_argument("--target", default=None,
                        help="CPU target (a file under firmware_c/cmake/, see --list-targets) or 'all' "
                             "(default: the reference target, whose figures are the <key>_* ones, m4_* on the M4)")
    parser.add_argument("--list-targets", action="store_true", help="list the CPU targets and exit")
    parser.add_argument("--compare", type=Path, metavar="BUNDLE",
                        help="a second bundle of another architecture (e.g. an SN-D export): its instructions per "
                        "inference, flash and stack on the same targets, and host C against onnxruntime, beside "
                        "the main bundle's (keys compare_*, a second table)")
    parser.add_argument("--trap-unaligned", action="store_true",
                        help="build the targets for firmware that traps unaligned access (-DSLIPEST_TRAP_UNALIGNED=ON: "
                        "no unaligned loads, the portable hidden loop; ARMv7-M targets only): what that costs")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def run(args: argparse.Namespace) -> int:
    if args.list_targets:
        print(json.dumps(list_targets()) if args.json else targets_text())
        return 0
    result = bench(args.bundle, args.build_dir, args.iterations, args.target, args.compare, args.trap_unaligned,
                   progress=not args.json and sys.stderr.isatty())
    print(json.dumps(result) if args.json else format_result(result, reference().key))
    return 0
