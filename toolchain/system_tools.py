"""The system commands fleetlab calls (compilers, QEMU, analysers) and the Debian package of each.

The one list is scripts/apt-packages.txt: scripts/setup.sh installs its packages, and the words after a
package name the commands of it that the builds and tests call. A missing command is reported with its
package, so a package dropped from the list (or renamed by a distribution release) is named at once.
"""

from __future__ import annotations

import shutil
from functools import lru_cache

from .errors import MissingTool
from .paths import repo_root

__all__ = ["MissingTool", "INSTALL_HINT", "need", "package_of", "packages"]
INSTALL_HINT = "scripts/setup.sh installs it (scripts/apt-packages.txt)"


@lru_cache(maxsize=1)
def packages() -> dict[str, str]:
    """command -> package, from scripts/apt-packages.txt (the wheel carries it in its C tree too)."""
    out = {}
    for line in (repo_root() / "scripts" / "apt-packages.txt").read_text().splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        for command in words[1:]:
            out[command] = words[0]
    return out


def package_of(command: str) -> str:
    return packages().get(command, "unknown (add it to scripts/apt-packages.txt)")


def need(command: str, needed_for: str = "fleetlab") -> str:
    """Full path of `command`, or errors.MissingTool naming what needs it and its Debian package."""
    path = shutil.which(command)
    if path is None:
        raise MissingTool(command, needed_for, package_of(command))
    return path
