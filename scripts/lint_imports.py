"""Check fleetlab's imports: the folder rule, then import-linter's layers (pyproject.toml).

1. The folder rule (scripts/fix_imports.py): a relative import stays inside its top-level folder;
   a module in another folder is imported as `fleetlab.…`. `python scripts/fix_imports.py` fixes it.
2. The layers and acyclic contracts of pyproject.toml, by import-linter. fleetlab's subpackages
   live in several top-level folders (pyproject's `package-dir`: toolchain/ is `fleetlab`,
   export/ is `fleetlab.export`, ...), and import-linter (grimp) finds a package's modules by
   walking the one folder its top package is in, so plain `lint-imports` on an editable install
   misses export/, host_tools/, dbc/ and canopen_od/ ("module fleetlab.host_tools does not exist").
   This script therefore mirrors the installed layout in a temporary folder with symlinks and runs
   `lint-imports` against it.

    python scripts/lint_imports.py [extra lint-imports options]

Exit status: 1 if the folder rule is broken, else lint-imports' own.
"""

from __future__ import annotations

import importlib.util
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


def folder_rule_findings() -> list:
    """What scripts/fix_imports.py would rewrite (loaded by path: scripts/ is not a package)."""
    spec = importlib.util.spec_from_file_location("fix_imports", ROOT / "scripts" / "fix_imports.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("fix_imports", module)  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module.scan(ROOT)


def main(argv: list[str]) -> int:
    findings = folder_rule_findings()
    for finding in findings:
        print(finding)
    if findings:
        print(f"{len(findings)} import(s) cross a folder relatively or stay in it absolutely; "
              "run python scripts/fix_imports.py")
        return 1
    print("folder rule: every relative import stays in its folder, every cross-folder import is fleetlab.…")
    with tempfile.TemporaryDirectory(prefix="fleetlab-imports-") as tmp:
        tree = mirror(Path(tmp))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        exe = Path(sys.executable).with_name("lint-imports")
        cmd = [str(exe) if exe.exists() else "lint-imports", str(ROOT / "pyproject.toml"), "--no-cache", *argv]
        return subprocess.run(cmd, env=env, cwd=tmp).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
