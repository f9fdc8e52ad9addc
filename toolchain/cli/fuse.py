"""`fleetlab fuse`: train the experts, fuse them with one registered method on D_Cal, report.

Writes the run folder described in `fleetlab.evaluation.fuse_report`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import torch

from ..compute import device_label, torch_threads
from ..data.calibration import calibration_set
from ..data.label_noise import VoModel
from ..evaluation.fuse_report import Row, scores, write_run
from ..fusion import registry
from ..fusion.baselines import model_from_flat
from ..fusion.finetune import FINETUNE_STEPS, finetune
from ..fusion.fitness import CalibrationFitness
from ..fusion.pipeline import fuse, needs_joint, prepare_sources, source_device
from ..fusion.registry import Budget
from ..models import flatten
from . import dataset_input, options
from ..errors import InputError

DEFAULT_METHOD = "acomerge"
DEFAULT_CAL_SIZE = 150


def add_arguments(p: argparse.ArgumentParser) -> None:
    methods = registry.selectable()
    p.description = (
        "Train one expert per source (Earth analog + each fleet rover), align them with Git Re-Basin, "
        "fuse them with a registered method (AcoMerge by default) on a small calibration set of the target "
        "rover, and compare the fused model with the Earth expert fine-tuned on the same calibration set."
    )
    options.data_dir(p, "dataset folder (dataset.json or Fleet-To-Lab file names) or a roles .toml file")
    p.add_argument("--out", required=True, type=Path, help="run folder to create/overwrite (RUN)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=methods, metavar="NAME",
                   help=f"fusion method, one of: {', '.join(methods)} (default: {DEFAULT_METHOD})")
    options.arch(p)
    p.add_argument("--cal-size", type=int, default=DEFAULT_CAL_SIZE,
                   help=f"|D_Cal| rows drawn from the target data (default: {DEFAULT_CAL_SIZE})")
    p.add_argument("--calibration", type=Path, help="use this window CSV (Fleet-To-Lab format) as D_Cal instead of drawing one")
    p.add_argument("--vo-labels", type=Path, metavar="FILE",
                   help="label D_Cal by visual odometry: FILE has one row per window of --calibration, in order, with "
                        "total_dist_vo (VO's travelled distance, m) and vo_dropout (1 where VO did not converge), as "
                        "`fleetlab simulate --labels vo` writes NAME.vo_labels.csv. Every method then fits VO's classes; "
                        "acomerge-vo fits what each reading says of each class, and leaves out the dropouts")
    p.add_argument("--vo-error-scale", type=float, default=1.0, metavar="S",
                   help="your VO's errors against the default VO model (2 %% of distance, 1 %% scale, 2 mm; "
                        "docs/paper_table.md, 'Noisy calibration labels'), used for acomerge-vo's class probabilities "
                        "(default: 1)")
    options.protocol(p)
    options.seed(p, "the experts, the split and the method's search")
    options.epochs(p)
    options.search_budget(p, "AcoMerge generations = optimisation steps of the method", copies=True)
    options.noise_rate(p)
    p.add_argument("--finetune-steps", type=int, default=FINETUNE_STEPS,
                   help=f"Adam steps of the Earth fine-tune reference (default: {FINETUNE_STEPS})")
    options.threads(p)
    options.device(p)
    options.no_progress(p)


def run(args: argparse.Namespace) -> int:
    options.at_least_one(args, "cal_size", "epochs", "generations", "ants", "finetune_steps")
    if args.threads < 0:
        raise InputError(f"--threads must be 0 (chosen from the free cores) or more, got {args.threads}")
    with torch_threads(args.threads):
        return _fuse(args)


def _fuse(args: argparse.Namespace) -> int:
    progress = not args.no_progress
    device = options.resolved_device(args)  # a missing GPU fails before any training
    label = registry.get(args.method).label
    seconds: dict[str, float] = {}
    dataset = dataset_input.load(args.data)
    dataset.check_roles()
    if not (np.isfinite(args.vo_error_scale) and args.vo_error_scale >= 0):
        raise InputError(f"--vo-error-scale must be a number >= 0, got {args.vo_error_scale}")
    cal = calibration_set(dataset, args.protocol, args.cal_size, args.seed, args.calibration,  # bad input fails early
                          args.vo_labels, VoModel().scaled(args.vo_error_scale))
    if registry.get(args.method).needs_label_probs and cal.y_cal_probs is None:  # before hours of training
        raise InputError(f"{args.method} fits on what each label's VO reading says of it: give --calibration FILE "
                         "with --vo-labels FILE")

    t0 = time.perf_counter()
    src = prepare_sources(dataset, args.arch, args.seed, args.epochs, joint=needs_joint([args.method]), progress=progress,
                          device=source_device(device, args.rng))
    seconds["experts"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    budget = Budget(steps=args.generations, ants=args.ants, sigma=args.sigma, copies=args.copies, threads=args.threads,
                    device=device, rng=args.rng, noise_rate=args.noise_rate)
    if device != "cpu" and progress:
        print(f"{label}: searching on {device_label(device)}", file=sys.stderr)
    fused = fuse(args.method, src, cal.x_cal, cal.y_cal, seed=args.seed, buffer_seed=args.seed, budget=budget,
                 y_cal_probs=cal.y_cal_probs)
    seconds[args.method] = time.perf_counter() - t0

    t0 = time.perf_counter()
    earth = model_from_flat(args.arch, torch.as_tensor(src.experts[0]))
    tuned = finetune(earth, cal.x_cal, cal.y_cal, steps=args.finetune_steps, seed=args.seed)
    seconds["finetune"] = time.perf_counter() - t0

    # One table, one loss: every row's weighted CE on D_Cal as the report's column says, from one call (issue 42:
    # the same bits within a call). A search's own best fitness is another number wherever it minimised another
    # objective (GCE, forward-corrected, VO's probabilities) or fewer rows (the audit, VO's dropouts).
    cal_loss = CalibrationFitness(args.arch, cal.x_cal, cal.y_cal)
    fused_j, tuned_j, *expert_j = (float(j) for j in cal_loss(torch.stack(
        [fused.flat, flatten(tuned), *(torch.as_tensor(a) for a in src.aligned)])))
    rows = [Row(f"{label} (fused)", fused_j, scores(fused.module(), cal.x_test, cal.y_test)),
            Row("Earth+FullFinetune", tuned_j, scores(tuned, cal.x_test, cal.y_test))]
    for role, flat, j in zip(src.roles, src.aligned, expert_j):
        model = model_from_flat(args.arch, torch.as_tensor(flat)).eval()
        rows.append(Row(f"expert {role} (no adaptation)", j, scores(model, cal.x_test, cal.y_test)))

    run_info = {"data": str(args.data), "seed": args.seed, "epochs": args.epochs,
                "finetune_steps": args.finetune_steps, "budget": dataclasses.asdict(budget)}
    write_run(args.out, run_info, dataset, cal, fused, label, tuned, dict(zip(src.roles, src.aligned)), rows, seconds)
    for r in rows[:2]:
        print(f"{r.name:20s} D_Cal CE {r.fitness:.4f}  test balanced accuracy {r.scores['balanced_accuracy']:.4f}  "
              f"macro-F1 {r.scores['macro_f1']:.4f}")
    print(f"wrote {args.out}/fused.pt, report.md, history.json" + (", convergence.png" if fused.curve else ""))
    return 0
