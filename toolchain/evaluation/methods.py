"""The methods an evaluation can compare, and how one of them is fitted on one D_Cal draw.

Every method returns a flat parameter vector of the evaluated architecture (plus,
for the AcoMerge family, its convergence history). Source models are trained once
per evaluation (`Sources`); only the calibration-dependent search runs per draw.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from ..fusion import baselines as bl
from ..fusion.baselines.modelswarm import BUFFER_COPIES, BUFFER_SIGMA  # 3 experts x (1 + 15) = 48 candidates
from ..models import flatten

# Groups of the paper's table, in its order, and the ablations shown beneath it.
GROUPS: dict[str, tuple[str, ...]] = {
    "Fine-tuned": ("joint-ft", "earth-ft", "model-base"),
    "Merging": ("adamerging", "evomerge", "modelswarm", "acomerge"),
    "Distillation": ("distill",),
    "Ablation": ("mmas-only", "iwoa-only"),
}
METHODS: tuple[str, ...] = tuple(m for ms in GROUPS.values() for m in ms)
# Buffer ablation: AcoMerge on other buffers ("experts" is AcoMerge's own buffer).
BUFFER_METHODS: dict[str, str] = {"buffer-centroid-random": "centroid_random", "buffer-random": "random"}
GROUPS_WITH_BUFFER = {**GROUPS, "Buffer ablation": tuple(BUFFER_METHODS)}
LABELS: dict[str, str] = {
    "joint-ft": "Joint + FullFinetune", "earth-ft": "Earth + FullFinetune", "model-base": "Model Base",
    "adamerging": "AdaMerging", "evomerge": "Evolutionary Merge", "modelswarm": "ModelSwarm",
    "acomerge": "AcoMerge", "distill": "Ensemble distillation", "mmas-only": "MMAS only",
    "iwoa-only": "IWOA only", "buffer-centroid-random": "buffer: experts×3 + centroid-random×45",
    "buffer-random": "buffer: random×48",
}
ACO_FAMILY = ("acomerge", "mmas-only", "iwoa-only", *BUFFER_METHODS)


def parse_methods(text: str | None) -> list[str]:
    """Comma list -> method names in table order; None/'all' -> every method."""
    if text is None or text.strip() == "all":
        return list(METHODS)
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in METHODS]
    if unknown or not names:
        raise ValueError(f"--methods: unknown method(s) {', '.join(unknown) or '(none given)'}; choose from {', '.join(METHODS)}")
    return [m for m in METHODS if m in names]


@dataclass
class Sources:
    """Models trained on the source data (independent of D_Cal): experts, aligned, joint."""

    arch: str
    roles: list[str]
    experts: np.ndarray  # (K, T) float32, Earth first, as trained
    aligned: np.ndarray  # (K, T) float32, Git Re-Basin aligned to the Earth expert
    joint: np.ndarray | None  # (T,) the joint model, if a method needs it
    seconds: dict[str, float]


@dataclass(frozen=True)
class Budget:
    steps: int = bl.BUDGET_STEPS  # AcoMerge generations = optimisation steps of every baseline
    ants: int = 300
    sigma: float = BUFFER_SIGMA  # std of the perturbed copies in the 48-model buffer (paper 0.05)


def _aco_config(variant: str, budget: Budget):
    from ..fusion.acomerge import AcoMergeConfig

    cfg = dataclasses.replace(AcoMergeConfig(), generations=budget.steps, n_ants=budget.ants)
    if variant == "mmas-only":
        cfg = dataclasses.replace(cfg, phases=("mmas",))
    elif variant == "iwoa-only":  # whole-model IWOA over the buffer (ModelSwarm's search, PSO replaced)
        cfg = dataclasses.replace(cfg, phases=("iwoa",))
    return cfg


def make_run_buffer(aligned: torch.Tensor, kind: str, seed: int, sigma: float = BUFFER_SIGMA) -> torch.Tensor:
    from ..fusion.buffer import make_buffer

    return make_buffer(aligned, copies=BUFFER_COPIES, sigma=sigma, seed=seed, kind=kind)


def fit_method(
    method: str, src: Sources, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, buffer_seed: int, budget: Budget
) -> tuple[torch.Tensor, list[float] | None]:
    """Fit `method` on D_Cal. `buffer_seed` is shared by the methods of one draw, so AcoMerge
    and ModelSwarm search exactly the same 48-model buffer."""
    arch, steps = src.arch, budget.steps
    aligned = torch.as_tensor(src.aligned)
    if method == "model-base":
        return flatten(bl.model_base(arch, x_cal, y_cal, seed, steps=steps)), None
    if method == "earth-ft":
        return flatten(bl.earth_finetune(bl.model_from_flat(arch, src.experts[0]), x_cal, y_cal, seed, steps=steps)), None
    if method == "joint-ft":
        if src.joint is None:
            raise ValueError("joint-ft needs the joint model, which was not trained")
        return flatten(bl.joint_finetune(bl.model_from_flat(arch, src.joint), x_cal, y_cal, seed, steps=steps)), None
    if method == "adamerging":
        return bl.adamerging(aligned, arch, x_cal, y_cal, seed, steps=steps), None
    if method == "evomerge":
        return bl.evomerge(aligned, arch, x_cal, y_cal, seed, steps=steps), None
    if method == "modelswarm":
        buffer = make_run_buffer(aligned, "experts", buffer_seed, budget.sigma)
        return bl.modelswarm(aligned, arch, x_cal, y_cal, seed, steps=steps, buffer=buffer), None
    if method == "distill":
        return flatten(bl.distill(torch.as_tensor(src.experts), arch, x_cal, y_cal, seed, steps=steps)), None
    if method in ACO_FAMILY:
        from ..fusion.acomerge import acomerge

        kind = BUFFER_METHODS.get(method, "experts")
        buffer = make_run_buffer(aligned, kind, buffer_seed, budget.sigma)
        variant = method if method in ("mmas-only", "iwoa-only") else "acomerge"
        res = acomerge(aligned, arch, x_cal, y_cal, config=_aco_config(variant, budget), seed=seed, buffer=buffer)
        curve = [float(v) for v in res.history.get("best_so_far", [])]  # best J on D_Cal per generation
        return torch.as_tensor(res.best_flat, dtype=torch.float32), curve
    raise ValueError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
