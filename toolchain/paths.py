"""Where things are: the C source tree, the committed example bundle, the build root.

The one home of these locations; every other module asks here, when it needs them (never at import, so
that importing fleetlab touches no file). The C source tree is the clone for a clone or an editable
install, else the copy an installed wheel carries in the package (`fleetlab/c_tree`, the same layout:
CMakeLists.txt, firmware_c/, dbc/, canopen_od/, export/c/). Builds go to `build/` in a clone, else to a
per-user cache folder.
"""

from __future__ import annotations

import hashlib
import os
from functools import cache
from pathlib import Path

from .errors import FleetlabError

BUILD_ROOT_ENV = "FLEETLAB_BUILD_ROOT"
PACKAGED_TREE = "c_tree"  # the wheel's copy of the C source tree, inside the package (setup.py writes it)


@cache
def _tree() -> tuple[Path, bool]:
    """(source tree, is a clone)."""
    package = Path(__file__).resolve().parent
    clone = package.parent  # toolchain/ sits directly under the clone's root
    if (clone / "CMakeLists.txt").is_file() and (clone / "firmware_c").is_dir():
        return clone, True
    packaged = package / PACKAGED_TREE
    if (packaged / "CMakeLists.txt").is_file():
        return packaged, False
    raise FleetlabError(f"{package}: neither a fleetlab clone nor a wheel with its C sources ({PACKAGED_TREE}/); "
                        "reinstall fleetlab from its wheel or clone")


def repo_root() -> Path:
    """The C source tree: the clone, or the wheel's packaged copy (same layout)."""
    return _tree()[0]


def in_clone() -> bool:
    """True for a clone (or an editable install of one), False for an installed wheel."""
    return _tree()[1]


def default_bundle() -> Path:
    """The committed example export bundle (also CMake's SLIPEST_BUNDLE default)."""
    return repo_root() / "firmware_c" / "bundles" / "example"


def cache_dir() -> Path:
    """The per-user cache folder: `$XDG_CACHE_HOME/fleetlab`, else `~/.cache/fleetlab`."""
    base = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(base) if base else Path.home() / ".cache") / "fleetlab"


def build_root() -> Path:
    """Where our build dirs go: `$FLEETLAB_BUILD_ROOT`; else `build/` in a clone; else, for a wheel, a folder
    of the user's cache keyed by fleetlab's version and where it is installed (CMake ties a build folder
    to one source tree)."""
    env = os.environ.get(BUILD_ROOT_ENV, "").strip()
    if env:
        return Path(env).resolve()
    if in_clone():
        return repo_root() / "build"
    from . import __version__

    key = hashlib.sha256(str(repo_root()).encode()).hexdigest()[:10]
    return cache_dir() / f"build-{__version__}-{key}"
