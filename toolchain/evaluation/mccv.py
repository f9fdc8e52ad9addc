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
draws dropout masks from a per-process global RNG, which threads would share.
"""

from __future__ import annotations

import contextlib
import sys
import time
import zlib
from dataclasses import asdict, dataclass, field

import joblib
import numpy as np
import torch
from tqdm.auto import tqdm

from ..data.dataset import TARGET, Dataset
from ..data.splits import PROTOCOLS, make_split
from ..models import batched_logits, canonical_arch
from ..fusion.pipeline import Sources, align_sources, fuse, needs_joint, train_expert_flats, train_joint_flat
from ..fusion.registry import Budget
from ..models.train import EXPERT_EPOCHS
from .methods import UNRANKED_GROUPS, buffer_methods, fleet_methods, selectable, table_groups
from .metrics import SCALAR_METRICS, classification_metrics
from .stats import FORMS, corrected_resampled_ttest

BACKENDS = ("loky", "dask")
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
    methods: tuple[str, ...] = field(default_factory=selectable)
    buffer_ablation: bool = False
    fleet_ablation: bool = False

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


def _train_experts_job(dataset: Dataset, settings: EvalSettings, progress: bool) -> tuple[list[str], np.ndarray, float]:
    with single_threaded_torch():
        t0 = time.perf_counter()
        roles, experts = train_expert_flats(dataset, settings.arch, settings.seed, settings.epochs, progress)
        return roles, experts, time.perf_counter() - t0


def _train_joint_job(dataset: Dataset, settings: EvalSettings, progress: bool) -> tuple[np.ndarray, float]:
    with single_threaded_torch():
        t0 = time.perf_counter()
        joint = train_joint_flat(dataset, settings.arch, settings.seed, settings.epochs, progress)
        return joint, time.perf_counter() - t0


def prepare_sources(
    dataset: Dataset, settings: EvalSettings, n_jobs: int = 1, backend: str = "loky",
    scheduler: str | None = None, progress: bool = True,
) -> Sources:
    """Train the experts and (if a method needs it) the joint model — two independent jobs,
    run in parallel when workers allow — then align the experts to the Earth expert."""
    tasks = [joblib.delayed(_train_experts_job)(dataset, settings, progress)]
    if needs_joint(settings.all_methods):
        tasks.append(joblib.delayed(_train_joint_job)(dataset, settings, progress))
    done = execute(tasks, n_jobs, backend, scheduler, progress=False, ordered=True)
    roles, experts, t_experts = done[0]
    seconds = {"experts": t_experts}
    joint = None
    if len(done) > 1:
        joint, seconds["joint"] = done[1]
    with single_threaded_torch():
        return align_sources(settings.arch, roles, experts, joint, seconds)


@dataclass(frozen=True)
class Target:
    x: np.ndarray
    y: np.ndarray
    groups: np.ndarray


def run_job(cal_size: int, run: int, method: str, src: Sources, target: Target, settings: EvalSettings) -> dict:
    """Fit one method on one calibration draw and score it on that draw's test rows."""
    with single_threaded_torch():
        split = make_split(settings.protocol, target.y, target.groups, cal_size, seed=run)
        x_cal, y_cal = target.x[split.cal], target.y[split.cal]
        x_test, y_test = target.x[split.test], target.y[split.test]
        t0 = time.perf_counter()
        fused = fuse(
            method, src, x_cal, y_cal,
            seed=derive_seed(settings.seed, cal_size, run, method_code(method)),
            buffer_seed=derive_seed(settings.seed, cal_size, run),
            budget=settings.budget,
        )
        flat, history = fused.flat, fused.curve
        seconds = time.perf_counter() - t0
        with torch.no_grad():
            pred = batched_logits(src.arch, flat.unsqueeze(0), torch.as_tensor(x_test))[0].argmax(dim=1).numpy()
            pred_cal = batched_logits(src.arch, flat.unsqueeze(0), torch.as_tensor(x_cal))[0].argmax(dim=1).numpy()
    fit = classification_metrics(y_cal, pred_cal)
    return {
        "method": method, "cal_size": cal_size, "run": run, "n_cal": int(len(split.cal)),
        "n_test": int(len(split.test)), "seconds": seconds, "history": history,
        **classification_metrics(y_test, pred),
        # the same scores on D_Cal itself: the fit the method reached, beside what it generalises to
        "calibration_fit": {k: fit[k] for k in SCALAR_METRICS},
    }


def execute(
    tasks: list, n_jobs: int, backend: str, scheduler: str | None, progress: bool, ordered: bool = False
) -> list:
    """Run joblib `delayed` tasks locally (loky) or on a Dask cluster; results in completion
    order, or in task order with `ordered`."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    bar = dict(total=len(tasks), desc="MCCV jobs", disable=not progress)
    return_as = "generator" if ordered else "generator_unordered"
    if backend == "loky":
        runner = joblib.Parallel(n_jobs=min(n_jobs, len(tasks)), backend="loky", return_as=return_as)
        return list(tqdm(runner(tasks), **bar))
    if not scheduler:
        raise ValueError("--backend dask needs --scheduler ADDRESS of a running Dask scheduler")
    from dask.distributed import Client

    with Client(scheduler) as client, joblib.parallel_config(backend="dask"):
        threads = {w["nthreads"] for w in client.scheduler_info()["workers"].values()}
        if any(t > 1 for t in threads):
            # torch seeds dropout through its per-process global RNG: two jobs in threads of one
            # worker would interleave their draws and the numbers would depend on timing.
            print("warning: Dask workers with more than one thread; start them with --nthreads 1 "
                  "for results identical to the local backend", file=sys.stderr)
        runner = joblib.Parallel(n_jobs=-1, return_as=return_as)
        return list(tqdm(runner(tasks), **bar))


def run_mccv(
    dataset: Dataset, settings: EvalSettings, n_jobs: int = 1, backend: str = "loky",
    scheduler: str | None = None, progress: bool = True,
) -> dict:
    """The whole evaluation; returns the JSON-ready result (see `summarise`)."""
    dataset.check_roles()
    x, y = dataset.xy(TARGET)
    target = Target(x=x, y=y, groups=dataset.groups(TARGET))
    too_big = [c for c in settings.cal_sizes if c >= len(y)]
    if too_big:
        raise ValueError(f"{dataset.root}: calibration size(s) {too_big} leave no test rows ({len(y)} target rows)")
    for c in settings.cal_sizes:  # every draw must be possible before hours of work start
        for r in range(settings.runs):
            try:
                make_split(settings.protocol, y, target.groups, c, seed=r)
            except ValueError as e:
                raise ValueError(f"{dataset.root}: run {r}, |D_Cal| = {c}: {e}") from None
    t0 = time.perf_counter()
    src = prepare_sources(dataset, settings, n_jobs, backend, scheduler, progress)
    call = joblib.delayed(run_job)
    tasks = [call(c, r, m, src, target, settings) for c in settings.cal_sizes for r in range(settings.runs)
             for m in settings.all_methods]
    t1 = time.perf_counter()
    jobs = execute(tasks, n_jobs, backend, scheduler, progress)
    order = {m: i for i, m in enumerate(settings.all_methods)}
    jobs.sort(key=lambda j: (j["cal_size"], j["run"], order[j["method"]]))
    out = summarise(jobs, settings)
    out["sources"] = {"roles": src.roles, "trained": "once per evaluation (independent of the calibration draws)",
                      "n_params": int(src.experts.shape[1]), "rejected_nonfinite_rows": dataset.rejected_nonfinite}
    out["timing"] = {
        "sources_s": src.seconds, "mccv_wall_s": time.perf_counter() - t1, "total_wall_s": time.perf_counter() - t0,
        "backend": backend, "jobs": n_jobs,
        "method_mean_s": {m: float(np.mean([j["seconds"] for j in jobs if j["method"] == m])) for m in settings.all_methods},
    }
    return out


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
