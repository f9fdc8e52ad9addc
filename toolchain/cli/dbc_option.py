"""`--dbc FILE`, the option of the commands that talk CAN (emulate, stream, monitor): the rover's own copy of the
DBC, other frame IDs, the same layout (fleetlab.host_tools.wire.dbc checks it and makes it the one in use).

Apart from `options` so that these commands do not import torch to build their parsers."""

from __future__ import annotations

import argparse
from pathlib import Path

from fleetlab.host_tools.wire.dbc import DBC_ENV, dbc_path, use_dbc


def add_dbc_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dbc", type=Path, default=None, metavar="FILE",
                        help=f"CAN database with the rover's own frame IDs (default: ${DBC_ENV} or "
                             "dbc/slipest.dbc); must keep the layout of dbc/slipest.dbc. "
                             "A started emulator is built against it")


def apply_dbc_option(args: argparse.Namespace) -> Path:
    """Select the DBC named by `--dbc` (if given); returns the DBC in use."""
    return use_dbc(args.dbc) if getattr(args, "dbc", None) is not None else dbc_path()
