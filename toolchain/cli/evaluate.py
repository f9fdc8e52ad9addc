"""`fleetlab evaluate`: Monte Carlo cross-validation of AcoMerge against the paper's baselines."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..evaluation.executor import BACKENDS, write_atomic
from ..evaluation.mccv import run_mccv
from ..evaluation.protocol import EvalSettings
from ..evaluation.methods import parse_methods, selectable
from ..fusion.registry import Budget
from ..models.train import EXPERT_LR
from . import dataset_input, options
from ..errors import InputError

DEFAULT_CAL_SIZES = EvalSettings.cal_sizes
DEFAULT_RUNS = EvalSettings.runs


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Monte Carlo cross-validation (MCCV) of AcoMerge and the paper's baselines on the target rover's "
        "Moon data. Experts (and the joint model) are trained once on the source data; every run then draws "
        "a fresh calibration set D_Cal (split seed = run index), fits every method on it with the same budget "
        "of optimisation steps, and scores it on the remaining target rows. Reports balanced accuracy, "
        "macro-F1, per-class precision/recall, confusion matrices and a corrected resampled t-test "
        "(Nadeau & Bengio) of the best method against the second."
    )
    options.data_dir(p)
    options.protocol(p)
    options.arch(p)
    p.add_argument("--cal-size", type=int, action="append", dest="cal_sizes", metavar="N",
                   help="calibration size |D_Cal|; repeat for several (default: "
                   f"{' and '.join(map(str, DEFAULT_CAL_SIZES))})")
    p.add_argument("--runs", type=int, default=DEFAULT_RUNS, help=f"MCCV runs per calibration size (default: {DEFAULT_RUNS})")
    options.seed(p, "the experts and of every method's search")
    options.epochs(p, "the experts and the joint model")
    options.search_budget(p, "AcoMerge generations = optimisation steps of EVERY method (Adam steps, CMA-ES "
                          "generations, PSO iterations)")
    p.add_argument("--finetune-lr", type=float, default=EXPERT_LR, metavar="LR",
                   help="Adam learning rate of Earth + FullFinetune and Joint + FullFinetune (default: "
                   f"{EXPERT_LR:g}, the experts' rate; the paper grid-searched it, so try a few)")
    p.add_argument("--methods", default="all", metavar="LIST",
                   help=f"comma-separated methods out of: {', '.join(selectable())} (default: all, which leaves "
                        "out the noise-robust group: name those to run them)")
    p.add_argument("--buffer-ablation", action="store_true",
                   help="also run AcoMerge on the ablation buffers (experts×3 + centroid-random×45, random×48)")
    p.add_argument("--fleet-ablation", action="store_true",
                   help="also run AcoMerge with the Earth expert only and with the fleet experts only (same "
                   "buffer size): what the fleet adds beyond the Earth expert and the search itself")
    p.add_argument("--label-noise", default="", metavar="KIND:RATE",
                   help="corrupt D_Cal's labels (only; the test rows keep exact labels), per run and seeded: "
                        "symmetric:RATE (any other class), adjacent:RATE (low<->moderate, moderate<->high, the "
                        "confusion visual odometry makes), vo:SCALE (the slip measured again by a visual-odometry "
                        "model, SCALE times its default errors; each label then also carries its reading's class "
                        "probabilities, which acomerge-vo fits). The table says how many labels were changed")
    options.noise_rate(p)
    p.add_argument("--label-noise-sweep", metavar="KIND:R1,R2,...",
                   help="run the whole evaluation at each rate (source models trained once), e.g. "
                        "adjacent:0,0.1,0.2,0.3,0.4; prints one table of balanced accuracy per rate and, with "
                        "--out, writes sweep.json, sweep.md and sweep.png (accuracy against the rate)")
    options.jobs(p)
    p.add_argument("--backend", choices=BACKENDS, default="loky",
                   help="where MCCV jobs run: local processes (loky) or an existing Dask cluster (default: loky)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address, e.g. tcp://host:8786 (with --backend dask)")
    options.device(p)
    options.json_file(p)
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="write results.json, table.md and the plots into DIR, and every run's result into DIR/runs/ "
                        "as it finishes (what --resume reads)")
    p.add_argument("--resume", type=Path, metavar="DIR",
                   help="continue an interrupted evaluation whose --out was DIR: runs already in DIR/runs/ are read, "
                        "the others are run (same options required); results go to DIR")
    options.no_progress(p)


def settings_from_args(args: argparse.Namespace) -> EvalSettings:
    if args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    if args.backend == "dask" and not args.scheduler:
        raise InputError("--backend dask needs --scheduler ADDRESS")
    return EvalSettings(
        protocol=args.protocol, arch=args.arch, cal_sizes=tuple(args.cal_sizes or DEFAULT_CAL_SIZES),
        runs=args.runs, seed=args.seed, epochs=args.epochs,
        budget=Budget(steps=args.generations, ants=args.ants, sigma=args.sigma, finetune_lr=args.finetune_lr,
                      device=options.resolved_device(args), rng=args.rng, noise_rate=args.noise_rate),
        methods=tuple(parse_methods(args.methods)), buffer_ablation=args.buffer_ablation,
        fleet_ablation=args.fleet_ablation, label_noise=args.label_noise,
    )


def run(args: argparse.Namespace) -> int:
    from ..evaluation.plots import write_plots
    from ..evaluation.tables import markdown_table

    settings = settings_from_args(args)
    if args.resume and args.out and args.out.resolve() != args.resume.resolve():
        raise InputError("--resume DIR writes into DIR: give no other --out")
    args.out = args.resume or args.out
    dataset = dataset_input.load(args.data)
    if args.label_noise_sweep:
        return _sweep(args, settings, dataset)
    result = run_mccv(dataset, settings, n_jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                      progress=not args.no_progress, results_dir=args.out, resume=args.resume is not None)
    result["config"]["data"] = str(args.data)
    return _output(args, result, markdown_table(result), "results.json", "table.md",
                   lambda out: f"{len(write_plots(result, out))} plots")


def _sweep(args: argparse.Namespace, settings: EvalSettings, dataset) -> int:
    from ..evaluation import noise_sweep

    if args.label_noise:
        raise InputError("--label-noise-sweep runs every rate itself: give no --label-noise")
    kind, rates = noise_sweep.parse_sweep(args.label_noise_sweep)
    sweep = noise_sweep.run_sweep(dataset, settings, kind, rates, n_jobs=args.jobs, backend=args.backend,
                                  scheduler=args.scheduler, progress=not args.no_progress, results_dir=args.out,
                                  resume=args.resume is not None)
    sweep["config"] = {"data": str(args.data), "arch": settings.arch, "protocol": settings.protocol,
                       "runs": settings.runs, "seed": settings.seed, "methods": list(settings.all_methods)}
    return _output(args, sweep, noise_sweep.markdown(sweep), "sweep.json", "sweep.md",
                   lambda out: noise_sweep.plot(sweep, out / "sweep.png").name)


def _output(args: argparse.Namespace, result: dict, table: str, json_name: str, table_name: str, plots) -> int:
    """The one way an evaluation's result leaves: --json, and with --out the JSON, the table and `plots(out)`
    (which says what it drew); the table on stdout."""
    text = json.dumps(result, indent=1)
    if args.json:
        write_atomic(args.json, text)
    if args.out:
        write_atomic(args.out / json_name, text)
        write_atomic(args.out / table_name, table)
        drawn = plots(args.out)
        print(f"wrote {args.out / table_name}, {json_name} and {drawn}", file=sys.stderr)
    sys.stdout.write(table)
    return 0
