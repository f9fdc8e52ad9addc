"""The MCCV protocol: what one evaluation is, how its calibration draws are made, what one job computes.

One evaluation = one protocol ('paper' random rows, or leakage-free 'traverse'), one architecture, some
calibration sizes and N runs (`EvalSettings`). Run r draws D_Cal with
`make_split(protocol, y, groups, cal_size, seed=r)` — so the draws are paired across methods, seeds and
evaluations — and a job (cal size, run, method) fits the method on it and scores it on the rest of the target
rows (`run_jobs`). Every job seeds itself from (seed, cal size, run, method) and runs torch on one thread, so
its result does not depend on where or when it runs: `executor` may run it anywhere, and a resumed evaluation
reads it back instead.
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass, field

import numpy as np
import torch

from ..compute import torch_threads
from ..data.contracts import N_CLASSES
from ..data.dataset import TARGET, Dataset
from ..data.label_noise import LabelNoise
from ..data.splits import PROTOCOLS, make_split
from ..errors import InputError
from ..fusion.fitness import fitness_seconds
from ..fusion.pipeline import Sources, fuse_many
from ..fusion.registry import Budget
from ..models import batched_logits, canonical_arch
from ..models.train import EXPERT_EPOCHS, check_noise_rate
from .methods import buffer_methods, default_methods, fleet_methods, needs_label_probs, selectable
from .metrics import SCALAR_METRICS, classification_metrics


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
            raise InputError(f"unknown protocol {self.protocol!r}; choose one of {', '.join(PROTOCOLS)}")
        object.__setattr__(self, "arch", canonical_arch(self.arch))  # an InputError names the accepted forms
        b = self.budget
        if self.runs < 1 or self.epochs < 1 or b.steps < 1 or b.ants < 1 or b.sigma < 0 or not b.finetune_lr > 0:
            raise InputError("runs, epochs, generations and ants must all be at least 1, sigma not negative, "
                             "the fine-tuning rate positive")
        check_noise_rate(b.noise_rate, "the assumed label-noise rate (--noise-rate)")
        if not self.cal_sizes or min(self.cal_sizes) < 3:
            raise InputError(f"calibration sizes must be at least 3 rows, got {list(self.cal_sizes)}")
        if self.label_noise:
            object.__setattr__(self, "label_noise", str(LabelNoise.parse(self.label_noise)))
        unknown = set(self.methods) - set(selectable())
        if unknown or not self.methods:
            raise InputError(f"unknown or no methods: {sorted(unknown)}")
        flipped = self.label_noise and LabelNoise.parse(self.label_noise).kind != "vo"
        blind = [m for m in self.methods if needs_label_probs(m)] if flipped else []
        if blind:  # refused before the experts train: these labels carry no measurement to weigh them by
            raise InputError(f"{', '.join(blind)} fit(s) on what each label's measurement says of it, and "
                             f"{self.label_noise} flips labels without one: use exact labels or --label-noise vo:SCALE")

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


@dataclass(frozen=True)
class Target:
    x: np.ndarray
    y: np.ndarray
    groups: np.ndarray
    d_actual: np.ndarray | None = None  # per row: what the VO label model measures again (label_noise vo)
    d_commanded: np.ndarray | None = None
    duration_s: np.ndarray | None = None


NOISE_CODE = method_code("label-noise")  # the noise of a draw is seeded apart from every method's own seed


def target_rows(dataset: Dataset) -> Target:
    """The target rover's rows of `dataset`, with what the label-noise models measure again."""
    x, y = dataset.xy(TARGET)
    table = dataset.table(TARGET)
    return Target(x=x, y=y, groups=dataset.groups(TARGET), d_actual=table.d_actual, d_commanded=table.d_commanded,
                  duration_s=table.duration_s)


def check_draws(dataset: Dataset, settings: EvalSettings, target: Target) -> None:
    """Every calibration draw of the evaluation can be made: refused before hours of work start."""
    too_big = [c for c in settings.cal_sizes if c >= len(target.y)]
    if too_big:
        raise InputError(f"{dataset.root}: calibration size(s) {too_big} leave no test rows ({len(target.y)} target rows)")
    for c in settings.cal_sizes:
        for r in range(settings.runs):
            try:
                make_split(settings.protocol, target.y, target.groups, c, seed=r)
            except InputError as e:
                raise InputError(f"{dataset.root}: run {r}, |D_Cal| = {c}: {e}") from None


def calibration_labels(settings: EvalSettings, cal_size: int, run: int, target: Target,
                       cal: np.ndarray) -> tuple[np.ndarray, dict | None, np.ndarray | None]:
    """(labels, noise record, class probabilities) of D_Cal as the methods see them: exact, or corrupted by
    `settings.label_noise` (the test rows keep their exact labels). Seeded by (seed, cal size, run), not the
    method: every method of a draw sees the same noisy labels, so the comparison stays paired. The
    probabilities (n, 3) are what a label's own measurement says of it: certain for exact labels, VO's reading
    under `vo` (`label_noise.vo_class_probabilities`), None for flips that come with no reading."""
    y = target.y[cal]
    if not settings.label_noise:
        return y, None, np.eye(N_CLASSES)[y]
    noise = LabelNoise.parse(settings.label_noise)
    rng = np.random.default_rng(derive_seed(settings.seed, cal_size, run, NOISE_CODE))
    # every target row is measured (VO's lag reaches the window before, which may be a test row); D_Cal's are kept
    noisy, probs = noise.apply_with_probabilities(target.y, rng, target.d_actual, target.d_commanded, target.groups,
                                                  target.duration_s)
    record = noise.record(y, noisy[cal])
    if probs is not None:  # the windows whose VO did not converge: acomerge-vo leaves them out
        record["vo_dropouts"] = int((probs[cal].sum(axis=1) == 0).sum())
    return noisy[cal], record, None if probs is None else probs[cal]


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
    with torch_threads(1):  # identical float results whatever the worker count
        splits = [make_split(settings.protocol, target.y, target.groups, cal_size, seed=r) for r in runs]
        labels = [calibration_labels(settings, cal_size, r, target, sp.cal) for r, sp in zip(runs, splits)]
        draws = [(target.x[sp.cal], y_cal, derive_seed(settings.seed, cal_size, r, method_code(method)),
                  derive_seed(settings.seed, cal_size, r), probs) for r, sp, (y_cal, _, probs) in zip(runs, splits, labels)]
        t0 = time.perf_counter()
        fused_all = fuse_many(method, src, draws, budget=settings.budget)
        seconds = (time.perf_counter() - t0) / len(runs)
        out = []
        for run, split, fused, (y_cal, noise, _) in zip(runs, splits, fused_all, labels):
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
