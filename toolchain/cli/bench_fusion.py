"""`fleetlab bench fusion`: the options; the measurement is `fleetlab.fusion.bench`."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from ..compute import AUTO_THREADS, MAX_THREADS
from ..errors import InputError
from ..fusion.bench import (GOAL_TABLE_JOBS, GOAL_TABLE_RUNS, TARGET_FULL_RUN_S, TARGET_SPEEDUP, FusionBench, figures,
                            text)
from . import options


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = (
        "Prints batched_ms_per_generation (one generation's ants evaluated as AcoMerge does), "
        "sequential_ms_per_generation (the same ants one at a time through an nn.Module, the reference code's way), "
        "their speedup, full_generation_ms (construction + evaluation + update in a real run) and full_run_s. "
        f"Targets: speedup >= {TARGET_SPEEDUP:g}, full run <= {TARGET_FULL_RUN_S:g} s."
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--data", type=Path, help="dataset folder: draw D_Cal from its target rows (default: synthetic)")
    default = FusionBench()
    p.add_argument("--ants", type=int, default=default.ants, help=f"ants per generation (default: {default.ants})")
    p.add_argument("--generations", type=int, default=default.generations,
                   help=f"generations of the full run (default: {default.generations})")
    p.add_argument("--cal-size", type=int, default=200, help="|D_Cal| (default: 200)")
    p.add_argument("--repeats", type=int, default=40,
                   help="repeats of the batched timing, best kept; the sequential baselines run a tenth as often, "
                        "at least once (default: 40)")
    p.add_argument("--full-runs", type=int, default=5, help="complete runs timed, best kept (default: 5)")
    p.add_argument("--threads", type=int, default=AUTO_THREADS,
                   help=f"threads of the batched evaluation (default: {AUTO_THREADS} = chosen as a run chooses them: "
                        f"the cores free when it starts, up to {MAX_THREADS})")
    p.add_argument("--load", type=int, default=1, metavar="N",
                   help="busy processes (one spinning core each) started beside a second set of full runs, to "
                        "measure the run time on a busy machine; 0 skips it (default: 1)")
    p.add_argument("--table-runs", type=int, default=0, metavar="R",
                   help=f"also time the paper table (`fleetlab evaluate`, R runs x 2 calibration sizes, every method; "
                        f"needs --data; the goal is for R = {GOAL_TABLE_RUNS}); 0 skips it (default: 0)")
    p.add_argument("--table-jobs", type=int, default=GOAL_TABLE_JOBS, metavar="J",
                   help=f"--jobs of that evaluation (default: {GOAL_TABLE_JOBS})")
    p.add_argument("--device", default="cpu", metavar="cpu|cuda|auto",
                   help="cpu (default): the reference path; cuda: the GPU path (lockstep engine)")
    p.add_argument("--batch-runs", type=int, default=30, metavar="R",
                   help="with --device cuda: runs stepped together in the batched measurement (default: 30)")
    p.add_argument("--seed", type=int, default=0, help="seed (default: 0)")
    options.arch(p)  # after the others: `--help` lists the options in the order they had before moving here


def run(args: argparse.Namespace) -> int:
    for name in ("ants", "generations", "cal_size", "repeats", "full_runs", "batch_runs"):
        if getattr(args, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be at least 1")
    if args.threads < 0 or args.load < 0 or args.table_runs < 0 or args.table_jobs < 1:
        raise InputError("--threads, --load and --table-runs must not be negative, --table-jobs at least 1")
    if args.table_runs and args.data is None:
        raise InputError("--table-runs needs --data DIR (the table is evaluated on the real target rover's rows)")
    result = figures(FusionBench(**{f.name: getattr(args, f.name) for f in dataclasses.fields(FusionBench)}))
    print(json.dumps(result) if args.json else text(result))
    return 0
