"""What `fleetlab data info` reports of a dataset folder: rows and class mix per role and per file, NaN/Inf rows
rejected, feature statistics (`summarise`), and per-class feature histograms (`plot_histograms`).

Windows without labels (`Dataset.unlabelled`) count in the rows and the feature statistics of their role
and file; the class mix is given only where labels exist (`classes` is None for a file without them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .contracts import CLASS_NAMES, FEATURE_NAMES
from .dataset import Dataset


def all_features(ds: Dataset) -> np.ndarray:
    """(n, 12) features of every window, labelled or not."""
    parts = [f.table.features for f in ds.files] + [f.features for f in ds.unlabelled]
    return np.concatenate(parts) if parts else np.empty((0, len(FEATURE_NAMES)))


def summarise(ds: Dataset) -> dict:
    roles = {}
    for role in dict.fromkeys([*ds.roles, *(f.role for f in ds.unlabelled)]):
        labelled = [f for f in ds.files if f.role == role]
        loose = [f for f in ds.unlabelled if f.role == role]
        n_loose = sum(len(f.features) for f in loose)
        roles[role] = {"rows": sum(len(f.table) for f in labelled) + n_loose,
                       "classes": ds.table(role).class_counts() if labelled else None,
                       "files": len(labelled) + len(loose), **({"unlabelled_rows": n_loose} if loose else {})}
    all_x = all_features(ds)
    stats = {
        name: {
            "mean": float(all_x[:, i].mean()),
            "std": float(all_x[:, i].std()),
            "min": float(all_x[:, i].min()),
            "max": float(all_x[:, i].max()),
        }
        for i, name in enumerate(FEATURE_NAMES)
    } if len(all_x) else {}
    files = [{"file": f.path.name, "role": f.role, "rows": len(f.table), "classes": f.table.class_counts(),
              "rejected_nonfinite_rows": f.table.rejected_nonfinite} for f in ds.files]
    files += [{"file": f.path.name, "role": f.role, "rows": len(f.features), "classes": None,
               "rejected_nonfinite_rows": 0} for f in ds.unlabelled]
    return {
        "path": str(ds.root),
        "recognised_by": ds.source,
        "total_rows": len(all_x),
        "labelled_rows": sum(len(f.table) for f in ds.files),
        "rejected_nonfinite_rows": ds.rejected_nonfinite,
        "class_names": list(CLASS_NAMES),
        "roles": roles,
        "files": files,
        "features": stats,
    }


def plot_histograms(ds: Dataset, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.concatenate([f.table.features for f in ds.files]) if ds.files else np.empty((0, len(FEATURE_NAMES)))
    y = np.concatenate([f.table.label for f in ds.files]) if ds.files else np.empty(0, dtype=np.int64)
    loose = np.concatenate([f.features for f in ds.unlabelled]) if ds.unlabelled else np.empty((0, len(FEATURE_NAMES)))
    fig, axes = plt.subplots(3, 4, figsize=(16, 10))
    for i, ax in enumerate(axes.flat):
        edges = np.histogram_bin_edges(np.concatenate([x[:, i], loose[:, i]]), bins=40)
        for c, name in enumerate(CLASS_NAMES):
            if np.any(y == c):
                ax.hist(x[y == c, i], bins=edges, alpha=0.5, density=True, label=name)
        if len(loose):
            ax.hist(loose[:, i], bins=edges, alpha=0.5, density=True, label="unlabelled")
        ax.set_title(FEATURE_NAMES[i], fontsize=9)
    axes.flat[0].legend()
    fig.suptitle(f"Per-class feature distributions — {ds.root.name} ({len(y) + len(loose)} windows)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
