"""Statistics that say how alike two dataset folders are, role by role (`fleetlab data compare`).

Pure statistics of the window files, no model: the class mix, how persistent the
slip is within a traverse, per-feature mean and std, and which acceleration
convention the files use. The learnability half of the report (models trained on
the data) lives in `fleetlab.evaluation.realism`.

Persistence is measured inside each file (one file = one traverse), never across
a file boundary, because consecutive files need not be consecutive in time.

Windows without labels (an import without ground truth) count in a role's rows, feature
statistics and acceleration convention; the class mix and persistence exist only where labels
do (None otherwise). `range_warnings` lists the features whose range in A is far outside B's
(all windows of each side pooled), with the likely causes (`reference_ranges`).
"""

from __future__ import annotations

import numpy as np

from .contracts import CLASS_NAMES, FEATURE_NAMES
from .csvio import WindowTable
from .dataset import Dataset
from .reference_ranges import compare_range_warnings, feature_ranges

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


def feature_stats(table: WindowTable | np.ndarray) -> dict[str, dict[str, float]]:
    x = table.features if isinstance(table, WindowTable) else table
    return {name: {"mean": float(x[:, i].mean()), "std": float(x[:, i].std())} for i, name in enumerate(FEATURE_NAMES)}


def acceleration_convention(table: WindowTable | np.ndarray) -> dict:
    """Detect whether gravity is in the acceleration features, from the mean of feat_acc_z_mean."""
    x = table.features if isinstance(table, WindowTable) else table
    mean_z = float(x[:, _ACC_Z].mean()) if len(x) else float("nan")
    return {"mean_acc_z": mean_z,
            "convention": GRAVITY_PRESENT if abs(mean_z) > GRAVITY_THRESHOLD else GRAVITY_REMOVED}


def _features(ds: Dataset, role: str | None = None) -> np.ndarray:
    parts = [f.table.features for f in ds.files if role in (None, f.role)]
    parts += [f.features for f in ds.unlabelled if role in (None, f.role)]
    return np.concatenate(parts) if parts else np.empty((0, len(FEATURE_NAMES)))


def role_statistics(ds: Dataset) -> dict[str, dict]:
    """Every statistic of every role of one dataset (unlabelled windows: no class mix, no persistence)."""
    out = {}
    for role in dict.fromkeys([*ds.roles, *(f.role for f in ds.unlabelled)]):
        labelled = ds.files_of(role)
        x = _features(ds, role)
        out[role] = {
            "files": len(labelled) + sum(f.role == role for f in ds.unlabelled),
            "rows": len(x),
            "labelled_rows": sum(len(f.table) for f in labelled),
            "class_mix": class_mix(ds.table(role)) if labelled else None,
            "persistence": persistence([f.table for f in labelled]) if labelled else persistence([]),
            "acceleration": acceleration_convention(x),
            "features": feature_stats(x),
        }
    return out


def range_warnings(a: Dataset, b: Dataset) -> list[str]:
    """Features whose range over all of A's windows is far outside their range over all of B's."""
    xa, xb = _features(a), _features(b)
    if not len(xa) or not len(xb):
        return []
    return compare_range_warnings(feature_ranges(xa), feature_ranges(xb))


def compare_statistics(a: Dataset, b: Dataset) -> dict:
    """Side-by-side statistics of two datasets; roles present in only one side are kept."""
    return {"class_names": list(CLASS_NAMES), "a": {"path": str(a.root), "roles": role_statistics(a)},
            "b": {"path": str(b.root), "roles": role_statistics(b)}, "warnings": range_warnings(a, b)}
