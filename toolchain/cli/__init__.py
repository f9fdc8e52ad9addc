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

from ..errors import FleetlabError, InputError, first_line

# exit statuses: bad input 1 and a missing tool or part of the installation 2 (the errors module's types);
# anything else raised is a bug in fleetlab, EX_SOFTWARE of sysexits.h, so that a script can tell them apart
INPUT_EXIT, SETUP_EXIT, INTERNAL_EXIT, INTERRUPTED_EXIT, READER_GONE_EXIT = 1, 2, 70, 130, 141

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
    parser.add_argument("--debug", action="store_true",
                        help="let any error end with its traceback (for a bug report) instead of one line")
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


def _command(argv: list[str]) -> str | None:
    """The subcommand named in `argv`: the first word after the global options (`fleetlab --debug fuse ...`)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = build_parser(_command(argv)).parse_args(argv)
    except FleetlabError as e:  # a subcommand's options could not be set up (e.g. its files are missing)
        if "--debug" in argv:
            raise
        print(f"fleetlab: error: {e}", file=sys.stderr)
        return SETUP_EXIT
    if not getattr(args, "_module", None):
        build_parser().print_help()
        return SETUP_EXIT
    try:
        code = int(importlib.import_module(args._module).run(args) or 0)
        sys.stdout.flush()  # so that a reader gone away (`| head`) is met here, not in the interpreter's exit
        return code
    except BrokenPipeError:
        if not _reader_gone():
            return _failed(args, INPUT_EXIT)  # a pipe other than stdout (an emulator that died): said in one line
        # `fleetlab data info DIR | head`: the reader has what it wanted. Nothing is wrong, so no message;
        # the rest of the output goes nowhere, so that the exit's own flush cannot fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return READER_GONE_EXIT  # 128 + SIGPIPE: what a shell tool stopped by the same closed pipe returns
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("interrupted", file=sys.stderr)
        return INTERRUPTED_EXIT
    except (InputError, OSError):
        # bad input: an option, a file's contents, a path that is not there (OSError names it)
        return _failed(args, INPUT_EXIT)
    except FleetlabError:
        # what the user can fix outside the input (a missing tool, a missing part of the installation)
        return _failed(args, SETUP_EXIT)
    except Exception:  # noqa: BLE001 - every other exception is a bug: one line here, the traceback with --debug
        return _failed(args, INTERNAL_EXIT)


def _failed(args: argparse.Namespace, code: int) -> int:
    """The exception being handled as one line on stderr, and `code`; with --debug, the exception itself."""
    if args.debug:
        raise  # noqa: PLE0704 - called from an except block: re-raises the exception being handled
    error = sys.exc_info()[1]
    if code == INTERNAL_EXIT:
        print(f"fleetlab {args.command}: internal error ({type(error).__name__}: {first_line(error)}); "
              f"rerun with `fleetlab --debug {args.command} ...` for the traceback and report it", file=sys.stderr)
    else:
        print(f"fleetlab {args.command}: error: {error}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
