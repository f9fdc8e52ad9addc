"""`fleetlab bench KIND`: benchmarks that print their figures (and JSON with --json).

Each kind is a module here, `bench_<kind>.py`, with `add_arguments(parser)` and `run(args) -> int`; the
measurement itself lives next to the code it measures (`fleetlab.data.bench`, `fleetlab.fusion.bench`, ...) and
takes plain arguments. A kind whose measurement needs a package that is not installed (a GPU image without the
CAN stack) is listed and says so when run; the others still work.
"""

from __future__ import annotations

import argparse
import importlib

from ..errors import InputError

KINDS: dict[str, tuple[str, str]] = {
    "data": ("fleetlab.cli.bench_data", "featurisation (raw samples/s) and simulation speed (simulated s per wall s)"),
    "import": ("fleetlab.cli.bench_import", "data import: windows/s from a 10-minute rosbag2 (vs in-memory featurisation, real time)"),
    "attitude": ("fleetlab.cli.bench_attitude", "roll and pitch from the IMU ([attitude] source = \"imu\"): error in "
                 "degrees vs the truth on the simulator's traverses, flat and sloped, Earth and Moon"),
    "fusion": ("fleetlab.cli.bench_fusion", "AcoMerge: batched vs one-ant-at-a-time generation, full-run time"),
    "link": ("fleetlab.cli.bench_link", "host emulation loop over a link: frames/s vs the rover's 150, estimator latency at 50 Hz"),
    "c": ("fleetlab.cli.bench_c", "C estimator: host ns/inference vs onnxruntime and torch, Cortex-M4 cost and size"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="kind", metavar="KIND", required=True)
    for kind, (module, help_text) in KINDS.items():
        p = sub.add_parser(kind, help=help_text, description=help_text)
        p.set_defaults(_bench_module=module)
        try:
            importlib.import_module(module).add_arguments(p)
        except ModuleNotFoundError as e:
            # a kind left out of this build, or one whose third-party package is not installed (a
            # GPU image without the CAN stack still runs `bench fusion`); fleetlab's own imports must work
            if e.name != module and (e.name or "fleetlab").split(".")[0] == "fleetlab":
                raise
            p.set_defaults(_bench_missing=e.name)


def run(args: argparse.Namespace) -> int:
    missing = getattr(args, "_bench_missing", None)
    if missing == args._bench_module:
        raise InputError(f"benchmark {args.kind!r} is not available in this build")
    if missing:
        raise InputError(f"benchmark {args.kind!r} needs the Python package {missing!r}, which is not installed here")
    return importlib.import_module(args._bench_module).run(args)
