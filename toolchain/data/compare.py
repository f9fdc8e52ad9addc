"""Statistics that say how alike two dataset folders are, role by role (`fleetlab data compare`).

Pure statistics of the window files, no model: the class mix, how persistent the
slip is within a traverse, per-feature mean and std, and which acceleration
convention the files use. The learnability half of the report (models trained on
the data) lives in `fleetlab.evaluation.realism`.

Persistence is measured inside each file (one file = one traverse), never across
a file boundary, because consecutive files need not be consecutive in time.
"""

from __future__ import annotations

import numpy as np

from .contracts import CLASS_NAMES, FEATURE_NAMES
from .csvio import WindowTable
from .dataset import Dataset

# A window's mean acc_z near g means the accelerometer reports specific force with
# gravity in it; near 0 means gravity was removed (linear acceleration). The Moon's
# 1.62 m/s^2 is the smallest gravity a rover in these datasets meets, so half of it
# separates the two conventions on every body.
GRAVITY_THRESHOLD = 0.81  # m/s^2
GRAVITY_PRESENT = "gravity present (specific force)"
GRAVITY_REMOVED = "gravity removed (linear acceleration)"
_ACC_Z = FEATURE_NAMES.index("feat_acc_z_mean")


def class_mix(table: WindowTable) -> list[float]:
    """Share of each slip class, in CLASS_NAMES order."""
    counts = np.asarray(table.class_counts(), dtype=np.float64)
    return (counts / max(1.0, counts.sum())).tolist()


def lag1_autocorrelation(x: np.ndarray) -> float | None:
    """Lag-1 autocorrelation of a series (None if it has < 3 values or no variance)."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 3:
        return None
    d = x - x.mean()
    denom = float(np.dot(d, d))
    if denom <= 0.0:
        return None
    return float(np.dot(d[:-1], d[1:]) / denom)


def run_lengths(labels: np.ndarray) -> np.ndarray:
    """Lengths of the maximal runs of equal consecutive labels."""
    labels = np.asarray(labels)
    if len(labels) == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    return np.diff(np.r_[starts, len(labels)])


def persistence(tables: list[WindowTable]) -> dict:
    """Within-traverse persistence of a role: per-file lag-1 slip autocorrelation (mean, min,
    max over files that have one) and the mean same-class run length (runs of all files pooled)."""
    acs = [a for a in (lag1_autocorrelation(t.slip_pct) for t in tables) if a is not None]
    runs = np.concatenate([run_lengths(t.label) for t in tables]) if tables else np.zeros(0)
    return {
        "slip_lag1_autocorr_mean": float(np.mean(acs)) if acs else None,
        "slip_lag1_autocorr_min": float(np.min(acs)) if acs else None,
        "slip_lag1_autocorr_max": float(np.max(acs)) if acs else None,
        "files_with_autocorr": len(acs),
        "mean_run_length": float(runs.mean()) if len(runs) else None,
    }


def feature_stats(table: WindowTable) -> dict[str, dict[str, float]]:
    x = table.features
    return {name: {"mean": float(x[:, i].mean()), "std": float(x[:, i].std())} for i, name in enumerate(FEATURE_NAMES)}


def acceleration_convention(table: WindowTable) -> dict:
    """Detect whether gravity is in the acceleration features, from the mean of feat_acc_z_mean."""
    mean_z = float(table.features[:, _ACC_Z].mean()) if len(table) else float("nan")
    return {"mean_acc_z": mean_z,
            "convention": GRAVITY_PRESENT if abs(mean_z) > GRAVITY_THRESHOLD else GRAVITY_REMOVED}


def role_statistics(ds: Dataset) -> dict[str, dict]:
    """Every statistic of every role of one dataset."""
    out = {}
    for role in ds.roles:
        table = ds.table(role)
        out[role] = {
            "files": len(ds.files_of(role)),
            "rows": len(table),
            "class_mix": class_mix(table),
            "persistence": persistence([f.table for f in ds.files_of(role)]),
            "acceleration": acceleration_convention(table),
            "features": feature_stats(table),
        }
    return out


def compare_statistics(a: Dataset, b: Dataset) -> dict:
    """Side-by-side statistics of two datasets; roles present in only one side are kept."""
    return {"class_names": list(CLASS_NAMES), "a": {"path": str(a.root), "roles": role_statistics(a)},
            "b": {"path": str(b.root), "roles": role_statistics(b)}}
