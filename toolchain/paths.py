"""Where things are: the source tree, the committed example bundle, the build root, the DBC.

The one home of these locations; every other module asks here. The source-tree paths only
exist in a clone (an editable install): commands that build C code need the tree and say so.
"""

from __future__ import annotations

import os
from pathlib import Path

# toolchain/ (this package) sits directly under the repository root.
_PACKAGE_DIR = Path(__file__).resolve().parent
BUILD_ROOT_ENV = "FLEETLAB_BUILD_ROOT"


def repo_root() -> Path:
    """The source tree this package was installed from (editable install: toolchain/..)."""
    root = _PACKAGE_DIR.parent
    if not (root / "CMakeLists.txt").is_file():
        raise OSError(f"{root}: no CMakeLists.txt; building the C estimator needs the fleetlab source tree")
    return root


def default_bundle() -> Path:
    """The committed example export bundle (also CMake's SLIPEST_BUNDLE default)."""
    return repo_root() / "firmware_c" / "bundles" / "example"


def build_root() -> Path:
    """Where our build dirs go: `$FLEETLAB_BUILD_ROOT`, else `build/` in the source tree."""
    env = os.environ.get(BUILD_ROOT_ENV, "").strip()
    return Path(env).resolve() if env else repo_root() / "build"
