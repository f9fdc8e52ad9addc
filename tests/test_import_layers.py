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
