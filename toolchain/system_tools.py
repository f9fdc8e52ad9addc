"""The system commands fleetlab calls (compilers, QEMU, analysers) and the Debian package of each.

The one list is scripts/apt-packages.txt: scripts/setup.sh installs its packages, and the words after a
package name the commands of it that the builds and tests call. A missing command is reported with its
package, so a package dropped from the list (or renamed by a distribution release) is named at once.
"""

from __future__ import annotations

import shutil
from functools import lru_cache

from .paths import repo_root

INSTALL_HINT = "scripts/setup.sh installs it (scripts/apt-packages.txt)"


class MissingTool(RuntimeError):
    """A command is not on PATH; `package` is the Debian package that provides it (or "unknown")."""

    def __init__(self, command: str, package: str):
        self.command, self.package = command, package
        super().__init__(f"{command} not found on PATH: install the Debian package {package} ({INSTALL_HINT})")


@lru_cache(maxsize=1)
def packages() -> dict[str, str]:
    """command -> package, from scripts/apt-packages.txt."""
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


def need(command: str) -> str:
    """Full path of `command`, or MissingTool naming its package."""
    path = shutil.which(command)
    if path is None:
        raise MissingTool(command, package_of(command))
    return path
