"""Monte Carlo cross-validation (MCCV) of AcoMerge and its baselines: one evaluation, start to end.

The pieces: `protocol` (the settings, the paired calibration draws, what one job computes), `executor`
(where the jobs run, and the job files a resume reads back), `summary` (means, t-tests, CPU time). This
module trains the source models and schedules the jobs.

The experts, their Re-Basin alignment and the joint model are trained on the source
data only (Earth analog + fleet), which no calibration draw touches: they are trained
ONCE per evaluation (seeded by --seed) and shared by every run. The per-run work is
split into independent jobs (cal size, run, method) executed through joblib (`executor`).
On Dask the source models and the target rows are scattered once to every worker (`broadcast`), and
each task carries only (cal size, run, method). A worker lost at any moment loses nothing: the
scheduler runs its task again elsewhere, and a task whose scattered inputs died with it (the only
copy: Dask's memory manager drops the others) is submitted again with its inputs scattered again
(`dask_backend`), in the source models' training as in the MCCV jobs.

On a GPU (`budget.device` not 'cpu'), the methods that can batch their runs (the AcoMerge
family, `registry.fit_many`) run all the draws of one calibration size in one lockstep
search in this process (one GPU); every other method runs as jobs on the CPU as above.
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from dataclasses import asdict
from pathlib import Path

import joblib
import numpy as np

from ..compute import device_label, resolve_device, torch_threads
from ..data.dataset import Dataset
from ..fusion import registry
from ..fusion.pipeline import Sources, align_sources, needs_joint, source_device, train_expert_flats, train_joint_flat
from ..fusion.registry import Budget
from .executor import Progress, execute, load_done, save_job, save_settings
from .protocol import EvalSettings, check_draws, run_job, run_jobs, target_rows
from .summary import cpu_breakdown, summarise


def _train_experts_job(dataset: Dataset, settings: EvalSettings, progress: bool,
                       device: str) -> tuple[list[str], np.ndarray, dict]:
    with torch_threads(1):
        t0, c0 = time.perf_counter(), time.process_time()
        roles, experts = train_expert_flats(dataset, settings.arch, settings.seed, settings.epochs, progress, device)
        return roles, experts, {"experts": time.perf_counter() - t0, "experts_cpu": time.process_time() - c0}


def _train_joint_job(dataset: Dataset, settings: EvalSettings, progress: bool, device: str) -> tuple[np.ndarray, dict]:
    with torch_threads(1):
        t0, c0 = time.perf_counter(), time.process_time()
        joint = train_joint_flat(dataset, settings.arch, settings.seed, settings.epochs, progress, device)
        return joint, {"joint": time.perf_counter() - t0, "joint_cpu": time.process_time() - c0}


def prepare_sources(
    dataset: Dataset, settings: EvalSettings, n_jobs: int = 1, backend: str = "loky",
    scheduler: str | None = None, progress: bool = True,
) -> Sources:
    """Train the experts and (if a method needs it) the joint model — two independent jobs,
    run in parallel when workers allow, on a local GPU where the search runs on one
    (`pipeline.source_device`) — then align the experts to the Earth expert."""
    # on the GPU this process uses (loky's workers are on this machine), never on Dask's workers
    device = "cpu" if backend == "dask" else source_device(settings.budget.device, settings.budget.rng)
    tasks = [joblib.delayed(_train_experts_job)(dataset, settings, progress, device)]
    if needs_joint(settings.all_methods):
        tasks.append(joblib.delayed(_train_joint_job)(dataset, settings, progress, device))
    done = execute(tasks, n_jobs, backend, scheduler, progress=False, ordered=True)
    roles, experts, seconds = done[0]
    joint = None
    if len(done) > 1:
        joint, joint_seconds = done[1]
        seconds = {**seconds, **joint_seconds}
    with torch_threads(1):
        return align_sources(settings.arch, roles, experts, joint, seconds)


def run_mccv(
    dataset: Dataset, settings: EvalSettings, n_jobs: int = 1, backend: str = "loky",
    scheduler: str | None = None, progress: bool = True, results_dir: Path | None = None, resume: bool = False,
    batch_runs: bool | None = None, sources: Sources | None = None,
) -> dict:
    """The whole evaluation; returns the JSON-ready result (see `summarise`).

    With `results_dir`, every finished job is written there as it finishes (see the module
    docstring); with `resume`, the jobs already there are read back instead of run again.
    `batch_runs` (default: on a GPU) runs the methods that batch their runs in this process,
    beside the other jobs."""
    dataset.check_roles()
    target = target_rows(dataset)
    check_draws(dataset, settings, target)
    device = _device_name(settings.budget.device)  # a missing GPU fails here, before any training
    done = load_done(results_dir, settings) if resume else {}
    if results_dir is not None:
        save_settings(results_dir, settings)
    t0 = time.perf_counter()
    # `sources`: trained by the caller for these settings (a noise sweep trains them once for every rate)
    src = sources or prepare_sources(dataset, settings, n_jobs, backend, scheduler, progress)
    todo = [(c, r, m) for c in settings.cal_sizes for r in range(settings.runs) for m in settings.all_methods
            if (c, r, m) not in done]
    count = lambda keys: {m: sum(1 for k in keys if k[2] == m) for m in settings.all_methods}  # noqa: E731
    bars = Progress(count(todo), count(done), device, progress)

    def finished(results):
        for job in results if isinstance(results, list) else [results]:
            if results_dir is not None:
                save_job(results_dir, job)
            bars.finished(job)
            done[(job["cal_size"], job["run"], job["method"])] = job

    t1 = time.perf_counter()
    on_gpu = device != "cpu"
    batch = on_gpu if batch_runs is None else batch_runs
    batched = [m for m in settings.all_methods if batch and registry.get(m).fit_many is not None]
    call = joblib.delayed(run_job)
    tasks = [call(c, r, m, src, target, _on_cpu(settings) if on_gpu else settings)
             for c, r, m in todo if m not in batched]
    try:
        if not batched:
            execute(tasks, n_jobs, backend, scheduler, progress=False, on_result=finished)
        else:
            # One GPU: the batched methods run in this process, all runs of a calibration size in one
            # search, while the other methods' jobs run on the CPU workers beside them.
            lock = threading.Lock()

            def locked(results):
                with lock:
                    finished(results)

            with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
                cpu_part = pool.submit(execute, tasks, n_jobs, backend, scheduler, False, False, locked)
                for c in settings.cal_sizes:
                    for m in batched:
                        runs = [r for (cc, r, mm) in todo if cc == c and mm == m]
                        if runs:
                            locked(run_jobs(c, runs, m, src, target, settings))
                cpu_part.result()
    finally:
        bars.close()
    order = {m: i for i, m in enumerate(settings.all_methods)}
    jobs = sorted(done.values(), key=lambda j: (j["cal_size"], j["run"], order[j["method"]]))
    out = summarise(jobs, settings)
    out["sources"] = {"roles": src.roles, "trained": "once per evaluation (independent of the calibration draws)",
                      "n_params": int(src.experts.shape[1]), "rejected_nonfinite_rows": dataset.rejected_nonfinite}
    out["timing"] = {
        "sources_s": src.seconds, "mccv_wall_s": time.perf_counter() - t1, "total_wall_s": time.perf_counter() - t0,
        "backend": backend, "jobs": n_jobs, "device": device, "resumed_jobs": len(jobs) - len(todo),
        "method_mean_s": {m: float(np.mean([j["seconds"] for j in jobs if j["method"] == m])) for m in settings.all_methods},
        **cpu_breakdown(jobs, src.seconds, settings.all_methods),
    }
    return out


def _device_name(device: str) -> str:
    return "cpu" if device == "cpu" else device_label(resolve_device(device))


def _on_cpu(settings: EvalSettings) -> EvalSettings:
    """The same settings with the budget on the CPU: the methods that do not batch their runs."""
    return EvalSettings(**{**settings.__dict__, "budget": Budget(**{**asdict(settings.budget), "device": "cpu"})})
