"""The paper's table under noisy calibration labels: one MCCV evaluation per noise rate.

`run_sweep` trains the source models once (no calibration label reaches them), then runs the same
evaluation at every rate of one noise model (`data/label_noise.py`) with D_Cal's labels corrupted and the
test rows' labels exact. Every rate draws the same D_Cal rows (split seed = run index) and, within a rate,
every method sees the same corrupted labels, so methods stay paired and a rate's table is a paper table.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..data.dataset import Dataset
from ..data.label_noise import KINDS
from .mccv import prepare_sources, run_mccv
from .protocol import EvalSettings
from .methods import LABELS
from ..errors import InputError

METRIC = "balanced_accuracy"


def parse_sweep(text: str) -> tuple[str, list[float]]:
    """'adjacent:0,0.1,0.2' -> ('adjacent', [0.0, 0.1, 0.2])."""
    kind, sep, values = text.partition(":")
    kind = kind.strip().lower()
    if kind not in KINDS or not sep:
        raise InputError(f"--label-noise-sweep {text!r}: write KIND:R1,R2,... with KIND one of {', '.join(KINDS)}")
    try:
        rates = [float(v) for v in values.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--label-noise-sweep {text!r}: the rates must be numbers") from None
    if not rates or len(set(rates)) != len(rates):
        raise InputError(f"--label-noise-sweep {text!r}: give distinct rates, e.g. {kind}:0,0.1,0.2")
    return kind, rates


def run_sweep(dataset: Dataset, settings: EvalSettings, kind: str, rates: list[float], n_jobs: int = 1,
              backend: str = "loky", scheduler: str | None = None, progress: bool = True,
              results_dir: Path | None = None, resume: bool = False) -> dict:
    """{'kind', 'rates', 'per_rate': {rate: run_mccv result}, 'summary': ...}; with `results_dir`, each
    rate's jobs go to results_dir/<kind>-<rate>/ (what `resume` reads back)."""
    per_rate = {}
    sources = None
    for rate in rates:
        rated = replace(settings, label_noise=f"{kind}:{rate:g}")
        if sources is None:
            sources = prepare_sources(dataset, rated, n_jobs, backend, scheduler, progress)
        folder = None if results_dir is None else Path(results_dir) / f"{kind}-{rate:g}"
        if progress:
            print(f"label noise {kind}:{rate:g}", flush=True)
        per_rate[f"{rate:g}"] = run_mccv(dataset, rated, n_jobs, backend, scheduler, progress, folder,
                                         resume and folder is not None and folder.is_dir(), sources=sources)
    return {"kind": kind, "rates": rates, "per_rate": per_rate, "summary": summary(per_rate)}


def summary(per_rate: dict) -> dict:
    """Per calibration size: every method's mean and std of balanced accuracy at each rate, the
    corrupted fraction of D_Cal's labels, and the best-vs-second t-test at each rate."""
    first = next(iter(per_rate.values()))
    out: dict = {}
    for c in first["results"][next(iter(first["results"]))]:
        methods = list(first["results"])
        out[c] = {
            "methods": {m: {"mean": [r["results"][m][c][METRIC]["mean"] for r in per_rate.values()],
                            "std": [r["results"][m][c][METRIC]["std"] for r in per_rate.values()]} for m in methods},
            "corrupted_fraction": [next(iter(r["results"].values()))[c].get("label_noise", {})
                                   .get("corrupted_fraction", 0.0) for r in per_rate.values()],
            "best_vs_second": [{k: r["ttest"][c][METRIC].get(k) for k in ("best", "second", "significant")}
                               | {"p": r["ttest"][c][METRIC].get("tests", {}).get("nadeau-bengio", {}).get("p")}
                               for r in per_rate.values()],
        }
    return out


def markdown(sweep: dict) -> str:
    """One table per calibration size: methods × rates, balanced accuracy mean ± std, best in bold."""
    rates = [f"{r:g}" for r in sweep["rates"]]
    lines = []
    for c, s in sweep["summary"].items():
        lines += [f"Balanced accuracy under `{sweep['kind']}` label noise, |D_Cal| = {c} (test labels exact):", "",
                  "| Method | " + " | ".join(f"{sweep['kind']} {r}" for r in rates) + " |",
                  "|---|" + "---|" * len(rates)]
        means = np.array([v["mean"] for v in s["methods"].values()])
        best = means.argmax(axis=0)
        for i, (m, v) in enumerate(s["methods"].items()):
            cells = [f"{mu:.3f} ± {sd:.3f}" for mu, sd in zip(v["mean"], v["std"])]
            cells = [f"**{t}**" if best[k] == i else t for k, t in enumerate(cells)]
            lines.append(f"| {LABELS.get(m, m)} | " + " | ".join(cells) + " |")
        lines.append("| labels corrupted | " + " | ".join(f"{100 * f:.1f} %" for f in s["corrupted_fraction"]) + " |")
        lines.append("| best vs second, p | " + " | ".join(
            "—" if t["p"] is None else f"{t['p']:.3f}{' †' if t['significant'] else ''}"
            for t in s["best_vs_second"]) + " |")
        lines += ["", "† best significantly better than second (corrected resampled t-test, p < 0.05).", ""]
    return "\n".join(lines)


def plot(sweep: dict, path: Path) -> Path:
    """Balanced accuracy against the noise rate, one line per method, error bars = std over runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = list(sweep["summary"])
    fig, axes = plt.subplots(1, len(sizes), figsize=(5.5 * len(sizes), 4.2), squeeze=False, sharey=True)
    for ax, c in zip(axes[0], sizes):
        for k, (m, v) in enumerate(sweep["summary"][c]["methods"].items()):
            shift = (k - len(sweep["summary"][c]["methods"]) / 2) * 0.002 * max(sweep["rates"] + [1e-9])
            ax.errorbar(np.array(sweep["rates"]) + shift, v["mean"], yerr=v["std"], marker="o", capsize=3,
                        label=LABELS.get(m, m))
        ax.set_xlabel(f"{sweep['kind']} noise rate of D_Cal's labels")
        ax.set_title(f"|D_Cal| = {c}")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("balanced accuracy (mean ± std over runs)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
