"""How fast AcoMerge evaluates a generation, and a full run (`fleetlab bench fusion`, options in
`fleetlab.cli.bench_fusion`).

Figures (one JSON object with --json):
- batched_ms_per_generation: one generation's ants (AcoMergeConfig.n_ants different models, none shared)
  evaluated the way `acomerge` evaluates them — models gathered from the buffer, one
  batched fitness computation on `--threads` torch threads;
- sequential_ms_per_generation: the same ants evaluated one at a time the way the
  reference code does it: copy the flat vector into an nn.Module, run D_Cal through a
  torch DataLoader (batches of 200, its setting), softmax, predictions and probabilities
  collected row by row into numpy, weighted CE in numpy;
- speedup = sequential / batched: the same work, done both ways;
- full_generation_ms: everything one generation of a real run costs — ant construction,
  evaluation (ants that rebuilt the greedy path share one), pheromone update, IWOA
  amortised — i.e. the full run's time over its generations; speedup_full_generation =
  sequential / that (the stricter ratio: the sequential figure leaves construction out);
- sequential_fullbatch_ms_per_generation: one at a time through the nn.Module but with
  all of D_Cal in one batch and torch's weighted cross-entropy (a stronger baseline), and
  speedup_vs_fullbatch;
- full_run_s: one complete run (SN-S, the paper budget of AcoMergeConfig, |D_Cal| = 200 by default);
- every timing is the best of its repeats (the one least disturbed by other processes);
- max_abs_fitness_diff: batched vs sequential fitness of the same ants (must be ~1e-6);
- cpu: process CPU time of the same work (with more than one thread it adds the threads
  up), and load_average_1min: wall-clock figures mean little on a busy machine;
- busy (`--load N`, default 1): full runs with the threads chosen as a real run chooses them
  (`default_threads`, from the cores free at its start), first as the machine is, then with N
  extra processes spinning on a core each; beside them the same loaded runs with a fixed
  thread count of every core (the old default, the peer that collapses), against the goals
  (SN-S: ≤ 0.35 s idle, ≤ 0.6 s with one core busy, on 2 cores); of the idle run, the wall time
  in fitness calls and the rest (run_s_idle_outside_fitness: what no faster fitness shortens).
- table (`--table-runs R` with `--data`): the paper table (R runs × the two calibration sizes, every
  registered method) run by `fleetlab evaluate --jobs --table-jobs` in a child process, as a user runs it:
  wall_s against the goal (SN-S, 30 runs, 2 jobs: ≤ 60 s), and where its CPU time went (the source
  models' training and every method's jobs, CPU seconds, from evaluate's own timing), the part of
  it in fitness calls, and wall_s_bound_without_fitness: the command's other CPU seconds spread
  without loss over its jobs, the least the table could take if the fitness cost nothing.

With `--device cuda` it measures the accelerator path instead (fusion/lockstep.py):
generation_ms (one run's generation: construction, fitness of every ant, updates, IWOA
amortised, the run's set-up and CUDA graph captures included, its random-free steps compiled
(lockstep.generation_steps); _eager: compiled, without any CUDA graph; _uncompiled: the graph of
the plain steps, the peer; _steady: what one more generation adds, from a full run less a run of
a fifth of the generations, i.e. one replay of the generation's graph), compile_s (the first
run's extra time: torch.compile, paid once per process and shape), fitness_ms (one generation's
fitness call alone; _cuda_graph: replayed, with cuda_graph_max_abs_diff against the call),
full_run_s, and the same with `--batch-runs` runs in lockstep as `evaluate` runs them, uncompiled
(batched_generation_ms for all of them, per_run_generation_ms; _compiled beside it), against the
goals of issue 30 (SN-S generation ≤ 0.15 ms, SN-D run ≤ 0.5 s on an H100-class GPU).

Calibration data: a paper-protocol draw from `--data` (the target rover's rows) or,
without --data, a synthetic three-class set whose feature means and spreads are of
the same order as the real Fleet-To-Lab windows. Experts: three SN-S/SN-D models
from different seeds, briefly trained on it, so the fitness landscape is not flat.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, TensorDataset

from ..compute import AUTO_THREADS, MAX_THREADS, default_threads, device_label, resolve_device, torch_threads, usable_cores
from ..data.contracts import N_CLASSES
from ..models import build, flatten, load_flat
from ..models.train import class_weights
from .acomerge import AcoMergeConfig, acomerge, construct_departures, evaluate_ants, search_threads
from .buffer import make_buffer
from .finetune import finetune
from .fitness import CalibrationFitness, fitness_seconds
from .lockstep import StackedFitness, graphed, search_lockstep
from ..errors import FleetlabError

TARGET_SPEEDUP = 50.0
TARGET_FULL_RUN_S = 2.0
# issue 30: SN-S on 2 cores, idle and with one core busy; on one H100-class GPU
GOAL_IDLE_RUN_S = 0.35
GOAL_LOADED_RUN_S = 0.6
GOAL_TABLE_S = 60.0  # SN-S paper table: 30 runs x 2 calibration sizes, every registered method, --jobs 2
GOAL_TABLE_RUNS, GOAL_TABLE_JOBS = 30, 2
GOAL_GPU_GENERATION_MS = {"sn-s": 0.15}
GOAL_GPU_RUN_S = {"sn-d": 0.5}
REFERENCE_BATCH = 200  # the reference's D_Cal loader batch size (BATCH_SIZE_ADAPT)

# Per-feature location and spread, same order of magnitude as the real windows (raw units).
_LOC = np.array([3.0, 0.07, 67.0, 14.0, 0.0, 0.7, 0.02, 0.4, 0.0, 1.4, -0.13, -0.03], dtype=np.float32)
_SCALE = np.array([0.4, 0.08, 11.0, 10.0, 0.05, 0.45, 0.05, 0.25, 0.07, 1.2, 0.22, 0.22], dtype=np.float32)


_ACO = AcoMergeConfig()


@dataclass(frozen=True)
class FusionBench:
    """What to measure; the fields are `fleetlab bench fusion`'s options, and their defaults too."""
    arch: str = "sn-s"
    data: Path | None = None  # dataset folder: D_Cal drawn from its target rows (None: synthetic)
    ants: int = _ACO.n_ants
    generations: int = _ACO.generations  # of the full run
    cal_size: int = 200
    repeats: int = 40  # of the batched timing, best kept; the sequential baselines run a tenth as often
    full_runs: int = 5  # complete runs timed, best kept
    threads: int = AUTO_THREADS  # of the batched evaluation
    load: int = 1  # busy processes beside a second set of full runs; 0 skips it
    table_runs: int = 0  # runs of the paper table timed (needs data); 0 skips it
    table_jobs: int = GOAL_TABLE_JOBS
    device: str = "cpu"  # cpu: the reference path; cuda: the GPU path (lockstep engine)
    batch_runs: int = 30  # with a GPU: runs stepped together in the batched measurement
    seed: int = 0


def synthetic_calibration(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Three classes (65/22/13 %, the paper's D_Cal mix) whose means shift with the class."""
    rng = np.random.default_rng(seed)
    y = rng.choice(N_CLASSES, size=n, p=[0.65, 0.22, 0.13])
    shift = np.linspace(-1.0, 1.0, N_CLASSES)[y, None] * _SCALE
    x = _LOC + shift + rng.standard_normal((n, _LOC.size)).astype(np.float32) * _SCALE
    return x.astype(np.float32), y.astype(np.int64)


def _calibration(bench: FusionBench) -> tuple[np.ndarray, np.ndarray, str]:
    if bench.data is None:
        x, y = synthetic_calibration(bench.cal_size, bench.seed)
        return x, y, "synthetic"
    from ..data.dataset import TARGET, load_dataset
    from ..data.splits import make_split

    ds = load_dataset(bench.data)
    x, y = ds.xy(TARGET)
    cal = make_split("paper", y, ds.groups(TARGET), bench.cal_size, bench.seed).cal
    return x[cal], y[cal], f"{bench.data} (target rows, paper split)"


def reference_style_fitness(model, flat: torch.Tensor, loader: DataLoader, y: np.ndarray) -> float:
    """One ant evaluated as the reference does: load weights, mini-batch predictions, numpy CE."""
    load_flat(model, flat)
    model.eval()
    preds, probs = [], []
    with torch.no_grad():
        for (xb,) in loader:
            prob = torch.softmax(model(xb), dim=1)
            preds.extend(prob.argmax(dim=1).numpy())
            probs.extend(prob.numpy())
    p = np.clip(np.array(probs), 1e-8, 1.0)
    counts = np.bincount(y, minlength=N_CLASSES)
    w = (len(y) / (N_CLASSES * np.maximum(counts, 1)))[y]
    return float(-np.sum(w * np.log(p[np.arange(len(y)), y])) / np.sum(w))


def _timed(fn, repeats: int, warmup=None) -> tuple[float, float]:
    """Best (smallest) wall-clock and process-CPU milliseconds of `fn` over `repeats` calls:
    on a shared machine the minimum is the run least disturbed by other processes."""
    (warmup or fn)()
    wall, cpu = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return 1e3 * min(wall), 1e3 * min(cpu)


def measure(bench: FusionBench) -> dict:
    x, y, source = _calibration(bench)
    experts = torch.stack([flatten(finetune(build(bench.arch, seed=bench.seed + k), x, y, steps=30, seed=k)) for k in range(3)])
    buffer = make_buffer(experts, 15, 0.05, bench.seed)
    gen = torch.Generator().manual_seed(bench.seed)
    tau = torch.rand(buffer.shape[1], buffer.shape[0], generator=gen) + 0.5
    departures = construct_departures(tau, None, 0.5, bench.ants, gen)  # early-run pheromone: every ant explores
    ants = buffer.gather(0, departures.dense().long())
    threads = bench.threads or default_threads()
    config = AcoMergeConfig(n_ants=bench.ants, generations=bench.generations, threads=threads)

    fitness = CalibrationFitness(bench.arch, x, y, chunk=config.chunk)
    with search_threads(threads):
        eval_ms, eval_cpu = _timed(lambda: evaluate_ants(departures, buffer, fitness), bench.repeats)
        batched_j = evaluate_ants(departures, buffer, fitness)

    torch.set_num_threads(1)  # the reference's forward passes are far too small for intra-op threads
    model = build(bench.arch)
    xt = torch.from_numpy(x)
    loader = DataLoader(TensorDataset(xt), batch_size=REFERENCE_BATCH, shuffle=False)
    seq_j: list[float] = []

    def sequential():
        seq_j.clear()
        seq_j.extend(reference_style_fitness(model, a, loader, y) for a in ants)

    def warmup():
        for a in ants[:5]:
            reference_style_fitness(model, a, loader, y)

    # the slow baselines: fewer repeats, warm-up on a few ants only
    seq_ms, seq_cpu = _timed(sequential, max(1, bench.repeats // 10), warmup)
    yt, wt = torch.from_numpy(y), class_weights(y)

    def sequential_fullbatch():
        with torch.no_grad():
            for a in ants:
                torch.nn.functional.cross_entropy(load_flat(model, a)(xt), yt, weight=wt)

    full_ms, full_cpu = _timed(sequential_fullbatch, max(1, bench.repeats // 10), warmup)

    run_ms, run_cpu = _timed(lambda: acomerge(experts, bench.arch, x, y, config, seed=bench.seed), bench.full_runs,
                             warmup=lambda: acomerge(experts, bench.arch, x, y, replace(config, generations=2), seed=bench.seed))
    gen_ms, gen_cpu = run_ms / bench.generations, run_cpu / bench.generations
    return {
        "arch": bench.arch, "ants": bench.ants, "generations": bench.generations, "cal_size": int(len(y)),
        "calibration": source, "threads": threads,
        "batched_ms_per_generation": round(eval_ms, 3),
        "sequential_ms_per_generation": round(seq_ms, 3),
        "speedup": round(seq_ms / eval_ms, 2),
        "full_generation_ms": round(gen_ms, 3),
        "speedup_full_generation": round(seq_ms / gen_ms, 2),
        "sequential_fullbatch_ms_per_generation": round(full_ms, 3),
        "speedup_vs_fullbatch": round(full_ms / eval_ms, 2),
        "full_run_s": round(run_ms / 1e3, 3),
        "cpu": {"batched_ms_per_generation": round(eval_cpu, 3), "sequential_ms_per_generation": round(seq_cpu, 3),
                "full_generation_ms": round(gen_cpu, 3),
                "sequential_fullbatch_ms_per_generation": round(full_cpu, 3), "full_run_s": round(run_cpu / 1e3, 3)},
        "load_average_1min": round(os.getloadavg()[0], 2),
        "max_abs_fitness_diff": float(np.max(np.abs(np.array(seq_j) - batched_j.numpy()))),
        "targets": {"speedup": TARGET_SPEEDUP, "full_run_s": TARGET_FULL_RUN_S},
        **({"busy": busy_machine(experts, x, y, bench)} if bench.load else {}),
        **({"table": table_time(bench)} if bench.table_runs else {}),
    }


def table_time(bench: FusionBench) -> dict:
    """The paper table as a user runs it: `fleetlab evaluate` in a child process (its start-up, data
    loading, expert training, every method's jobs and the summary included), wall time against the
    goal, and the CPU seconds per stage and method that evaluate reports."""
    with tempfile.TemporaryDirectory(prefix="fleetlab-table-") as tmp:
        out = Path(tmp) / "table.json"
        cmd = [sys.executable, "-m", "fleetlab.cli", "evaluate", "--data", str(bench.data), "--arch", bench.arch,
               "--runs", str(bench.table_runs), "--jobs", str(bench.table_jobs), "--seed", str(bench.seed),
               "--no-progress", "--json", str(out)]
        t0, c0 = time.perf_counter(), _children_cpu_s()
        done = subprocess.run(cmd, capture_output=True, text=True)
        wall_s, process_cpu_s = time.perf_counter() - t0, _children_cpu_s() - c0
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise FleetlabError(f"the paper table's `fleetlab evaluate` failed (exit {done.returncode}): {last}")
        timing = json.loads(out.read_text())["timing"]
    return {**table_figures(timing, wall_s, process_cpu_s, bench.arch, bench.table_runs, bench.table_jobs),
            "command": " ".join(cmd[2:])}


def table_figures(timing: dict, wall_s: float, process_cpu_s: float, arch: str, runs: int, jobs: int) -> dict:
    """The table's figures from evaluate's `timing`, its wall time and its processes' CPU seconds."""
    cores = min(jobs, usable_cores())
    table = {"runs": runs, "jobs": jobs, "wall_s": round(wall_s, 2),
             "cpu_s": round(timing["cpu_s"], 2),
             # the command's processes in all (evaluate and its workers): start-up, imports, data loading,
             # pickling and the summary are the difference to the jobs' cpu_s
             "process_cpu_s": round(process_cpu_s, 2),
             "sources_cpu_s": {k: round(v, 2) for k, v in timing["sources_cpu_s"].items()},
             "method_cpu_s": {k: round(v, 2) for k, v in timing["method_cpu_s"].items()},
             "method_mean_cpu_s": {k: round(v, 4) for k, v in timing["method_mean_cpu_s"].items()},
             # of the jobs' CPU seconds, those spent in fitness calls: the only part a faster fitness shortens
             "fitness_cpu_s": round(timing["fitness_cpu_s"], 2),
             "method_fitness_cpu_s": {k: round(v, 2) for k, v in timing["method_fitness_cpu_s"].items()},
             # the least wall time the command could take if its fitness cost nothing: the rest of its
             # CPU seconds spread without loss over its jobs (or the cores, if fewer)
             "wall_s_bound_without_fitness": round((process_cpu_s - timing["fitness_cpu_s"]) / cores, 2),
             "bound_cores": cores,
             "load_average_1min": round(os.getloadavg()[0], 2)}
    if arch == "sn-s" and runs == GOAL_TABLE_RUNS and jobs == GOAL_TABLE_JOBS:
        table["goal"] = {"wall_s": GOAL_TABLE_S, "met": wall_s <= GOAL_TABLE_S,
                         "within_reach_of_a_faster_fitness": table["wall_s_bound_without_fitness"] <= GOAL_TABLE_S}
    return table


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's finished children (and theirs, once reaped)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


@contextlib.contextmanager
def busy_processes(n: int):
    """n processes that each keep one core busy until the block ends."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        time.sleep(0.5)  # let the scheduler place them before anything is measured or sampled
        yield
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


def busy_machine(experts: torch.Tensor, x: np.ndarray, y: np.ndarray, bench: FusionBench) -> dict:
    """Full-run times (best of --full-runs) with the threads a run chooses, idle and with --load busy
    processes, and loaded with every core as threads (the fixed choice that collapses)."""
    cores = usable_cores()

    def runs(threads: int) -> tuple[float, int, float]:
        """Best wall seconds of the runs, their threads, and the wall seconds of that run's fitness calls."""
        chosen = threads or default_threads()
        cfg = AcoMergeConfig(n_ants=bench.ants, generations=bench.generations, threads=chosen)
        acomerge(experts, bench.arch, x, y, replace(cfg, generations=2), seed=bench.seed)  # warm-up
        best = (math.inf, 0.0)
        for _ in range(bench.full_runs):
            w0, f0 = time.perf_counter(), fitness_seconds()[0]
            acomerge(experts, bench.arch, x, y, cfg, seed=bench.seed)
            best = min(best, (time.perf_counter() - w0, fitness_seconds()[0] - f0))
        return best[0], chosen, best[1]

    idle_s, idle_threads, idle_fitness_s = runs(bench.threads)
    with busy_processes(bench.load):
        loaded_s, loaded_threads, _ = runs(bench.threads)
        fixed_s, _, _ = runs(min(MAX_THREADS, cores))
    out = {"load": bench.load, "cores": cores, "run_s_idle": round(idle_s, 3), "threads_idle": idle_threads,
           # the idle run's fitness calls, and the rest of it: what no faster fitness would shorten
           "run_s_idle_in_fitness": round(idle_fitness_s, 3),
           "run_s_idle_outside_fitness": round(idle_s - idle_fitness_s, 3),
           "run_s_loaded": round(loaded_s, 3), "threads_loaded": loaded_threads,
           "run_s_loaded_all_cores": round(fixed_s, 3), "threads_all_cores": min(MAX_THREADS, cores),
           "load_average_1min": round(os.getloadavg()[0], 2)}
    if bench.arch == "sn-s":
        out["goals"] = {"run_s_idle": GOAL_IDLE_RUN_S, "run_s_loaded": GOAL_LOADED_RUN_S,
                        "met": idle_s <= GOAL_IDLE_RUN_S and loaded_s <= GOAL_LOADED_RUN_S}
    return out


def measure_device(bench: FusionBench) -> dict:
    """The accelerator path: one run's generation, its fitness call, a full run, R runs batched."""
    device = resolve_device(bench.device)
    x, y, source = _calibration(bench)
    experts = torch.stack([flatten(finetune(build(bench.arch, seed=bench.seed + k), x, y, steps=30, seed=k)) for k in range(3)])
    buffer = make_buffer(experts, 15, 0.05, bench.seed)
    config = AcoMergeConfig(n_ants=bench.ants, generations=bench.generations, device=str(device))
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)

    results = {}

    first_s = {}

    def timed_runs(n_runs: int, generations: int, cuda_graph: bool = True, compiled: bool = True) -> float:
        """Best wall seconds of a lockstep search of n_runs runs (different seeds)."""
        cfg = replace(config, generations=generations)
        fitness = StackedFitness(bench.arch, [(x, y)] * n_runs, device)
        go = lambda: search_lockstep([experts] * n_runs, [buffer] * n_runs, fitness, cfg,  # noqa: E731
                                     [bench.seed + r for r in range(n_runs)], device, cuda_graph=cuda_graph,
                                     compiled=compiled)
        t0 = time.perf_counter()
        results[n_runs, generations, cuda_graph, compiled] = go()  # also the warm-up: compiled, kernels loaded
        sync()
        first_s[n_runs, generations, cuda_graph, compiled] = time.perf_counter() - t0
        best = math.inf
        for _ in range(bench.full_runs):
            t0 = time.perf_counter()
            go()
            sync()
            best = min(best, time.perf_counter() - t0)
        return best

    run_s = timed_runs(1, bench.generations)
    compile_s = first_s[1, bench.generations, True, True] - run_s
    run_s_eager = timed_runs(1, bench.generations, cuda_graph=False)
    run_s_uncompiled = timed_runs(1, bench.generations, compiled=False)
    short = max(1, bench.generations // 5)
    steady_ms = (1e3 * (run_s - timed_runs(1, short)) / (bench.generations - short)
                 if bench.generations > short else math.nan)
    batched_s = timed_runs(bench.batch_runs, bench.generations, compiled=False)  # as `evaluate` runs them
    batched_s_compiled = timed_runs(bench.batch_runs, bench.generations)
    graphed_run, eager_run = results[1, bench.generations, True, True][0], results[1, bench.generations, False, True][0]
    same_search = (graphed_run.history == eager_run.history and torch.equal(graphed_run.best_flat, eager_run.best_flat))
    fitness = StackedFitness(bench.arch, [(x, y)], device)
    gen = torch.Generator(device=device).manual_seed(bench.seed)
    ants = buffer.to(device)[torch.randint(0, buffer.shape[0], (1, bench.ants), generator=gen, device=device)]
    ants = ants + 0.01 * torch.randn(ants.shape, generator=gen, device=device)
    replayed = graphed(fitness, ants)
    graph_diff = float((replayed(ants) - fitness(ants)).abs().max())

    def best_call_s(fn) -> float:
        fn(ants)
        sync()
        best = math.inf
        for _ in range(bench.repeats):
            t0 = time.perf_counter()
            fn(ants)
            sync()
            best = min(best, time.perf_counter() - t0)
        return best

    fit_best, fit_graph = best_call_s(fitness), best_call_s(replayed)
    gen_ms = 1e3 * run_s / bench.generations
    out = {
        "arch": bench.arch, "ants": bench.ants, "generations": bench.generations, "cal_size": int(len(y)),
        "calibration": source, "device": device_label(device),
        "fitness_ms": round(1e3 * fit_best, 4), "fitness_ms_cuda_graph": round(1e3 * fit_graph, 4),
        "cuda_graph_max_abs_diff": graph_diff,
        "generation_ms": round(gen_ms, 4), "generation_ms_eager": round(1e3 * run_s_eager / bench.generations, 4),
        "generation_ms_uncompiled": round(1e3 * run_s_uncompiled / bench.generations, 4),
        "generation_ms_steady": round(steady_ms, 4), "compile_s": round(compile_s, 2),
        "cuda_graph_same_search": same_search,  # the replayed run's history and model equal the eager run's
        "full_run_s": round(run_s, 3), "full_run_s_eager": round(run_s_eager, 3),
        "batch_runs": bench.batch_runs, "batched_generation_ms": round(1e3 * batched_s / bench.generations, 4),
        "per_run_generation_ms": round(1e3 * batched_s / bench.generations / bench.batch_runs, 4),
        "batched_full_runs_s": round(batched_s, 3),
        "batched_generation_ms_compiled": round(1e3 * batched_s_compiled / bench.generations, 4),
    }
    goals = {}
    if bench.arch in GOAL_GPU_GENERATION_MS:
        goals["generation_ms"] = GOAL_GPU_GENERATION_MS[bench.arch]
        goals["generation_ms_met"] = gen_ms <= goals["generation_ms"]
    if bench.arch in GOAL_GPU_RUN_S:
        goals["full_run_s"] = GOAL_GPU_RUN_S[bench.arch]
        goals["full_run_s_met"] = run_s <= goals["full_run_s"]
    out["goals"] = goals
    return out


def figures(bench: FusionBench) -> dict:
    """The figures of `bench`: the CPU reference path, or the accelerator path where `bench.device` names one."""
    device = resolve_device(bench.device)  # one line, before any work, where the GPU is missing
    # each measurement sets the threads it measures with: the caller's count is put back after
    with torch_threads(torch.get_num_threads()):
        return measure(bench) if device.type == "cpu" else measure_device(bench)


def text(result: dict) -> str:
    """The figures as `fleetlab bench fusion` prints them without --json."""
    lines = []
    if "fitness_ms" in result:  # the accelerator path's figures
        lines.append(f"AcoMerge on {result['device']}: {result['arch']}, {result['ants']} ants, |D_Cal| = {result['cal_size']}")
        for key, unit in (("fitness_ms", "ms"), ("fitness_ms_cuda_graph", "ms"), ("generation_ms", "ms"),
                          ("generation_ms_eager", "ms"), ("generation_ms_uncompiled", "ms"),
                          ("generation_ms_steady", "ms"), ("compile_s", "s"), ("full_run_s", "s"),
                          ("full_run_s_eager", "s"), ("batched_generation_ms", "ms"),
                          ("batched_generation_ms_compiled", "ms"), ("per_run_generation_ms", "ms"),
                          ("batched_full_runs_s", "s")):
            lines.append(f"  {key:40s} {result[key]:10.4f} {unit}")
        lines.append(f"  the graph-replayed run is the eager run's search: {result['cuda_graph_same_search']}")
        lines.append(f"  goals: {result['goals']}")
        return "\n".join(lines)
    lines.append(f"AcoMerge benchmark: {result['arch']}, {result['ants']} ants, |D_Cal| = {result['cal_size']} "
                 f"({result['calibration']}), {result['threads']} thread(s)")
    for key in ("batched_ms_per_generation", "sequential_ms_per_generation", "full_generation_ms",
                "sequential_fullbatch_ms_per_generation"):
        lines.append(f"  {key:40s} {result[key]:10.3f} ms")
    lines.append(f"  {'speedup (same ants, reference-style)':40s} {result['speedup']:10.1f} x   (target >= {TARGET_SPEEDUP:g})")
    lines.append(f"  {'speedup (full generation vs sequential)':40s} {result['speedup_full_generation']:10.1f} x")
    lines.append(f"  {'speedup (vs full-batch sequential)':40s} {result['speedup_vs_fullbatch']:10.1f} x")
    lines.append(f"  {'full run, ' + str(result['generations']) + ' generations':40s} {result['full_run_s']:10.3f} s    "
                 f"(target <= {TARGET_FULL_RUN_S:g})")
    lines.append(f"  {'max |batched - sequential| fitness':40s} {result['max_abs_fitness_diff']:10.2e}")
    lines.append(f"  machine load (1 min): {result['load_average_1min']}")
    if "busy" in result:
        b = result["busy"]
        lines.append(f"  full run as the machine is             {b['run_s_idle']:10.3f} s    ({b['threads_idle']} thread(s))")
        lines.append(f"  full run with {b['load']} busy process(es)        {b['run_s_loaded']:10.3f} s    "
                     f"({b['threads_loaded']} thread(s); with {b['threads_all_cores']}: {b['run_s_loaded_all_cores']:.3f} s)")
        lines.append(f"    of the first, fitness calls {b['run_s_idle_in_fitness']:.3f} s, the rest "
                     f"{b['run_s_idle_outside_fitness']:.3f} s (what no faster fitness shortens)")
        if "goals" in b:
            lines.append(f"  goals: <= {GOAL_IDLE_RUN_S} s idle, <= {GOAL_LOADED_RUN_S} s loaded: "
                         f"{'met' if b['goals']['met'] else 'not met'}")
    if "table" in result:
        t = result["table"]
        goal = f"   (goal <= {GOAL_TABLE_S:g} s: {'met' if t['goal']['met'] else 'not met'})" if "goal" in t else ""
        lines.append(f"  paper table, {t['runs']} runs, --jobs {t['jobs']}:    {t['wall_s']:10.1f} s{goal}")
        lines.append(f"    CPU seconds: {t['process_cpu_s']:.1f} for the command's processes, {t['cpu_s']:.1f} of them in "
                     f"the jobs; sources {t['sources_cpu_s']}")
        for m, c in sorted(t["method_cpu_s"].items(), key=lambda kv: -kv[1]):
            lines.append(f"    {m:24s} {c:8.1f} s CPU, {t['method_fitness_cpu_s'][m]:6.1f} s of it in fitness calls   "
                         f"({t['method_mean_cpu_s'][m]:.3f} s per run)")
        lines.append(f"    with a fitness that cost nothing, at least {t['wall_s_bound_without_fitness']:.1f} s on "
                     f"{t['bound_cores']} core(s) ({t['fitness_cpu_s']:.1f} s CPU in fitness calls)")
    return "\n".join(lines)
