"""`fleetlab c-sources --out DIR`: the slipest C library for a firmware build, from the clone or the wheel.

DIR gets the C source tree (CMakeLists.txt, firmware_c/ with the sources, public headers, CPU target files
and the example bundle, the DBC and the generators the build runs); a firmware project takes it with
`add_subdirectory(DIR slipest EXCLUDE_FROM_ALL)` and links `slipest` (docs/integrating_slipest.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..c_sources import copy_tree
from ..errors import FleetlabError
from ..paths import repo_root

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="folder to write the C source tree into (created; "
                   "must be empty or absent)")


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FleetlabError(f"{out}: exists and is not an empty folder (c-sources writes a fresh copy)")
    files = copy_tree(repo_root(), out)
    print(f"{len(files)} files written to {out}")
    print("In your firmware's CMakeLists.txt:")
    print(f'  set(SLIPEST_BUNDLE "/path/to/your/bundle" CACHE PATH "")   # default: {out}/firmware_c/bundles/example')
    print(f"  add_subdirectory({out.resolve()} slipest EXCLUDE_FROM_ALL)")
    print("  target_link_libraries(your_firmware PRIVATE slipest)")
    print(f"The build generates the CAN codec with cantools: configure with -DPython3_EXECUTABLE={sys.executable}")
    return 0
