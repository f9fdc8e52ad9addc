"""The one error type for what a user can fix: a mistake in the input, a missing tool, a missing part of
the installation. `fleetlab` prints its message as one line and exits 2; a bug still shows its traceback.
"""

from __future__ import annotations

import shutil

# Debian package of each host tool fleetlab runs itself (a CPU target's compiler and emulator name theirs in the
# target file, SLIPEST_TARGET_PACKAGES); scripts/apt-packages.txt, what scripts/setup.sh installs, holds every one
# of them (tests/test_cli_errors.py checks it).
DEBIAN_PACKAGES = {
    "cmake": "cmake", "ctest": "cmake", "gcc": "gcc", "gcov": "gcc", "clang": "clang", "doxygen": "doxygen",
    "cppcheck": "cppcheck", "clang-tidy": "clang-tidy", "frama-c": "frama-c-base",
    "arm-none-eabi-gcc": "gcc-arm-none-eabi", "arm-none-eabi-nm": "gcc-arm-none-eabi",  # assure's stack, float checks
}


class FleetlabError(Exception):
    """Something the user can fix; the message says what is wrong and how to fix it, in one line."""


class MissingTool(FleetlabError):
    """An executable fleetlab runs is not on PATH."""

    def __init__(self, tool: str, needed_for: str, package: str | None = None):
        package = package or DEBIAN_PACKAGES.get(tool)
        how = f"`sudo apt-get install {package}`" if package else "your distribution's package"
        super().__init__(f"{tool} not found on PATH ({needed_for} needs it): install it with "
                         f"`bash scripts/setup.sh` in a clone, or {how}")
        self.tool = tool


def need(tool: str, needed_for: str, package: str | None = None) -> str:
    """Full path of `tool`, or MissingTool naming what needs it and how to install it (`package`: its Debian
    package, where DEBIAN_PACKAGES does not know it)."""
    path = shutil.which(tool)
    if path is None:
        raise MissingTool(tool, needed_for, package)
    return path
