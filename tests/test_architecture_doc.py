"""docs/architecture.md stays true: every file, folder and module it names exists, its layer list is the
import-linter contract of pyproject.toml, and what it says of `main` holds (issue 43, item 7)."""

from __future__ import annotations

import ast
import importlib.util
import os
import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "architecture.md"
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
PACKAGE_DIRS = list(PYPROJECT["tool"]["setuptools"]["package-dir"].values())

# a path as the doc writes one in backticks: a file by its extension, or a folder by its trailing slash
PATH = re.compile(r"(?:[\w.-]+/)*[\w.-]*\w\.(?:py|c|h|md|toml|cmake|dbc|txt|json|sh|img|npz|bin|onnx)|(?:[\w.-]+/)+")
MODULE = re.compile(r"fleetlab(?:\.\w+)+")
# named by the doc, made by the build: they exist in a build folder, never in the tree
GENERATED = {"slipest_co_od.c": "canopen_od/generate.py writes it at build time",
             "slipest_co_od.h": "canopen_od/generate.py writes it at build time"}
# library modules with a `main` of their own, and why (the doc says the same)
MAIN_OUTSIDE_CLI = {"dbc/layout.py": "CMake runs it as a script, without fleetlab installed",
                    "canopen_od/generate.py": "CMake runs it as a script, without fleetlab installed"}
SKIPPED_DIRS = {".git", ".venv", "build", "__pycache__", "node_modules"}


def _named() -> tuple[set[str], set[str]]:
    """The paths and the fleetlab module names the doc writes in backticks."""
    paths, modules = set(), set()
    for span in re.findall(r"`([^`\n]+)`", DOC.read_text()):
        for token in re.split(r"[\s,;()]+", span):
            token = token.rstrip(".:")
            if token.startswith("../"):  # outside the repository (the starting brief): nothing to check here
                continue
            if MODULE.fullmatch(token):  # first: `fleetlab.dbc` is a module, not a .dbc file
                modules.add(token)
            elif PATH.fullmatch(token):
                paths.add(token)
    return paths, modules


def _tree_names() -> set[str]:
    names = set()
    for _, dirs, files in os.walk(REPO):
        dirs[:] = [d for d in dirs if d not in SKIPPED_DIRS]
        names.update(files)
        names.update(f"{d}/" for d in dirs)
    return names


def _exists(path: str, tree: set[str]) -> bool:
    """A path with a folder in it, from the repository root or from one of the top-level folders (the doc's
    tables name `data/` in the toolchain row, `include/` in the firmware row); a bare name, anywhere in the tree."""
    if "/" in path.rstrip("/"):
        return any((REPO / base / path).exists() for base in ["", *PACKAGE_DIRS, "firmware_c"])
    return path in tree


def test_every_path_the_doc_names_exists():
    paths, _ = _named()
    tree = _tree_names()
    assert len(paths) > 50  # the doc's paths were found, not a few
    missing = sorted(p for p in paths if p not in GENERATED and not _exists(p, tree))
    assert not missing, f"docs/architecture.md names paths that do not exist: {missing}"


def test_every_module_the_doc_names_exists():
    _, modules = _named()
    assert modules
    missing = sorted(m for m in modules if importlib.util.find_spec(m) is None)
    assert not missing, f"docs/architecture.md names modules that do not exist: {missing}"


def _doc_layers() -> list[str]:
    """The layer column of the code block under "## Layers" (the description follows two spaces or more)."""
    section = DOC.read_text().split("\n## Layers\n", 1)[1]
    block = section.split("```\n", 2)[1]
    return [" ".join(re.split(r"\s{2,}", line.strip())[0].split()) for line in block.splitlines() if line.strip()]


def test_the_doc_layers_are_the_import_contract():
    contract = next(c for c in PYPROJECT["tool"]["importlinter"]["contracts"] if c["type"] == "layers")
    assert _doc_layers() == [" ".join(layer.split()) for layer in contract["layers"]]


def _has_main(tree: ast.Module) -> bool:
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "main":
            return True
        if isinstance(node, ast.If) and "__main__" in ast.unparse(node.test) and "__name__" in ast.unparse(node.test):
            return True
    return False


def test_no_library_module_has_a_main():
    """Commands are `fleetlab` subcommands or modules of toolchain/cli/ (`python -m fleetlab.cli.…`): a library
    module takes plain arguments and is never run as a script, but for the two CMake runs without fleetlab."""
    found = set()
    for base in PACKAGE_DIRS:
        for path in (REPO / base).rglob("*.py"):
            rel = str(path.relative_to(REPO))
            if "__pycache__" in path.parts or rel.startswith("toolchain/cli/"):
                continue
            if _has_main(ast.parse(path.read_text())):
                found.add(rel)
    assert found == MAIN_OUTSIDE_CLI.keys(), f"a `main` outside toolchain/cli/: {sorted(found - MAIN_OUTSIDE_CLI.keys())}"
