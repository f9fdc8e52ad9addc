"""Run import-linter on fleetlab's import layers (the contracts in pyproject.toml).

fleetlab's subpackages live in several top-level folders (pyproject's `package-dir`:
toolchain/ is `fleetlab`, export/ is `fleetlab.export`, ...). import-linter reads one package
folder, so this script first mirrors the installed layout in a temporary folder with
symlinks, then runs `lint-imports` against it. Exit status is lint-imports' own.

    python scripts/lint_imports.py [extra lint-imports options]
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def mirror(dest: Path) -> Path:
    """dest/fleetlab with every package of `package-dir` at its import path; returns dest."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    package_dir: dict[str, str] = config["tool"]["setuptools"]["package-dir"]
    top = dest / "fleetlab"
    top.mkdir(parents=True)
    for entry in (ROOT / package_dir["fleetlab"]).iterdir():
        if entry.name != "__pycache__":
            (top / entry.name).symlink_to(entry)
    for name, folder in package_dir.items():
        if name == "fleetlab":
            continue
        parts = name.split(".")[1:]
        target = top.joinpath(*parts)
        if target.exists() or target.is_symlink():
            raise SystemExit(f"{name}: {target} exists already in toolchain/; cannot mirror {folder}/")
        target.symlink_to(ROOT / folder)
    return dest


def main(argv: list[str]) -> int:
    with tempfile.TemporaryDirectory(prefix="fleetlab-imports-") as tmp:
        tree = mirror(Path(tmp))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        exe = Path(sys.executable).with_name("lint-imports")
        cmd = [str(exe) if exe.exists() else "lint-imports", str(ROOT / "pyproject.toml"), "--no-cache", *argv]
        return subprocess.run(cmd, env=env, cwd=tmp).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
