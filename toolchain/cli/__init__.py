"""`fleetlab` command line: one subcommand per everyday task.

The CLI layer sits on top of every library package. Each subcommand is a thin module
(`fleetlab.cli.<name>`) providing `add_arguments(parser)`
and `run(args) -> int`; `COMMANDS` below is the one table of subcommands. A module is
imported only when its subcommand runs, so `fleetlab --help` stays fast. Shared option
groups (data folder, seeds, budgets, jobs, JSON output) are in `options`.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import select
import sys

from ..errors import FleetlabError

# name -> (module, one-line help): the one table of subcommands
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("fleetlab.cli.simulate", "simulate rover telemetry and write window CSVs (built-in fleet scenario)"),
    "data": ("fleetlab.cli.data", "import your rover's logs (import: rosbag2 or time-series CSV), inspect a dataset "
             "folder (info) or compare two of them (compare: realism report)"),
    "fuse": ("fleetlab.cli.fuse", "train the experts and fuse them into one model (AcoMerge or any registered method)"),
    "evaluate": ("fleetlab.cli.evaluate", "Monte Carlo cross-validation of AcoMerge against the paper's baselines"),
    "export": ("fleetlab.cli.export", "export a model to ONNX, fixed-point C headers and test vectors"),
    "emulate": ("fleetlab.cli.emulate", "run the C estimator in the host emulation loop and compare bit for bit"),
    "stream": ("fleetlab.cli.stream", "stream telemetry or features to the estimator over CAN or serial"),
    "monitor": ("fleetlab.cli.monitor", "watch slip estimates and status frames on a CAN bus"),
    "upload": ("fleetlab.cli.upload", "send a model image to a running CANopen node (SDO block download) and activate it"),
    "bench": ("fleetlab.cli.bench", "benchmarks: featurisation and simulation, fusion, C inference"),
    "assure": ("fleetlab.cli.assure", "flight-software evidence: MISRA, analysers, stack, coverage, fuzzing report"),
    "c-sources": ("fleetlab.cli.c_sources", "copy the slipest C library (sources, headers, CMake files) out for a firmware build"),
    "demo": ("fleetlab.cli.demo", "the whole pipeline on built-in defaults, ending in a report"),
}


def _available() -> dict[str, tuple[str, str]]:
    """Commands whose module is installed (a command lands with its module)."""
    found = {}
    for name, entry in COMMANDS.items():
        try:
            if importlib.util.find_spec(entry[0]) is not None:
                found[name] = entry
        except ModuleNotFoundError:
            pass
    return found


class _Parser(argparse.ArgumentParser):
    """Options by their full names only. With argparse's abbreviations, a mistyped `export --model FILE`
    was taken as `--model-version FILE` and refused as "invalid int value"; the subcommands' parsers
    are of this class too (add_subparsers makes its parsers of the parent's class)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)


def build_parser(selected: str | None = None) -> argparse.ArgumentParser:
    """The parser; only the `selected` subcommand's module is imported for its options."""
    from .. import __version__

    parser = _Parser(
        prog="fleetlab",
        description="Lunar-rover wheel-slip estimation: simulate or load fleet data, fuse expert "
        "models with AcoMerge, export to fixed-point C, and verify the C estimator bit for bit.",
        epilog="Run 'fleetlab COMMAND --help' for the options of one command.",
    )
    parser.add_argument("--version", action="version", version=f"fleetlab {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in _available().items():
        p = sub.add_parser(name, help=help_text, description=help_text[0].upper() + help_text[1:] + ".")
        p.set_defaults(_module=module)
        if name == selected:
            importlib.import_module(module).add_arguments(p)
    return parser


def _reader_gone() -> bool:
    """True when the process reading fleetlab's stdout has closed its end of the pipe: polling the write end
    reports an error then (Linux, macOS). A failed write drops its bytes, so writing again cannot tell."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll() here, or stdout is no file
        return False


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = build_parser(argv[0] if argv else None).parse_args(argv)
    except FleetlabError as e:  # a subcommand's options could not be set up (e.g. its files are missing)
        print(f"fleetlab: error: {e}", file=sys.stderr)
        return 2
    if not getattr(args, "_module", None):
        build_parser().print_help()
        return 2
    try:
        code = int(importlib.import_module(args._module).run(args) or 0)
        sys.stdout.flush()  # so that a reader gone away (`| head`) is met here, not in the interpreter's exit
        return code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except FleetlabError as e:
        # what the user can fix (a missing tool, a missing part of the installation): one line, exit 2
        print(f"fleetlab {args.command}: error: {e}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as e:
        if isinstance(e, BrokenPipeError) and _reader_gone():
            # `fleetlab data info DIR | head`: the reader has what it wanted. Nothing is wrong, so no message;
            # the rest of the output goes nowhere, so that the exit's own flush cannot fail again.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141  # 128 + SIGPIPE: what a shell tool stopped by the same closed pipe returns
        # Bad input (a pipe other than stdout breaking too): one clear line naming what is wrong, no
        # traceback. Bugs still show theirs.
        print(f"fleetlab {args.command}: error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
