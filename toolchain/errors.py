"""The error types for what a user can fix: a mistake in the input (`InputError`, exit 1), a missing tool or
part of the installation (`FleetlabError`, exit 2). `fleetlab` prints their message as one line. Any other
exception is a bug: one "internal error" line (exit 70), and its traceback with `fleetlab --debug`.
"""

from __future__ import annotations


def first_line(error: BaseException) -> str:
    """The first line of an exception's message, or its type's name where it has none. torch's and
    python-can's messages run to paragraphs; fleetlab's errors and warnings are one line."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


class FleetlabError(Exception):
    """Something the user can fix; the message says what is wrong and how to fix it, in one line."""


class InputError(FleetlabError, ValueError):
    """A mistake in what the user gave: an option's value, a file's contents, a dataset that cannot serve the
    request. Raised on purpose by every layer where it checks its input; `fleetlab` exits 1 with the line.
    A ValueError too, so that a caller that tries an input and falls back (`except ValueError`) still can."""


class MissingTool(FleetlabError):
    """An executable fleetlab runs is not on PATH; `package` is its Debian package (fleetlab.system_tools
    finds it in scripts/apt-packages.txt), None where the list does not name the tool."""

    def __init__(self, tool: str, needed_for: str, package: str | None = None):
        how = f"`sudo apt-get install {package}`" if package else "your distribution's package"
        super().__init__(f"{tool} not found on PATH ({needed_for} needs it): install it with "
                         f"`bash scripts/setup.sh` in a clone, or {how}")
        self.tool, self.command, self.package = tool, tool, package

