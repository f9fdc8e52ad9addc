"""`fleetlab evaluate`: Monte Carlo cross-validation of AcoMerge against the paper's baselines."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..data.splits import PROTOCOLS
from ..models import ARCHS
from ..models.train import EXPERT_LR
from .mccv import BACKENDS, EvalSettings, run_mccv
from .methods import METHODS, Budget, parse_methods

DEFAULT_CAL_SIZES = (150, 200)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Monte Carlo cross-validation (MCCV) of AcoMerge and the paper's baselines on the target rover's "
        "Moon data. Experts (and the joint model) are trained once on the source data; every run then draws "
        "a fresh calibration set D_Cal (split seed = run index), fits every method on it with the same budget "
        "of optimisation steps, and scores it on the remaining target rows. Reports balanced accuracy, "
        "macro-F1, per-class precision/recall, confusion matrices and a corrected resampled t-test "
        "(Nadeau & Bengio) of the best method against the second."
    )
    p.add_argument("--data", required=True, type=Path, metavar="DIR",
                   help="dataset folder: made by 'fleetlab simulate' (dataset.json) or the original Fleet-To-Lab CSVs")
    p.add_argument("--protocol", choices=PROTOCOLS, default="paper",
                   help="calibration draw: 'paper' = stratified random rows (as in the paper), "
                   "'traverse' = leakage-free, calibration and test from different traverses (default: paper)")
    p.add_argument("--arch", choices=list(ARCHS), default="sn-s", help="model architecture (default: sn-s)")
    p.add_argument("--cal-size", type=int, action="append", dest="cal_sizes", metavar="N",
                   help="calibration size |D_Cal|; repeat for several (default: 150 and 200)")
    p.add_argument("--runs", type=int, default=30, help="MCCV runs per calibration size (default: 30)")
    p.add_argument("--seed", type=int, default=0, help="seed of the experts and of every method's search (default: 0)")
    p.add_argument("--epochs", type=int, default=70, help="training epochs of the experts and the joint model (default: 70)")
    p.add_argument("--generations", type=int, default=130,
                   help="AcoMerge generations = optimisation steps of EVERY method (Adam steps, CMA-ES "
                   "generations, PSO iterations) (default: 130)")
    p.add_argument("--ants", type=int, default=300, help="AcoMerge ants per generation (default: 300)")
    p.add_argument("--sigma", type=float, default=0.05,
                   help="std of the Gaussian-perturbed expert copies in the AcoMerge/ModelSwarm buffer "
                   "(default: 0.05, the paper's value; the reference code used 0.005)")
    p.add_argument("--finetune-lr", type=float, default=EXPERT_LR, metavar="LR",
                   help="Adam learning rate of Earth + FullFinetune and Joint + FullFinetune (default: "
                   f"{EXPERT_LR:g}, the experts' rate; the paper grid-searched it, so try a few)")
    p.add_argument("--methods", default="all", metavar="LIST",
                   help=f"comma-separated methods out of: {', '.join(METHODS)} (default: all)")
    p.add_argument("--buffer-ablation", action="store_true",
                   help="also run AcoMerge on the ablation buffers (experts×3 + centroid-random×45, random×48)")
    p.add_argument("--fleet-ablation", action="store_true",
                   help="also run AcoMerge with the Earth expert only and with the fleet experts only (same "
                   "buffer size): what the fleet adds beyond the Earth expert and the search itself")
    p.add_argument("--jobs", type=int, default=1, help="parallel local worker processes for the MCCV jobs (default: 1)")
    p.add_argument("--backend", choices=BACKENDS, default="loky",
                   help="where MCCV jobs run: local processes (loky) or an existing Dask cluster (default: loky)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address, e.g. tcp://host:8786 (with --backend dask)")
    p.add_argument("--json", type=Path, metavar="FILE", help="write the results as JSON")
    p.add_argument("--out", type=Path, metavar="DIR", help="write results.json, table.md and the plots into DIR")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def settings_from_args(args: argparse.Namespace) -> EvalSettings:
    if args.jobs < 1:
        raise ValueError(f"--jobs must be at least 1, got {args.jobs}")
    if args.backend == "dask" and not args.scheduler:
        raise ValueError("--backend dask needs --scheduler ADDRESS")
    return EvalSettings(
        protocol=args.protocol, arch=args.arch, cal_sizes=tuple(args.cal_sizes or DEFAULT_CAL_SIZES),
        runs=args.runs, seed=args.seed, epochs=args.epochs,
        budget=Budget(steps=args.generations, ants=args.ants, sigma=args.sigma, finetune_lr=args.finetune_lr),
        methods=tuple(parse_methods(args.methods)), buffer_ablation=args.buffer_ablation,
        fleet_ablation=args.fleet_ablation,
    )


def run(args: argparse.Namespace) -> int:
    from ..data.dataset import load_dataset
    from .plots import write_plots
    from .tables import markdown_table

    settings = settings_from_args(args)
    dataset = load_dataset(args.data)
    result = run_mccv(dataset, settings, n_jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                      progress=not args.no_progress)
    result["config"]["data"] = str(args.data)
    table = markdown_table(result)
    text = json.dumps(result, indent=1)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "results.json").write_text(text)
        (args.out / "table.md").write_text(table)
        written = write_plots(result, args.out)
        print(f"wrote {args.out / 'table.md'}, results.json and {len(written)} plots", file=sys.stderr)
    sys.stdout.write(table)
    return 0
