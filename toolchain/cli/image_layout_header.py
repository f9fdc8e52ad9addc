"""`python -m fleetlab.cli.image_layout_header [FILE]`: the maintainer's command that regenerates the model image's
C layout header (`firmware_c/include/slipest_image_layout.h`, or FILE) from `fleetlab.export.image_layout`.

Not a `fleetlab` subcommand: the header is committed, and tests/test_export_image.py checks that it is what the
layout description generates; run this after changing the layout.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fleetlab.export.image_layout import c_header
from ..paths import repo_root


def layout_header_path() -> Path:
    """Where the committed C layout header lives."""
    return repo_root() / "firmware_c" / "include" / "slipest_image_layout.h"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fleetlab.cli.image_layout_header", description=__doc__.splitlines()[0])
    ap.add_argument("file", type=Path, nargs="?", default=None,
                    help="where to write it (default: the committed firmware_c/include/slipest_image_layout.h)")
    args = ap.parse_args(argv)
    path = args.file or layout_header_path()
    path.write_text(c_header(), encoding="utf-8", newline="\n")  # LF on every host: the test compares bytes
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
