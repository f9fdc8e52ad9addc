"""What a test needs from the machine: system commands (with the Debian package of each, from
scripts/apt-packages.txt through fleetlab.system_tools) and the declared Python dependencies.

Outside CI a missing one skips the test, saying what is missing and how to install it. With
FLEETLAB_REQUIRE_TOOLS=1 (.ci/run sets it) it fails the test instead, naming the package: one package
dropped from the list must not quietly remove the evidence the tests give."""

from __future__ import annotations

import importlib
import os
import re
import tomllib
from functools import lru_cache
from pathlib import Path
from types import ModuleType

import pytest

from fleetlab import system_tools

REPO = Path(__file__).resolve().parents[1]
REQUIRE_ENV = "FLEETLAB_REQUIRE_TOOLS"


def tools_required() -> bool:
    return os.environ.get(REQUIRE_ENV, "") not in ("", "0")


def _missing(msg: str) -> None:
    if tools_required():
        pytest.fail(f"{REQUIRE_ENV} is set but {msg}", pytrace=False)
    pytest.skip(msg)


def need_tools(*commands: str) -> list[str]:
    """Full path of each command; a missing one skips (fails under FLEETLAB_REQUIRE_TOOLS) naming its package."""
    missing = []
    paths = []
    for c in commands:
        try:
            paths.append(system_tools.need(c))
        except system_tools.MissingTool as e:
            missing.append(e)
    if missing:
        pkgs = sorted({e.package for e in missing})
        _missing(f"{', '.join(e.command for e in missing)} not found on PATH: install the Debian package"
                 f"{'s' if len(pkgs) > 1 else ''} {', '.join(pkgs)} ({system_tools.INSTALL_HINT})")
    return paths


def need_tool(command: str) -> str:
    return need_tools(command)[0]


@lru_cache(maxsize=1)
def declared_dependencies() -> dict[str, str]:
    """Distribution name (lower case, extras dropped) -> requirement, from pyproject.toml (main + test)."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    reqs = list(project["dependencies"]) + list(project["optional-dependencies"]["test"])
    return {re.match(r"[A-Za-z0-9_.-]+", r)[0].lower(): r for r in reqs}


def need_module(module: str, distribution: str) -> ModuleType:
    """Import a module of a declared dependency; a missing one skips (fails under FLEETLAB_REQUIRE_TOOLS)
    naming the distribution and the install command."""
    req = declared_dependencies().get(distribution.lower())
    assert req is not None, f"{distribution} is not declared in pyproject.toml"
    try:
        return importlib.import_module(module)
    except ImportError as e:
        _missing(f"{module} cannot be imported ({e}): the declared dependency {req!r} is not installed: "
                 "pip install -c requirements.lock -e '.[test]' (scripts/setup.sh)")


def path_without(command: str, folder: Path) -> str:
    """A PATH on which `command` is missing and every other command of the current PATH is found: `folder`
    gets a symbolic link to each other executable (the first of each name, as PATH lookup picks it)."""
    folder.mkdir(parents=True, exist_ok=True)
    for d in os.environ["PATH"].split(os.pathsep):
        if not d or not Path(d).is_dir():
            continue
        for exe in Path(d).iterdir():
            link = folder / exe.name
            if exe.name == command or link.is_symlink() or not (exe.is_file() and os.access(exe, os.X_OK)):
                continue
            link.symlink_to(exe)
    return str(folder)
