"""The run folder of `fleetlab fuse`: the fused model, the aligned experts, the Earth fine-tune
reference, the search history, a convergence plot and a Markdown report.

  fused.pt                 the fused model (save_model) with its metadata
  experts/<role>.pt        the experts, aligned to the Earth expert (same functions)
  earth_finetuned.pt       the Earth expert fine-tuned on the same D_Cal (the reference point)
  history.json             the method's details (AcoMerge: per-generation convergence and config)
  convergence.png          best-so-far / iteration-best / mean J per generation (methods with a history)
  report.md                fused vs Earth+FullFinetune (and each expert) on the test set
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.calibration import CalibrationSet
from ..data.contracts import CLASS_NAMES, N_CLASSES
from ..data.dataset import EARTH, Dataset
from ..fusion.registry import FusedModel
from ..models import SlipNet, build, load_flat, save_model
from ..models.train import predict
from .metrics import SCALAR_METRICS, classification_metrics

FITNESS_NAME = "class-weighted cross-entropy on D_Cal (lower is better)"


@dataclass
class Row:
    name: str
    fitness: float  # weighted CE on D_Cal
    scores: dict[str, float]  # test-set scalar metrics


def scores(model: SlipNet, x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    m = classification_metrics(y, predict(model, x))
    return {k: m[k] for k in SCALAR_METRICS}


def plot_convergence(history: dict, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=120)
    gens = np.arange(1, len(history["best_so_far"]) + 1)
    if "iteration_mean" in history:
        ax.plot(gens, history["iteration_mean"], label="generation mean", alpha=0.6)
    if "iteration_best" in history:
        ax.plot(gens, history["iteration_best"], label="generation best", alpha=0.8)
    ax.plot(gens, history["best_so_far"], label="best so far", lw=2)
    for g in [i + 1 for i, v in enumerate(history.get("iwoa", [])) if v]:
        ax.axvline(g, color="grey", lw=0.5, ls=":")
    ax.set_xlabel("generation (dotted: IWOA update)")
    ax.set_ylabel("weighted CE on D_Cal")
    ax.legend(fontsize=8)
    ax.set_title(f"{title} convergence")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_report(path: Path, run: dict, cal: CalibrationSet, rows: list[Row], fused: FusedModel, label: str,
                 seconds: dict[str, float], rejected_rows: int) -> None:
    d = fused.details
    if "config" in d and "evaluations" in d:  # AcoMerge and its variants: the search as run
        cfg = d["config"]
        search = (f"- {label}: {cfg['generations']} generations × {cfg['n_ants']} ants, buffer {cfg['copies']} "
                  f"copies/expert, σ = {cfg['sigma']}; {d['evaluations']} models evaluated; best found at "
                  f"{d['best_origin']}")
    else:
        search = f"- {label}: budget {run['budget']['steps']} optimisation steps"
    lines = [
        "# fleetlab fuse report", "",
        f"- data: `{run['data']}`; architecture {fused.arch}; seed {run['seed']}; method {fused.method}; "
        f"rows rejected for NaN/Inf: {rejected_rows}",
        f"- D_Cal: {cal.info['size']} rows ({cal.info['source']}); test set: {cal.info['test_size']} target rows",
        *([_vo_line(cal.info["labels"])] if "labels" in cal.info else []),
        search,
        f"- Earth+FullFinetune: {run['finetune_steps']} Adam steps on class-weighted CE over the same D_Cal",
        "- time: " + ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items()), "",
        "| model | weighted CE on D_Cal | test balanced accuracy | test macro-F1 |",
        "|---|---|---|---|",
    ]
    lines += [f"| {r.name} | {r.fitness:.4f} | {r.scores['balanced_accuracy']:.4f} | {r.scores['macro_f1']:.4f} |"
              for r in rows]
    delta = rows[0].scores["balanced_accuracy"] - rows[1].scores["balanced_accuracy"]
    lines += ["", f"{label} − Earth+FullFinetune balanced accuracy: {delta:+.4f} (one calibration draw; "
              "use `fleetlab evaluate` for Monte Carlo cross-validation).", ""]
    path.write_text("\n".join(lines))


def write_run(out: Path, run: dict, dataset: Dataset, cal: CalibrationSet, fused: FusedModel, label: str,
              tuned: SlipNet, aligned: dict[str, np.ndarray], rows: list[Row], seconds: dict[str, float]) -> None:
    """Everything of one fuse run into `out` (created). `run` holds seed, epochs, finetune_steps,
    budget (dict) and data (the folder as given)."""
    out.mkdir(parents=True, exist_ok=True)
    data_summary = {"root": str(dataset.root), "roles": {r: int(len(dataset.table(r))) for r in dataset.roles},
                    "rejected_nonfinite_rows": dataset.rejected_nonfinite,
                    "class_counts_cal": np.bincount(cal.y_cal, minlength=N_CLASSES).tolist(),
                    "classes": list(CLASS_NAMES)}
    config = fused.details.get("config", {"budget": run["budget"]})
    meta = {"method": fused.method, "seed": run["seed"], "data": data_summary, "calibration": cal.info,
            "fitness": rows[0].fitness, "fitness_name": FITNESS_NAME, "best_origin": fused.details.get("best_origin"),
            "experts": list(aligned), "epochs": run["epochs"], "config": config, "test": rows[0].scores}
    save_model(out / "fused.pt", fused.module(), meta)
    for role, flat in aligned.items():
        save_model(out / "experts" / f"{role}.pt", load_flat(build(fused.arch), flat).eval(),
                   {"role": role, "seed": run["seed"], "epochs": run["epochs"], "aligned_to": EARTH})
    cal_info = {k: v for k, v in cal.info.items() if k != "indices"}
    save_model(out / "earth_finetuned.pt", tuned,
               {"method": "earth-ft", "seed": run["seed"], "steps": run["finetune_steps"], "calibration": cal_info})
    expert_rows = rows[2:]
    history = {"method": fused.method, "fitness": FITNESS_NAME, "config": config,
               "expert_fitness": {role: r.fitness for role, r in zip(aligned, expert_rows)},
               "best_fitness": rows[0].fitness, "best_origin": fused.details.get("best_origin"),
               "evaluations": fused.details.get("evaluations"), "history": fused.details.get("history", {})}
    if fused.curve and "best_so_far" not in history["history"]:
        history["history"] = {"best_so_far": fused.curve}
    (out / "history.json").write_text(json.dumps(history, indent=1))
    if history["history"].get("best_so_far"):
        plot_convergence(history["history"], out / "convergence.png", label)
    write_report(out / "report.md", run, cal, rows, fused, label, seconds, dataset.rejected_nonfinite)


def _vo_line(labels: dict) -> str:
    return (f"- D_Cal's labels: {labels['source']}; VO did not converge on {labels['vo_dropouts']} window(s) "
            f"(labelled low: the wheel odometry stands); VO's class differs from the file's slip_class in "
            f"{labels['differ_from_file_labels']}")
