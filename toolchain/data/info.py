"""`fleetlab data info PATH`: rows and class mix per role and per file, feature statistics."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from .contracts import CLASS_NAMES, FEATURE_NAMES
from .dataset import Dataset, load_dataset


def add_arguments(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    """Add the `info` action; returns the sub-parsers so other actions can join them."""
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    p = sub.add_parser(
        "info",
        help="summarise a dataset folder",
        description="Rows and class counts per role and per file, and per-feature summary statistics, of a "
        "dataset folder (one made by 'fleetlab simulate' or a folder of the original Fleet-To-Lab CSV files).",
    )
    p.add_argument("path", type=Path, help="dataset folder")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--plot", type=Path, metavar="FILE", help="write per-class feature histograms to this PNG")
    return sub


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


def _mix(counts: list[int]) -> str:
    n = max(sum(counts), 1)
    return " / ".join(f"{c} ({100 * c / n:.0f}%)" for c in counts)


def print_summary(s: dict) -> None:
    print(f"{s['path']}: {s['total_rows']} rows in {len(s['files'])} files (roles from {s['recognised_by']})")
    if s["rejected_nonfinite_rows"]:
        print(f"  rejected {s['rejected_nonfinite_rows']} rows holding NaN/Inf")
    print(f"\n{'role':<16}{'files':>6}{'rows':>7}   low / moderate / high")
    for role, r in s["roles"].items():
        print(f"{role:<16}{r['files']:>6}{r['rows']:>7}   {_mix(r['classes'])}")
    print(f"\n{'file':<70}{'role':<14}{'rows':>6}   classes")
    for f in s["files"]:
        name = f["file"] if len(f["file"]) < 70 else "…" + f["file"][-68:]
        print(f"{name:<70}{f['role']:<14}{f['rows']:>6}   {f['classes']}")
    print(f"\n{'feature':<20}{'mean':>12}{'std':>12}{'min':>12}{'max':>12}")
    for name, st in s["features"].items():
        print(f"{name:<20}{st['mean']:>12.4g}{st['std']:>12.4g}{st['min']:>12.4g}{st['max']:>12.4g}")


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


def run(args: argparse.Namespace) -> int:
    ds = load_dataset(args.path)
    s = summarise(ds)
    if args.json:
        print(json.dumps(s, indent=2))
    else:
        print_summary(s)
    if args.plot:
        plot_histograms(ds, args.plot)
        if not args.json:
            print(f"\nwrote {args.plot}")
    return 0
