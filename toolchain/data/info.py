"""What `fleetlab data info` reports of a dataset folder: rows and class mix per role and per file, NaN/Inf rows
rejected, feature statistics (`summarise`), and per-class feature histograms (`plot_histograms`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .contracts import CLASS_NAMES, FEATURE_NAMES
from .dataset import Dataset


def summarise(ds: Dataset) -> dict:
    roles = {}
    for role in ds.roles:
        t = ds.table(role)
        roles[role] = {"rows": len(t), "classes": t.class_counts(), "files": len(ds.files_of(role))}
    all_x = np.concatenate([f.table.features for f in ds.files]) if ds.files else np.empty((0, 12))
    stats = {
        name: {
            "mean": float(all_x[:, i].mean()),
            "std": float(all_x[:, i].std()),
            "min": float(all_x[:, i].min()),
            "max": float(all_x[:, i].max()),
        }
        for i, name in enumerate(FEATURE_NAMES)
    } if len(all_x) else {}
    return {
        "path": str(ds.root),
        "recognised_by": ds.source,
        "total_rows": sum(len(f.table) for f in ds.files),
        "rejected_nonfinite_rows": ds.rejected_nonfinite,
        "class_names": list(CLASS_NAMES),
        "roles": roles,
        "files": [
            {"file": f.path.name, "role": f.role, "rows": len(f.table), "classes": f.table.class_counts(),
             "rejected_nonfinite_rows": f.table.rejected_nonfinite}
            for f in ds.files
        ],
        "features": stats,
    }


def plot_histograms(ds: Dataset, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.concatenate([f.table.features for f in ds.files])
    y = np.concatenate([f.table.label for f in ds.files])
    fig, axes = plt.subplots(3, 4, figsize=(16, 10))
    for i, ax in enumerate(axes.flat):
        edges = np.histogram_bin_edges(x[:, i], bins=40)
        for c, name in enumerate(CLASS_NAMES):
            ax.hist(x[y == c, i], bins=edges, alpha=0.5, density=True, label=name)
        ax.set_title(FEATURE_NAMES[i], fontsize=9)
    axes.flat[0].legend()
    fig.suptitle(f"Per-class feature distributions — {ds.root.name} ({len(y)} windows)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
