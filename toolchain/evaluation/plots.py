"""Figures of an evaluation (matplotlib, Agg backend): metric bars, confusion matrices,
AcoMerge convergence and the buffer-ablation curves."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .methods import LABELS, buffer_methods, fleet_methods  # noqa: E402
from .metrics import SCALAR_METRICS  # noqa: E402
from .tables import CLASS_NAMES, COLUMN_NAMES  # noqa: E402


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def metric_bars(result: dict, path: Path) -> Path:
    results = result["results"]
    methods, sizes = list(results), list(next(iter(results.values())))
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 + 0.6 * len(methods), 4.2), squeeze=False, sharey=True)
    x = np.arange(len(methods))
    for ax, c in zip(axes[0], sizes):
        for k, metric in enumerate(SCALAR_METRICS):
            mean = [results[m][c][metric]["mean"] for m in methods]
            std = [results[m][c][metric]["std"] for m in methods]
            ax.bar(x + (k - 0.5) * 0.38, mean, 0.38, yerr=std, capsize=2, label=COLUMN_NAMES[metric])
        ax.set_xticks(x, [LABELS.get(m, m) for m in methods], rotation=60, ha="right", fontsize=7)
        ax.set_title(f"|D_Cal| = {c}")
        ax.set_ylim(0, 1)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("score (mean ± std over runs)")
    axes[0][0].legend(fontsize=8)
    return _save(fig, path)


def confusion_matrices(result: dict, cal_size: str, path: Path) -> Path:
    results = result["results"]
    methods = list(results)
    cols = min(4, len(methods))
    rows = (len(methods) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.1 * cols, 3.0 * rows), squeeze=False)
    for ax in axes.flat[len(methods):]:
        ax.axis("off")
    for ax, m in zip(axes.flat, methods):
        cm = np.asarray(results[m][cal_size]["confusion_matrix"], dtype=float)
        norm = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)  # row-normalised: recall on the diagonal
        ax.imshow(norm, vmin=0, vmax=1, cmap="Blues")
        for i in range(3):
            for j in range(3):
                ax.text(j, i, f"{norm[i, j]:.2f}", ha="center", va="center", fontsize=8,
                        color="white" if norm[i, j] > 0.6 else "black")
        ax.set_xticks(range(3), CLASS_NAMES, fontsize=7)
        ax.set_yticks(range(3), CLASS_NAMES, fontsize=7)
        ax.set_title(LABELS.get(m, m), fontsize=8)
        ax.set_xlabel("predicted", fontsize=7)
        ax.set_ylabel("true", fontsize=7)
    fig.suptitle(f"Confusion matrices summed over runs, |D_Cal| = {cal_size} (row-normalised)", fontsize=9)
    return _save(fig, path)


def _buffer_label(m: str) -> str:
    return "experts×48 (AcoMerge)" if m == "acomerge" else LABELS[m].removeprefix("buffer: ")


def _curves(ax, result: dict, methods: list[str], cal_size: str, label=lambda m: LABELS.get(m, m)) -> None:
    for m in methods:
        curve = result.get("convergence", {}).get(m, {}).get(cal_size)
        if not curve:
            continue
        mean, std = np.asarray(curve["mean"]), np.asarray(curve["std"])
        g = np.arange(1, len(mean) + 1)
        ax.plot(g, mean, label=label(m))
        ax.fill_between(g, mean - std, mean + std, alpha=0.2)
    ax.set_xlabel("generation (optimisation step)")
    ax.set_ylabel("best weighted CE on D_Cal")
    ax.set_title(f"|D_Cal| = {cal_size}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def convergence(result: dict, path: Path) -> Path | None:
    methods = [m for m in ("acomerge", "mmas-only", "iwoa-only") if m in result.get("convergence", {})]
    if not methods:
        return None
    sizes = list(result["convergence"][methods[0]])
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 3.8), squeeze=False)
    for ax, c in zip(axes[0], sizes):
        _curves(ax, result, methods, c)
    return _save(fig, path)


def _fleet_label(m: str) -> str:
    return "all experts (AcoMerge)" if m == "acomerge" else LABELS[m].removeprefix("AcoMerge, ")


def ablation(result: dict, path: Path, methods: tuple[str, ...], label) -> Path | None:
    """Convergence per AcoMerge variant (curves) and its test metrics (bars): the buffer
    ablation (buffer kinds) and the fleet ablation (which experts are in the buffer)."""
    methods = [m for m in ("acomerge", *methods) if m in result.get("convergence", {})]
    if len(methods) < 2:
        return None
    sizes = list(result["convergence"][methods[0]])
    fig, axes = plt.subplots(2, len(sizes), figsize=(5 * len(sizes), 7), squeeze=False)
    for k, c in enumerate(sizes):
        _curves(axes[0][k], result, methods, c, label)
        ax = axes[1][k]
        x = np.arange(len(methods))
        for i, metric in enumerate(SCALAR_METRICS):
            stats = [result["results"][m][c][metric] for m in methods]
            ax.bar(x + (i - 0.5) * 0.38, [s["mean"] for s in stats], 0.38, yerr=[s["std"] for s in stats],
                   capsize=3, label=COLUMN_NAMES[metric])
        ax.set_xticks(x, [label(m).replace(" + ", " +\n").replace(" (", "\n(") for m in methods], fontsize=7)
        ax.set_ylim(0, 1)
        ax.set_ylabel("test score")
        ax.legend(fontsize=7)
    return _save(fig, path)


def write_plots(result: dict, out_dir: Path) -> list[Path]:
    out_dir = Path(out_dir)
    paths = [metric_bars(result, out_dir / "metrics.png")]
    for c in next(iter(result["results"].values())):
        paths.append(confusion_matrices(result, c, out_dir / f"confusion_{c}.png"))
    for p in (convergence(result, out_dir / "convergence.png"),
              ablation(result, out_dir / "buffer_ablation.png", buffer_methods(), _buffer_label),
              ablation(result, out_dir / "fleet_ablation.png", fleet_methods(), _fleet_label)):
        if p is not None:
            paths.append(p)
    return paths
