"""`fleetlab fuse`: train the experts, fuse them with AcoMerge on D_Cal, report.

Writes into RUN:
  fused.pt                 the fused model (save_model) with its metadata
  experts/<role>.pt        the experts, aligned to the Earth expert (same functions)
  earth_finetuned.pt       the Earth expert fine-tuned on the same D_Cal (the reference point)
  history.json             AcoMerge's per-generation convergence history and config
  convergence.png          best-so-far / iteration-best / mean J per generation
  report.md                fused vs Earth+FullFinetune (and each expert) on the test set
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import torch

from ..data.contracts import CLASS_NAMES, N_CLASSES
from ..data.csvio import read_windows_csv
from ..data.dataset import EARTH, TARGET, load_dataset
from ..data.splits import PROTOCOLS, make_split
from ..evaluation.metrics import SCALAR_METRICS, classification_metrics
from ..models import SlipNet, build, flatten, load_flat, save_model
from ..models.mlp import ARCHS
from ..models.train import EXPERT_EPOCHS, predict
from .acomerge import AcoMergeConfig, acomerge, default_threads
from .experts import train_experts
from .finetune import FINETUNE_STEPS, finetune
from .fitness import CalibrationFitness
from .rebasin import align_to_reference


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Train one expert per source (Earth analog + each fleet rover), align them with Git Re-Basin, "
        "fuse them with AcoMerge on a small calibration set of the target rover, and compare the fused "
        "model with the Earth expert fine-tuned on the same calibration set."
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (dataset.json or Fleet-To-Lab file names)")
    p.add_argument("--out", required=True, type=Path, help="run folder to create/overwrite (RUN)")
    p.add_argument("--arch", default="sn-s", choices=sorted(ARCHS), help="network architecture (default: sn-s)")
    p.add_argument("--cal-size", type=int, default=150, help="|D_Cal| rows drawn from the target data (default: 150)")
    p.add_argument("--calibration", type=Path, help="use this window CSV (Fleet-To-Lab format) as D_Cal instead of drawing one")
    p.add_argument("--protocol", default="paper", choices=PROTOCOLS,
                   help="calibration/test split: 'paper' (random rows) or 'traverse' (leakage-free, by file)")
    p.add_argument("--seed", type=int, default=0, help="seed for the experts, the split and AcoMerge (default: 0)")
    p.add_argument("--epochs", type=int, default=EXPERT_EPOCHS, help=f"expert training epochs (default: {EXPERT_EPOCHS})")
    p.add_argument("--generations", type=int, default=130, help="AcoMerge generations = pheromone updates (default: 130)")
    p.add_argument("--ants", type=int, default=300, help="ants per generation (default: 300)")
    p.add_argument("--copies", type=int, default=15, help="perturbed copies per expert in the buffer (default: 15)")
    p.add_argument("--sigma", type=float, default=0.05, help="std of the buffer perturbation (default: 0.05)")
    p.add_argument("--finetune-steps", type=int, default=FINETUNE_STEPS,
                   help=f"Adam steps of the Earth fine-tune reference (default: {FINETUNE_STEPS})")
    p.add_argument("--threads", type=int, default=default_threads(),
                   help=f"threads for training and for AcoMerge's batched evaluation (default: {default_threads()}, "
                        "this machine's cores up to 4)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _calibration(args, dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
    """(x_cal, y_cal, x_test, y_test, description) for the chosen calibration source."""
    x, y = dataset.xy(TARGET)
    if args.calibration is None:
        split = make_split(args.protocol, y, dataset.groups(TARGET), args.cal_size, args.seed)
        info = {"source": f"{args.protocol} split of the target data", "protocol": args.protocol,
                "size": int(len(split.cal)), "indices": split.cal.tolist(), "test_size": int(len(split.test))}
        return x[split.cal], y[split.cal], x[split.test], y[split.test], info
    table = read_windows_csv(args.calibration)
    if len(table) == 0:
        raise ValueError(f"{args.calibration}: calibration file has no usable rows")
    x_cal, y_cal = table.features.astype(np.float32), table.label
    # Target rows that also appear in the calibration file are not test rows: drop and count them.
    cal_rows = {row.tobytes() for row in x_cal}
    in_cal = np.array([row.tobytes() in cal_rows for row in x])
    info = {"source": str(args.calibration), "size": int(len(y_cal)), "test_size": int((~in_cal).sum()),
            "test_rows_dropped_as_calibration": int(in_cal.sum()), "rejected_nonfinite": table.rejected_nonfinite}
    if (~in_cal).sum() == 0:
        raise ValueError(f"{args.calibration}: every target row is in the calibration file; nothing left to test on")
    return x_cal, y_cal, x[~in_cal], y[~in_cal], info


def _scores(model: SlipNet, x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    m = classification_metrics(y, predict(model, x))
    return {k: m[k] for k in SCALAR_METRICS}


def _plot(history: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=120)
    gens = np.arange(1, len(history["best_so_far"]) + 1)
    ax.plot(gens, history["iteration_mean"], label="generation mean", alpha=0.6)
    ax.plot(gens, history["iteration_best"], label="generation best", alpha=0.8)
    ax.plot(gens, history["best_so_far"], label="best so far", lw=2)
    for g in [i + 1 for i, v in enumerate(history.get("iwoa", [])) if v]:
        ax.axvline(g, color="grey", lw=0.5, ls=":")
    ax.set_xlabel("generation (dotted: IWOA update)")
    ax.set_ylabel("weighted CE on D_Cal")
    ax.legend(fontsize=8)
    ax.set_title("AcoMerge convergence")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _report(path: Path, args, info: dict, rows: list[tuple[str, float, dict]], result, seconds: dict) -> None:
    lines = [
        "# fleetlab fuse report", "",
        f"- data: `{args.data}`; architecture {args.arch}; seed {args.seed}",
        f"- D_Cal: {info['size']} rows ({info['source']}); test set: {info['test_size']} target rows",
        f"- AcoMerge: {args.generations} generations × {args.ants} ants, buffer {args.copies} copies/expert, "
        f"σ = {args.sigma}; {result.evaluations} models evaluated; best found at {result.best_origin}",
        f"- Earth+FullFinetune: {args.finetune_steps} Adam steps on class-weighted CE over the same D_Cal",
        "- time: " + ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items()), "",
        "| model | weighted CE on D_Cal | test balanced accuracy | test macro-F1 |",
        "|---|---|---|---|",
    ]
    lines += [f"| {name} | {j:.4f} | {s['balanced_accuracy']:.4f} | {s['macro_f1']:.4f} |" for name, j, s in rows]
    fused, ft = rows[0][2], rows[1][2]
    delta = fused["balanced_accuracy"] - ft["balanced_accuracy"]
    lines += ["", f"AcoMerge − Earth+FullFinetune balanced accuracy: {delta:+.4f} (one calibration draw; "
              "use `fleetlab evaluate` for Monte Carlo cross-validation).", ""]
    path.write_text("\n".join(lines))


def run(args: argparse.Namespace) -> int:
    for name in ("cal_size", "epochs", "generations", "ants", "finetune_steps", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be at least 1")
    previous_threads = torch.get_num_threads()
    torch.set_num_threads(args.threads)
    try:
        return _fuse(args)
    finally:
        torch.set_num_threads(previous_threads)


def _fuse(args: argparse.Namespace) -> int:
    progress = not args.no_progress
    seconds: dict[str, float] = {}
    dataset = load_dataset(args.data)
    dataset.check_roles()
    x_cal, y_cal, x_test, y_test, info = _calibration(args, dataset)  # bad calibration input fails early

    t0 = time.perf_counter()
    experts = train_experts(dataset, args.arch, args.seed, epochs=args.epochs, progress=progress)
    aligned = align_to_reference(list(experts.values()), args.arch, reference=0)  # Earth expert is the reference
    seconds["experts"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    config = AcoMergeConfig(n_ants=args.ants, generations=args.generations, copies=args.copies,
                            sigma=args.sigma, threads=args.threads)
    result = acomerge(torch.stack(aligned), args.arch, x_cal, y_cal, config, seed=args.seed, progress=progress)
    seconds["acomerge"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    tuned = finetune(experts[EARTH], x_cal, y_cal, steps=args.finetune_steps, seed=args.seed)
    seconds["finetune"] = time.perf_counter() - t0

    fused = load_flat(build(args.arch), result.best_flat).eval()
    cal_loss = CalibrationFitness(args.arch, x_cal, y_cal)
    rows = [("AcoMerge (fused)", result.best_fitness, _scores(fused, x_test, y_test)),
            ("Earth+FullFinetune", float(cal_loss(flatten(tuned))), _scores(tuned, x_test, y_test))]
    for role, flat, j in zip(experts, aligned, result.expert_fitness):
        rows.append((f"expert {role} (no adaptation)", j, _scores(load_flat(build(args.arch), flat).eval(), x_test, y_test)))

    _write_run(args, dataset, info, y_cal, config, result, fused, tuned, dict(zip(experts, aligned)), rows, seconds)
    for name, j, s in rows[:2]:
        print(f"{name:20s} D_Cal CE {j:.4f}  test balanced accuracy {s['balanced_accuracy']:.4f}  macro-F1 {s['macro_f1']:.4f}")
    print(f"wrote {args.out}/fused.pt, report.md, history.json, convergence.png")
    return 0


def _write_run(args, dataset, info, y_cal, config, result, fused, tuned, aligned: dict, rows, seconds) -> None:
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    fitness_name = "class-weighted cross-entropy on D_Cal (lower is better)"
    data_summary = {"root": str(dataset.root), "roles": {r: int(len(dataset.table(r))) for r in dataset.roles},
                    "class_counts_cal": np.bincount(y_cal, minlength=N_CLASSES).tolist(), "classes": list(CLASS_NAMES)}
    meta = {"method": "acomerge", "seed": args.seed, "data": data_summary, "calibration": info,
            "fitness": result.best_fitness, "fitness_name": fitness_name, "best_origin": result.best_origin,
            "experts": list(aligned), "epochs": args.epochs, "config": dataclasses.asdict(config), "test": rows[0][2]}
    save_model(out / "fused.pt", fused, meta)
    for role, flat in aligned.items():
        save_model(out / "experts" / f"{role}.pt", load_flat(build(args.arch), flat).eval(),
                   {"role": role, "seed": args.seed, "epochs": args.epochs, "aligned_to": EARTH})
    cal_info = {k: v for k, v in info.items() if k != "indices"}
    save_model(out / "earth_finetuned.pt", tuned,
               {"method": "earth-ft", "seed": args.seed, "steps": args.finetune_steps, "calibration": cal_info})
    history = {"fitness": fitness_name, "config": dataclasses.asdict(config),
               "expert_fitness": dict(zip(aligned, result.expert_fitness)), "best_fitness": result.best_fitness,
               "best_origin": result.best_origin, "evaluations": result.evaluations, "history": result.history}
    (out / "history.json").write_text(json.dumps(history, indent=1))
    _plot(result.history, out / "convergence.png")
    _report(out / "report.md", args, info, rows, result, seconds)
