"""Make fleetlab's imports follow the physical folders: rewrite them, or list the ones that do not.

pyproject's `package-dir` builds one import package, `fleetlab`, out of several top-level folders
(toolchain/ is `fleetlab`, export/ is `fleetlab.export`, ...). A relative import can therefore hop
from one folder into another without saying so: `from ..paths import repo_root` in host_tools/
resolves to toolchain/paths.py. The rule:

  * an import of a module in the SAME top-level folder is relative (`from ..wire import dbc`);
  * an import of a module in ANOTHER top-level folder is absolute (`from fleetlab.paths import ...`).

Only `from X import ...` statements are rewritten (the module part, in place; names, aliases,
comments and line breaks are kept). The rewrite is idempotent and reads the folder mapping from
pyproject.toml each run, so it also covers files and folders added later:

    python scripts/fix_imports.py            rewrite every file that breaks the rule, list them
    python scripts/fix_imports.py --check    list what breaks the rule, exit 1 if anything does

`scripts/lint_imports.py` runs the same check before import-linter.
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_FROM = re.compile(r"from\s+(\.*[\w.]*)\s+import\b")


@dataclass(frozen=True)
class Finding:
    path: Path  # relative to the repository root
    line: int
    col: int
    old: str  # the module part as written
    new: str  # what the rule asks for

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: from {self.old} import -> from {self.new} import"


def package_dirs(root: Path = ROOT) -> dict[str, str]:
    """Import name -> top-level folder, from pyproject's `package-dir`."""
    config = tomllib.loads((root / "pyproject.toml").read_text())
    return dict(config["tool"]["setuptools"]["package-dir"])


def _folder_of(module: str, dirs: dict[str, str]) -> str | None:
    """The top-level folder that holds `module` (longest mapped prefix), or None outside fleetlab."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        name = ".".join(parts[:n])
        if name in dirs:
            return dirs[name]
    return None


def _module_of(path: Path, folder: str, name: str) -> tuple[str, str]:
    """(module name, package name) of the file `path` inside `folder`, mapped to import name `name`."""
    rel = path.relative_to(folder).with_suffix("")
    parts = [name, *rel.parts]
    if parts[-1] == "__init__":
        parts.pop()
        return ".".join(parts), ".".join(parts)
    return ".".join(parts), ".".join(parts[:-1])


def _absolute(node: ast.ImportFrom, package: str) -> str:
    if node.level == 0:
        return node.module or ""
    base = package.split(".")
    if node.level - 1 >= len(base):
        raise ValueError(f"relative import beyond the top package (level {node.level} in {package})")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _relative(target: str, package: str) -> str:
    """`target` written relative to `package` (both absolute dotted names)."""
    t, p = target.split("."), package.split(".")
    common = 0
    while common < min(len(t), len(p)) and t[common] == p[common]:
        common += 1
    return "." * (len(p) - common + 1) + ".".join(t[common:])


def _targets(node: ast.ImportFrom, target: str, dirs: dict[str, str]) -> set[str | None]:
    """Folders the statement reaches: the module's, and each imported name's where it is a module
    mapped to another folder (`from fleetlab import export`)."""
    folders = {_folder_of(target, dirs)}
    for alias in node.names:
        sub = f"{target}.{alias.name}"
        if sub in dirs or any(k.startswith(sub + ".") for k in dirs):
            folders.add(_folder_of(sub, dirs))
    return folders


def scan_file(path: Path, folder: str, name: str, dirs: dict[str, str], root: Path = ROOT) -> list[Finding]:
    _, package = _module_of(path.relative_to(root), folder, name)
    try:
        tree = ast.parse(path.read_text(), filename=str(path))
    except SyntaxError as e:
        raise SystemExit(f"{path.relative_to(root)}:{e.lineno}: cannot parse ({e.msg}); fix it, then re-run") from None
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        target = _absolute(node, package)
        if _folder_of(target, dirs) is None:  # not fleetlab (stdlib, third party)
            continue
        folders = _targets(node, target, dirs)
        wanted = _relative(target, package) if folders == {folder} else target
        written = "." * node.level + (node.module or "")
        if written != wanted:
            found.append(Finding(path.relative_to(root), node.lineno, node.col_offset, written, wanted))
    return found


def scan(root: Path = ROOT) -> list[Finding]:
    """Every `from ... import` in the mapped folders that breaks the folder rule."""
    dirs = package_dirs(root)
    found: list[Finding] = []
    for name, folder in sorted(dirs.items(), key=lambda kv: kv[1]):
        for path in sorted((root / folder).rglob("*.py")):
            rel = path.relative_to(root / folder)
            # a subfolder mapped to its own import name is scanned under that name
            if any(p == "__pycache__" for p in rel.parts):
                continue
            if _folder_of(f"{name}.{'.'.join(rel.parent.parts)}".rstrip("."), dirs) != folder:
                continue
            found += scan_file(path, folder, name, dirs, root)
    return found


def fix(findings: list[Finding], root: Path = ROOT) -> None:
    """Rewrite the module part of each finding's statement, in place."""
    by_file: dict[Path, list[Finding]] = {}
    for f in findings:
        by_file.setdefault(f.path, []).append(f)
    for rel, items in by_file.items():
        path = root / rel
        lines = path.read_text().splitlines(keepends=True)
        for f in items:
            i = f.line - 1
            match = _FROM.match(lines[i], f.col)
            if match is None or match.group(1) != f.old:
                raise SystemExit(f"{f.path}:{f.line}: cannot find 'from {f.old} import' on that line")
            lines[i] = lines[i][: match.start(1)] + f.new + lines[i][match.end(1):]
        path.write_text("".join(lines))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="list what breaks the rule and exit 1; change nothing")
    args = parser.parse_args(argv)
    findings = scan()
    for f in findings:
        print(f)
    if args.check:
        print(f"{len(findings)} import(s) break the folder rule" if findings else "imports follow the folders")
        return 1 if findings else 0
    fix(findings)
    again = scan()
    if again:  # the rewrite must leave nothing behind (idempotence)
        print("\n".join(map(str, again)), file=sys.stderr)
        return 1
    print(f"rewrote {len(findings)} import(s) in {len({f.path for f in findings})} file(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
