"""The import layers of pyproject.toml hold (`lint-imports`, no ignored imports), and the
check does fail on an upward import."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "lint_imports.py"


def _lint(tree: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("lint-imports")
    env = dict(os.environ, PYTHONPATH=str(tree))
    return subprocess.run([str(exe), str(REPO / "pyproject.toml"), "--no-cache"], env=env, cwd=tree,
                          capture_output=True, text=True)


def _mirror(tmp_path: Path) -> Path:
    spec = importlib.util.spec_from_file_location("lint_imports", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.mirror(tmp_path / "tree")


def test_contracts_have_no_ignored_imports():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]
    kinds = {c["type"] for c in config["contracts"]}
    assert {"layers", "acyclic_siblings"} <= kinds
    assert not any("ignore_imports" in c for c in config["contracts"])


def test_import_layers_are_kept():
    r = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


def test_an_upward_import_breaks_the_contract(tmp_path):
    tree = _mirror(tmp_path)
    models = tree / "fleetlab" / "models"
    real = models.resolve()
    models.unlink()  # a real folder of links instead of the linked folder, so the probe stays out of the repo
    models.mkdir()
    for entry in real.iterdir():
        if entry.name != "__pycache__":
            (models / entry.name).symlink_to(entry)
    (models / "upward_probe.py").write_text("from fleetlab.evaluation import metrics  # models -> evaluation\n")
    r = _lint(tree)
    assert r.returncode != 0
    assert "fleetlab.models is not allowed to import fleetlab.evaluation" in r.stdout


def _tree_with_crossing_imports(tmp_path: Path) -> Path:
    """A copy of the folder mapping and the two scripts, with modules that break the folder rule."""
    root = tmp_path / "repo"
    (root / "scripts").mkdir(parents=True)
    for name in ("fix_imports.py", "lint_imports.py"):
        (root / "scripts" / name).write_text((REPO / "scripts" / name).read_text())
    (root / "pyproject.toml").write_text((REPO / "pyproject.toml").read_text())
    files = {
        "toolchain/__init__.py": "",
        "toolchain/paths.py": "A = 1\n",
        "toolchain/cli/__init__.py": "",
        "toolchain/cli/run.py": ("from fleetlab.paths import A  # same folder, written absolute\n"
                                 "from .. import export\n"
                                 "from fleetlab import paths as p\n"),
        "host_tools/__init__.py": "",
        "host_tools/b.py": "C = 2\n",
        "host_tools/wire/__init__.py": "",
        "host_tools/wire/codec.py": ("def f():\n"
                                     "    from ...paths import (\n"
                                     "        A,  # toolchain/paths.py, not host_tools/\n"
                                     "    )\n"
                                     "    from fleetlab.host_tools.b import C\n"
                                     "    from ..b import C as D; from fleetlab.export import x\n"
                                     "    return A, C, D, x\n"),
        "export/__init__.py": "x = 3\n",
    }
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def test_folder_rule_is_checked_and_fixed_idempotently(tmp_path):
    root = _tree_with_crossing_imports(tmp_path)
    fix = [sys.executable, str(root / "scripts" / "fix_imports.py")]
    check = subprocess.run([*fix, "--check"], capture_output=True, text=True)
    assert check.returncode == 1
    assert "host_tools/wire/codec.py:2: from ...paths import -> from fleetlab.paths import" in check.stdout
    assert "toolchain/cli/run.py:1: from fleetlab.paths import -> from ..paths import" in check.stdout
    assert "5 import(s) break the folder rule" in check.stdout
    lint = subprocess.run([sys.executable, str(root / "scripts" / "lint_imports.py")], capture_output=True, text=True)
    assert lint.returncode == 1 and "run python scripts/fix_imports.py" in lint.stdout

    assert subprocess.run(fix, capture_output=True, text=True).returncode == 0
    codec = (root / "host_tools/wire/codec.py").read_text()
    assert "from fleetlab.paths import (\n        A,  # toolchain/paths.py" in codec
    assert "    from ..b import C\n" in codec and "from ..b import C as D; from fleetlab.export import x" in codec
    run = (root / "toolchain/cli/run.py").read_text()
    assert run == "from ..paths import A  # same folder, written absolute\nfrom fleetlab import export\nfrom .. import paths as p\n"

    before = {p: p.read_text() for p in root.rglob("*.py")}
    again = subprocess.run(fix, capture_output=True, text=True)
    assert again.returncode == 0 and "rewrote 0 import(s)" in again.stdout
    assert {p: p.read_text() for p in root.rglob("*.py")} == before
    assert subprocess.run([*fix, "--check"], capture_output=True, text=True).returncode == 0


def test_the_tree_follows_the_folder_rule():
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "fix_imports.py"), "--check"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout


# Options are parsed in toolchain/cli/ only: a library module takes plain arguments. The one exception, and why.
ARGPARSE_OUTSIDE_CLI = {
    "dbc/layout.py": "run by CMake as a script, without fleetlab installed",
}


def _imports_argparse(path: Path) -> bool:
    import ast

    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "argparse" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "argparse":
            return True
    return False


def test_no_module_outside_the_cli_package_imports_argparse():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())
    folders = config["tool"]["setuptools"]["package-dir"].values()
    users = {str(p.relative_to(REPO)) for f in folders for p in (REPO / f).rglob("*.py")
             if "__pycache__" not in p.parts and _imports_argparse(p)}
    outside = {u for u in users if not u.startswith("toolchain/cli/")}
    assert outside == ARGPARSE_OUTSIDE_CLI.keys(), f"argparse outside toolchain/cli/: {sorted(outside - ARGPARSE_OUTSIDE_CLI.keys())}"


def test_no_test_module_imports_another():
    """What several test files share lives in conftest.py (fixtures) or a helper module (functions, paths):
    a test file importing another runs that file's module-level code and ties the two files together."""
    import ast

    tests = REPO / "tests"
    names = {p.stem for p in tests.glob("test_*.py")}
    crossing = []
    for path in sorted(tests.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            imported = ([a.name for a in node.names] if isinstance(node, ast.Import)
                        else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            crossing += [f"{path.name}:{node.lineno} imports {m}" for m in imported if m.split(".")[0] in names]
    assert names and not crossing, "\n".join(crossing)
