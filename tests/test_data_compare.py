"""`fleetlab data compare`: the realism statistics on small synthetic tables, and the command on the real files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from fleetlab.data.compare import (
    GRAVITY_PRESENT, GRAVITY_REMOVED, acceleration_convention, class_mix, compare_statistics, lag1_autocorrelation,
    persistence, run_lengths,
)
from fleetlab.data.contracts import FEATURE_NAMES, N_FEATURES
from fleetlab.data.csvio import WindowTable, write_windows_csv
from fleetlab.data.dataset import load_dataset, write_manifest


def _table(slip_pct, acc_z=0.0, seed=0) -> WindowTable:
    slip_pct = np.asarray(slip_pct, dtype=np.float64)
    n = len(slip_pct)
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, N_FEATURES))
    x[:, FEATURE_NAMES.index("feat_acc_z_mean")] = acc_z + 0.01 * rng.normal(size=n)
    label = np.digitize(np.abs(slip_pct) / 100.0, [0.3 + 1e-12, 0.6 + 1e-12]).astype(np.int64)
    d_cmd = np.full(n, 0.4)
    return WindowTable(features=x, d_actual=d_cmd * (1 - slip_pct / 100), d_commanded=d_cmd, slip_pct=slip_pct,
                       label=label, n_samples=np.full(n, 100), duration_s=np.full(n, 2.0))


def test_run_lengths_and_class_mix():
    t = _table([10, 10, 10, 40, 40, 70, 10, 10])
    assert run_lengths(t.label).tolist() == [3, 2, 1, 2]
    assert class_mix(t) == pytest.approx([5 / 8, 2 / 8, 1 / 8])
    assert run_lengths(np.array([], dtype=np.int64)).tolist() == []


def test_lag1_autocorrelation_separates_persistent_from_white_slip():
    rng = np.random.default_rng(1)
    white = rng.normal(size=2000)
    ar = np.zeros(2000)
    for i in range(1, 2000):
        ar[i] = 0.95 * ar[i - 1] + rng.normal()
    assert abs(lag1_autocorrelation(white)) < 0.08
    assert 0.9 < lag1_autocorrelation(ar) < 0.99
    alternating = np.tile([0.0, 1.0], 50)
    assert lag1_autocorrelation(alternating) == pytest.approx(-0.99, abs=0.01)
    assert lag1_autocorrelation(np.ones(10)) is None and lag1_autocorrelation(np.array([1.0, 2.0])) is None


def test_persistence_never_crosses_a_traverse_boundary():
    # Each file alone is a single constant run; glued together they would alternate classes.
    a, b = _table([10.0] * 6), _table([70.0] * 4)
    p = persistence([a, b])
    assert p["mean_run_length"] == pytest.approx(5.0)  # runs 6 and 4, not one run per file pair
    assert p["files_with_autocorr"] == 0 and p["slip_lag1_autocorr_mean"] is None  # constant files: no variance


def test_acceleration_convention_detects_gravity():
    assert acceleration_convention(_table([10] * 20, acc_z=9.81))["convention"] == GRAVITY_PRESENT
    assert acceleration_convention(_table([10] * 20, acc_z=1.62))["convention"] == GRAVITY_PRESENT
    assert acceleration_convention(_table([10] * 20, acc_z=0.02))["convention"] == GRAVITY_REMOVED


def _folder(root, acc_z, seed):
    root.mkdir()
    files = {}
    rng = np.random.default_rng(seed)
    for role, n_files in (("earth", 2), ("fleet_a", 1), ("target", 3)):
        for k in range(n_files):
            name = f"{role}_{k}.csv"
            write_windows_csv(root / name, _table(rng.uniform(0, 90, 30), acc_z=acc_z, seed=seed + k))
            files[name] = {"role": role}
    write_manifest(root, files, {})
    return root


def test_compare_statistics_side_by_side(tmp_path):
    a = load_dataset(_folder(tmp_path / "a", 0.0, 0))
    b = load_dataset(_folder(tmp_path / "b", 9.81, 1))
    rep = compare_statistics(a, b)
    assert set(rep["a"]["roles"]) == set(rep["b"]["roles"]) == {"earth", "fleet_a", "target"}
    assert rep["a"]["roles"]["target"]["rows"] == 90 and rep["a"]["roles"]["target"]["files"] == 3
    assert rep["a"]["roles"]["earth"]["acceleration"]["convention"] == GRAVITY_REMOVED
    assert rep["b"]["roles"]["earth"]["acceleration"]["convention"] == GRAVITY_PRESENT
    assert sum(rep["b"]["roles"]["target"]["class_mix"]) == pytest.approx(1.0)


def _fleetlab(*args):
    return subprocess.run([sys.executable, "-m", "fleetlab.cli", *args], capture_output=True, text=True)


def test_compare_command_statistics_only_and_bad_input(tmp_path):
    a, b = _folder(tmp_path / "a", 0.0, 0), _folder(tmp_path / "b", 9.81, 1)
    r = _fleetlab("data", "compare", str(a), str(b), "--no-learnability", "--plot", str(tmp_path / "c.png"))
    assert r.returncode == 0, r.stderr
    assert "slip lag-1 autocorr" in r.stdout and "gravity present" in r.stdout and "gravity removed" in r.stdout
    assert (tmp_path / "c.png").stat().st_size > 5_000
    r = _fleetlab("data", "compare", str(a), str(tmp_path / "missing"), "--no-learnability")
    assert r.returncode == 1 and "not a directory" in r.stderr and "Traceback" not in r.stderr


def test_compare_real_files_with_themselves(real_data_dir):
    """On the real files: gravity removed everywhere, the target's known class counts, persistent slip,
    and a learnability report whose two sides agree exactly (same data, same seeds)."""
    r = _fleetlab("data", "compare", str(real_data_dir), str(real_data_dir), "--json", "--runs", "1")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    target = rep["a"]["roles"]["target"]
    assert target["rows"] == 1367
    assert target["class_mix"] == pytest.approx([888 / 1367, 271 / 1367, 208 / 1367])
    assert all(role["acceleration"]["convention"] == GRAVITY_REMOVED for role in rep["a"]["roles"].values())
    assert 0.9 < target["persistence"]["slip_lag1_autocorr_mean"] < 0.99
    assert 8 <= target["persistence"]["mean_run_length"] <= 22
    la, lb = rep["learnability"]["a"], rep["learnability"]["b"]
    assert la == lb
    assert len(la["loto_bacc_per_traverse"]) == 5
    # Learnable but far from solved on unseen traverses; the Earth expert alone is worse still.
    assert 0.5 < la["loto_bacc_mean"] < 0.85
    assert 0.33 < la["earth_zero_shot_bacc"] < la["loto_bacc_mean"]
