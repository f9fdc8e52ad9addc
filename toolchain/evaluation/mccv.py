"""Monte Carlo cross-validation (MCCV) of AcoMerge and its baselines.

One evaluation = one protocol ('paper' random rows, or leakage-free 'traverse'),
one architecture, some calibration sizes and N runs. Run r draws D_Cal with
`make_split(protocol, y, groups, cal_size, seed=r)` — so the draws are paired across
methods, seeds and evaluations — fits every method on it and scores it on the rest of
the target data.

The experts, their Re-Basin alignment and the joint model are trained on the source
data only (Earth analog + fleet), which no calibration draw touches: they are trained
ONCE per evaluation (seeded by --seed) and shared by every run. The per-run work is
split into independent jobs (cal size, run, method) executed through joblib: local
processes (loky) or an existing Dask cluster (joblib's dask backend). Every job seeds
itself from (seed, cal size, run, method) and runs torch single-threaded, so results
do not depend on the backend, the number of workers or the order of completion.
Dask workers should run one thread each (`dask worker ADDRESS --nthreads 1`): torch
draws dropout masks from a per-process global RNG, which threads would share. On Dask the
source models and the target rows are scattered once to every worker (`broadcast`), and
each task carries only (cal size, run, method). A worker lost at any moment loses nothing: the
scheduler runs its task again elsewhere, and a task whose scattered inputs died with it (the only
copy: Dask's memory manager drops the others) is submitted again with its inputs scattered again
(`dask_backend`), in the source models' training as in the MCCV jobs.

On a GPU (`budget.device` not 'cpu'), the methods that can batch their runs (the AcoMerge
family, `registry.fit_many`) run all the draws of one calibration size in one lockstep
search in this process (one GPU); every other method runs as jobs on the CPU as above.

Every finished job is written at once to RESULTS/runs/<cal>-<run>-<method>.json (atomically:
a temporary file renamed over the name, so a crash leaves either the whole file or none);
`resume` reads them back and runs only the jobs still missing. The jobs' results are the
same whichever run produced them, so a resumed table equals an uninterrupted one.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import json
import os
import tempfile
import threading
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import joblib
import numpy as np
import torch
from tqdm.auto import tqdm

from ..data.dataset import TARGET, Dataset
from ..data.label_noise import LabelNoise
from ..data.splits import PROTOCOLS, make_split
from ..models import batched_logits, canonical_arch
from ..fusion import registry
from ..fusion.fitness import fitness_seconds
from ..fusion.pipeline import (Sources, align_sources, fuse_many, needs_joint, source_device, train_expert_flats,
                               train_joint_flat)
from ..fusion.registry import Budget
from ..models.train import EXPERT_EPOCHS
from .methods import UNRANKED_GROUPS, buffer_methods, default_methods, fleet_methods, selectable, table_groups
from .metrics import SCALAR_METRICS, classification_metrics
from .stats import FORMS, corrected_resampled_ttest

BACKENDS = ("loky", "dask")
RUNS_DIR = "runs"  # per-job results inside an evaluation's results folder
ALPHA = 0.05  # significance level of the best-vs-second t-test


@dataclass(frozen=True)
class EvalSettings:
    protocol: str = "paper"
    arch: str = "sn-s"
    cal_sizes: tuple[int, ...] = (150, 200)
    runs: int = 30
    seed: int = 0
    epochs: int = EXPERT_EPOCHS  # expert (and joint model) epochs
    budget: Budget = field(default_factory=Budget)
    methods: tuple[str, ...] = field(default_factory=default_methods)
    buffer_ablation: bool = False
    fleet_ablation: bool = False
    label_noise: str = ""  # KIND:RATE corrupting D_Cal's labels (data/label_noise.py); "" = exact labels

    def __post_init__(self):
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"unknown protocol {self.protocol!r}; choose one of {', '.join(PROTOCOLS)}")
        object.__setattr__(self, "arch", canonical_arch(self.arch))  # a ValueError names the accepted forms
        b = self.budget
        if self.runs < 1 or self.epochs < 1 or b.steps < 1 or b.ants < 1 or b.sigma < 0 or not b.finetune_lr > 0:
            raise ValueError("runs, epochs, generations and ants must all be at least 1, sigma not negative, "
                             "the fine-tuning rate positive")
        if not self.cal_sizes or min(self.cal_sizes) < 3:
            raise ValueError(f"calibration sizes must be at least 3 rows, got {list(self.cal_sizes)}")
        if self.label_noise:
            object.__setattr__(self, "label_noise", str(LabelNoise.parse(self.label_noise)))
        unknown = set(self.methods) - set(selectable())
        if unknown or not self.methods:
            raise ValueError(f"unknown or no methods: {sorted(unknown)}")

    @property
    def all_methods(self) -> tuple[str, ...]:
        """The methods to run: the chosen ones, plus the buffer and fleet ablations (which need
        AcoMerge itself as their reference)."""
        methods = list(self.methods)
        if (self.buffer_ablation or self.fleet_ablation) and "acomerge" not in methods:
            methods.append("acomerge")
        if self.buffer_ablation:
            methods += list(buffer_methods())
        if self.fleet_ablation:
            methods += list(fleet_methods())
        return tuple(methods)


def derive_seed(*parts: int) -> int:
    """A 31-bit seed from integer parts (numpy SeedSequence: well mixed, order-sensitive)."""
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1)[0] & 0x7FFFFFFF)


def method_code(method: str) -> int:
    return zlib.crc32(method.encode())


@contextlib.contextmanager
def single_threaded_torch():
    """Torch on one thread inside a job: identical float results whatever the worker count."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _train_experts_job(dataset: Dataset, settings: EvalSettings, progress: bool,
                       device: str) -> tuple[list[str], np.ndarray, dict]:
    with single_threaded_torch():
        t0, c0 = time.perf_counter(), time.process_time()
        roles, experts = train_expert_flats(dataset, settings.arch, settings.seed, settings.epochs, progress, device)
        return roles, experts, {"experts": time.perf_counter() - t0, "experts_cpu": time.process_time() - c0}


def _train_joint_job(dataset: Dataset, settings: EvalSettings, progress: bool, device: str) -> tuple[np.ndarray, dict]:
    with single_threaded_torch():
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
    with single_threaded_torch():
        return align_sources(settings.arch, roles, experts, joint, seconds)


@dataclass(frozen=True)
class Target:
    x: np.ndarray
    y: np.ndarray
    groups: np.ndarray
    d_actual: np.ndarray | None = None  # per row: what the VO label model measures again (label_noise vo)
    d_commanded: np.ndarray | None = None
    duration_s: np.ndarray | None = None


NOISE_CODE = method_code("label-noise")  # the noise of a draw is seeded apart from every method's own seed


def calibration_labels(settings: EvalSettings, cal_size: int, run: int, target: Target,
                       cal: np.ndarray) -> tuple[np.ndarray, dict | None]:
    """D_Cal's labels as the methods see them: exact, or corrupted by `settings.label_noise` (the test
    rows keep their exact labels). Seeded by (seed, cal size, run), not the method: every method of a
    draw sees the same noisy labels, so the comparison stays paired."""
    y = target.y[cal]
    if not settings.label_noise:
        return y, None
    noise = LabelNoise.parse(settings.label_noise)
    rng = np.random.default_rng(derive_seed(settings.seed, cal_size, run, NOISE_CODE))
    # every target row is measured (VO's lag reaches the window before, which may be a test row); D_Cal's are kept
    noisy = noise.apply(target.y, rng, target.d_actual, target.d_commanded, target.groups, target.duration_s)[cal]
    return noisy, noise.record(y, noisy)


def run_job(cal_size: int, run: int, method: str, src: Sources, target: Target, settings: EvalSettings) -> dict:
    """Fit one method on one calibration draw and score it on that draw's test rows."""
    return run_jobs(cal_size, [run], method, src, target, settings)[0]


def run_jobs(cal_size: int, runs: list[int], method: str, src: Sources, target: Target,
             settings: EvalSettings) -> list[dict]:
    """Fit one method on several calibration draws (batched where the method batches, i.e.
    AcoMerge on a GPU) and score each on its own test rows. `seconds` is the wall time per run and
    `cpu_seconds` this process's CPU time per run, fit and scoring (the job runs on one thread, so
    it is the job's own work, whatever else the machine runs), `fitness_cpu_seconds` the part of it
    spent in fitness calls on D_Cal (0 for the methods that only train)."""
    c0, f0 = time.process_time(), fitness_seconds()[1]
    with single_threaded_torch():
        splits = [make_split(settings.protocol, target.y, target.groups, cal_size, seed=r) for r in runs]
        labels = [calibration_labels(settings, cal_size, r, target, sp.cal) for r, sp in zip(runs, splits)]
        draws = [(target.x[sp.cal], y_cal, derive_seed(settings.seed, cal_size, r, method_code(method)),
                  derive_seed(settings.seed, cal_size, r)) for r, sp, (y_cal, _) in zip(runs, splits, labels)]
        t0 = time.perf_counter()
        fused_all = fuse_many(method, src, draws, budget=settings.budget)
        seconds = (time.perf_counter() - t0) / len(runs)
        out = []
        for run, split, fused, (y_cal, noise) in zip(runs, splits, fused_all, labels):
            x_cal = target.x[split.cal]
            x_test, y_test = target.x[split.test], target.y[split.test]
            flat = fused.flat.cpu()
            with torch.no_grad():
                pred = batched_logits(src.arch, flat.unsqueeze(0), torch.as_tensor(x_test))[0].argmax(dim=1).numpy()
                pred_cal = batched_logits(src.arch, flat.unsqueeze(0), torch.as_tensor(x_cal))[0].argmax(dim=1).numpy()
            fit = classification_metrics(y_cal, pred_cal)
            out.append({
                "method": method, "cal_size": cal_size, "run": run, "n_cal": int(len(split.cal)),
                "n_test": int(len(split.test)), "seconds": seconds, "history": fused.curve,
                **classification_metrics(y_test, pred),
                # the same scores on D_Cal itself (its labels as the method saw them): the fit the method
                # reached, beside what it generalises to
                "calibration_fit": {k: fit[k] for k in SCALAR_METRICS},
                **({"label_noise": noise} if noise else {}),
            })
    cpu_seconds = (time.process_time() - c0) / len(runs)
    fitness_cpu_seconds = (fitness_seconds()[1] - f0) / len(runs)
    for job in out:
        job["cpu_seconds"] = cpu_seconds
        job["fitness_cpu_seconds"] = fitness_cpu_seconds
    return out


def job_file(folder: Path, cal_size: int, run: int, method: str) -> Path:
    return Path(folder) / RUNS_DIR / f"{cal_size}-{run}-{method}.json"


def write_atomic(path: Path, text: str) -> None:
    """Write `text` to `path` so that a crash leaves the old file or the whole new one, never a part."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _settings_key(settings: EvalSettings) -> dict:
    """What a saved job depends on (JSON-normalised): a resume must use the same settings."""
    return json.loads(json.dumps(asdict(settings)))


def load_done(folder: Path, settings: EvalSettings) -> dict[tuple[int, int, str], dict]:
    """The jobs already finished in `folder` (written by an earlier, maybe interrupted, evaluation)."""
    folder = Path(folder)
    saved = folder / RUNS_DIR / "settings.json"
    if not saved.is_file():
        raise ValueError(f"--resume {folder}: no {RUNS_DIR}/settings.json there (not an evaluation's results folder)")
    if json.loads(saved.read_text()) != _settings_key(settings):
        raise ValueError(f"--resume {folder}: it was made with other settings ({saved}); use the same options")
    done = {}
    for c in settings.cal_sizes:
        for r in range(settings.runs):
            for m in settings.all_methods:
                path = job_file(folder, c, r, m)
                if path.is_file():
                    done[(c, r, m)] = json.loads(path.read_text())
    return done


class _Progress:
    """One bar per method (runs done of runs to do, with the time left), for any backend."""

    def __init__(self, todo: dict[str, int], done: dict[str, int], device: str, enabled: bool):
        self.bars = {m: tqdm(total=todo[m] + done.get(m, 0), initial=done.get(m, 0), position=i, leave=True,
                             desc=f"{m} [{device}]", unit="run", disable=not enabled, dynamic_ncols=True)
                     for i, m in enumerate(todo)}

    def finished(self, job: dict) -> None:
        bar = self.bars[job["method"]]
        bar.set_postfix_str(f"|D_Cal|={job['cal_size']} run {job['run']}", refresh=False)
        bar.update(1)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()


def execute(
    tasks: list, n_jobs: int, backend: str, scheduler: str | None, progress: bool, ordered: bool = False,
    on_result=None,
) -> list:
    """Run joblib `delayed` tasks locally (loky) or on a Dask cluster; results in completion
    order, or in task order with `ordered`. `on_result(result)` is called as each one finishes.

    On Dask (`dask_backend`), arguments shared by the tasks (the sources, the target rows) are scattered
    once to every worker; a task lost with a worker, or whose inputs were, runs again on another."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if not tasks:
        return []
    bar = tqdm(total=len(tasks), desc="MCCV jobs", disable=not progress)
    done = []

    def finished(result):
        done.append(result)
        bar.update(1)
        if on_result is not None:
            on_result(result)

    try:
        if backend == "loky":
            runner = joblib.Parallel(n_jobs=min(n_jobs, len(tasks)), backend="loky",
                                     return_as="generator" if ordered else "generator_unordered")
            for result in runner(tasks):
                finished(result)
            return done
        if not scheduler:
            raise ValueError("--backend dask needs --scheduler ADDRESS of a running Dask scheduler")
        from .dask_backend import run_on_dask

        return run_on_dask(tasks, scheduler, ordered, finished)
    finally:
        bar.close()


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
    x, y = dataset.xy(TARGET)
    table = dataset.table(TARGET)
    target = Target(x=x, y=y, groups=dataset.groups(TARGET), d_actual=table.d_actual, d_commanded=table.d_commanded,
                    duration_s=table.duration_s)
    too_big = [c for c in settings.cal_sizes if c >= len(y)]
    if too_big:
        raise ValueError(f"{dataset.root}: calibration size(s) {too_big} leave no test rows ({len(y)} target rows)")
    for c in settings.cal_sizes:  # every draw must be possible before hours of work start
        for r in range(settings.runs):
            try:
                make_split(settings.protocol, y, target.groups, c, seed=r)
            except ValueError as e:
                raise ValueError(f"{dataset.root}: run {r}, |D_Cal| = {c}: {e}") from None
    device = _device_name(settings.budget.device)  # a missing GPU fails here, before any training
    done = load_done(results_dir, settings) if resume else {}
    if results_dir is not None:
        write_atomic(Path(results_dir) / RUNS_DIR / "settings.json", json.dumps(_settings_key(settings)))
    t0 = time.perf_counter()
    # `sources`: trained by the caller for these settings (a noise sweep trains them once for every rate)
    src = sources or prepare_sources(dataset, settings, n_jobs, backend, scheduler, progress)
    todo = [(c, r, m) for c in settings.cal_sizes for r in range(settings.runs) for m in settings.all_methods
            if (c, r, m) not in done]
    count = lambda keys: {m: sum(1 for k in keys if k[2] == m) for m in settings.all_methods}  # noqa: E731
    bars = _Progress(count(todo), count(done), device, progress)

    def finished(results):
        for job in results if isinstance(results, list) else [results]:
            if results_dir is not None:
                write_atomic(job_file(results_dir, job["cal_size"], job["run"], job["method"]), json.dumps(job))
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


def cpu_breakdown(jobs: list[dict], source_seconds: dict[str, float], methods: tuple[str, ...]) -> dict:
    """Where the evaluation's CPU time went: the source models' training (CPU seconds of their jobs)
    and every method's jobs (sum over its runs, and the mean per run), and of the jobs' time the part
    spent in fitness calls. CPU time, not wall time: on a shared machine it is what the work itself
    cost. Jobs read back by --resume from an older fleetlab may lack it (counted as missing)."""
    timed = [j for j in jobs if "cpu_seconds" in j and "fitness_cpu_seconds" in j]
    per_method = {m: float(sum(j["cpu_seconds"] for j in timed if j["method"] == m)) for m in methods}
    in_fitness = {m: float(sum(j["fitness_cpu_seconds"] for j in timed if j["method"] == m)) for m in methods}
    sources = {k[: -len("_cpu")]: v for k, v in source_seconds.items() if k.endswith("_cpu")}
    return {
        "sources_cpu_s": sources,
        "method_cpu_s": per_method,
        "method_mean_cpu_s": {m: per_method[m] / max(1, sum(1 for j in timed if j["method"] == m)) for m in methods},
        "method_fitness_cpu_s": in_fitness,
        "cpu_s": float(sum(sources.values()) + sum(per_method.values())),
        "fitness_cpu_s": float(sum(in_fitness.values())),
        "jobs_without_cpu_time": len(jobs) - len(timed),
    }


def _device_name(device: str) -> str:
    if device == "cpu":
        return "cpu"
    from ..fusion.lockstep import device_label, resolve_device

    return device_label(resolve_device(device))


def _on_cpu(settings: EvalSettings) -> EvalSettings:
    """The same settings with the budget on the CPU: the methods that do not batch their runs."""
    return EvalSettings(**{**settings.__dict__, "budget": Budget(**{**asdict(settings.budget), "device": "cpu"})})


def _mean_std(values: list) -> dict:
    a = np.asarray(values, dtype=float)
    std = a.std(axis=0, ddof=1) if a.shape[0] > 1 else np.zeros_like(a[0])
    mean = a.mean(axis=0)
    return {"mean": mean.tolist(), "std": std.tolist()}


def summarise(jobs: list[dict], settings: EvalSettings) -> dict:
    """Per method and cal size: mean ± std over runs (sample std, ddof=1) of every metric, the
    per-run scores, summed confusion matrices; t-test of best vs second; convergence curves.

    JSON layout: {"results": {METHOD: {"150": {"balanced_accuracy": {"mean", "std", "runs"},
    "macro_f1": {...}, "precision": {...}, "recall": {...}, "confusion_matrix": ...,
    "calibration_fit": {"balanced_accuracy": {"mean", "std"}, "macro_f1": {...}}, ...}}},
    "ttest": {...}, "convergence": {...}, "config": {...}}.
    """
    results: dict[str, dict] = {}
    convergence: dict[str, dict] = {}
    for m in settings.all_methods:
        results[m], convergence_m = {}, {}
        for c in settings.cal_sizes:
            rs = [j for j in jobs if j["method"] == m and j["cal_size"] == c]
            entry = {k: {**_mean_std([r[k] for r in rs]), "runs": [r[k] for r in rs]} for k in SCALAR_METRICS}
            entry.update({k: _mean_std([r[k] for r in rs]) for k in ("precision", "recall")})
            entry["confusion_matrix"] = np.sum([r["confusion_matrix"] for r in rs], axis=0).tolist()
            entry["calibration_fit"] = {k: _mean_std([r["calibration_fit"][k] for r in rs]) for k in SCALAR_METRICS}
            entry["n_runs"] = len(rs)
            entry["n_cal"] = int(rs[0]["n_cal"])
            if "label_noise" in rs[0]:  # the same corrupted labels for every method of a draw
                corrupted = [r["label_noise"]["corrupted"] for r in rs]
                entry["label_noise"] = {"model": settings.label_noise, "corrupted_mean": float(np.mean(corrupted)),
                                        "corrupted_fraction": float(np.sum(corrupted) / np.sum(
                                            [r["label_noise"]["of"] for r in rs]))}
            entry["n_test_mean"] = float(np.mean([r["n_test"] for r in rs]))
            results[m][str(c)] = entry
            if rs[0]["history"]:  # methods that keep a convergence curve
                convergence_m[str(c)] = _mean_std([r["history"] for r in rs])
        if convergence_m:
            convergence[m] = convergence_m
    return {
        "results": results,
        "ttest": best_vs_second(results, settings),
        "convergence": convergence,
        "config": {**asdict(settings), "methods": list(settings.all_methods), "split_seed": "run index",
                   "std": "sample std over runs (ddof=1)"},
    }


def table_methods(results: dict) -> list[str]:
    """Methods that compete for best/second: the paper's table (not the ablations)."""
    main = [m for g, ms in table_groups().items() if g not in UNRANKED_GROUPS for m in ms]
    return [m for m in main if m in results]


def best_vs_second(results: dict, settings: EvalSettings) -> dict:
    """For every cal size and metric: rank the table's methods by mean, and test best vs second
    with the corrected resampled t-test on their paired per-run scores (see `stats`)."""
    out: dict[str, dict] = {}
    methods = table_methods(results)
    for c in map(str, settings.cal_sizes):
        out[c] = {}
        for metric in SCALAR_METRICS:
            ranked = sorted(methods, key=lambda m: -results[m][c][metric]["mean"])
            entry: dict = {"ranking": ranked}
            if len(ranked) >= 2 and settings.runs >= 2:
                best, second = ranked[:2]
                n_train, n_test = results[best][c]["n_cal"], results[best][c]["n_test_mean"]
                a, b = results[best][c][metric]["runs"], results[second][c][metric]["runs"]
                tests = {form: corrected_resampled_ttest(a, b, n_train, n_test, form).as_dict() for form in FORMS}
                entry.update(best=best, second=second, n_train=n_train, n_test=n_test, alpha=ALPHA,
                             significant=bool(tests["nadeau-bengio"]["p"] < ALPHA), tests=tests)
            out[c][metric] = entry
    return out
