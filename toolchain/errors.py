"""The one error type for what a user can fix: a mistake in the input, a missing tool, a missing part of
the installation. `fleetlab` prints its message as one line and exits 2; a bug still shows its traceback.
"""

from __future__ import annotations


def first_line(error: BaseException) -> str:
    """The first line of an exception's message, or its type's name where it has none. torch's and
    python-can's messages run to paragraphs; fleetlab's errors and warnings are one line."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


class FleetlabError(Exception):
    """Something the user can fix; the message says what is wrong and how to fix it, in one line."""


class MissingTool(FleetlabError):
    """An executable fleetlab runs is not on PATH; `package` is its Debian package (fleetlab.system_tools
    finds it in scripts/apt-packages.txt), None where the list does not name the tool."""

    def __init__(self, tool: str, needed_for: str, package: str | None = None):
        how = f"`sudo apt-get install {package}`" if package else "your distribution's package"
        super().__init__(f"{tool} not found on PATH ({needed_for} needs it): install it with "
                         f"`bash scripts/setup.sh` in a clone, or {how}")
        self.tool, self.command, self.package = tool, tool, package

