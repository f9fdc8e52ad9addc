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
from ..models.train import EXPERT_LR

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
# Fleet ablation: AcoMerge with some of the experts left out of its buffer (same buffer size),
# which measures what the fleet contributes beyond the Earth expert and the search itself.
FLEET_METHODS: tuple[str, ...] = ("acomerge-earth-only", "acomerge-fleet-only")
GROUPS_WITH_BUFFER = {**GROUPS, "Buffer ablation": tuple(BUFFER_METHODS), "Fleet ablation": FLEET_METHODS}
LABELS: dict[str, str] = {
    "joint-ft": "Joint + FullFinetune", "earth-ft": "Earth + FullFinetune", "model-base": "Model Base",
    "adamerging": "AdaMerging", "evomerge": "Evolutionary Merge", "modelswarm": "ModelSwarm",
    "acomerge": "AcoMerge", "distill": "Ensemble distillation", "mmas-only": "MMAS only",
    "iwoa-only": "IWOA only", "buffer-centroid-random": "buffer: experts×3 + centroid-random×45",
    "buffer-random": "buffer: random×48",
    "acomerge-earth-only": "AcoMerge, Earth expert only", "acomerge-fleet-only": "AcoMerge, fleet experts only",
}
ACO_FAMILY = ("acomerge", "mmas-only", "iwoa-only", *BUFFER_METHODS, *FLEET_METHODS)


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
    finetune_lr: float = EXPERT_LR  # Adam rate of Earth/Joint + FullFinetune (the experts' rate)


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


def fleet_ablation_buffer(method: str, aligned: torch.Tensor, seed: int, sigma: float = BUFFER_SIGMA
                          ) -> tuple[torch.Tensor, torch.Tensor]:
    """(kept experts, buffer) of a fleet-ablation method: the Earth expert (row 0) alone, or the
    fleet experts (rows 1..) alone, each with enough perturbed copies to keep the buffer at about
    its full size K·(1 + 15) (exactly 48 for three experts)."""
    from ..fusion.buffer import make_buffer

    n_all = aligned.shape[0]
    if n_all < 2:
        raise ValueError(f"{method} needs the Earth expert and at least one fleet expert, got {n_all} expert(s)")
    kept = aligned[:1] if method == "acomerge-earth-only" else aligned[1:]
    copies = max(0, round(n_all * (1 + BUFFER_COPIES) / kept.shape[0]) - 1)
    return kept, make_buffer(kept, copies=copies, sigma=sigma, seed=seed)


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
        earth = bl.model_from_flat(arch, src.experts[0])
        return flatten(bl.earth_finetune(earth, x_cal, y_cal, seed, steps=steps, lr=budget.finetune_lr)), None
    if method == "joint-ft":
        if src.joint is None:
            raise ValueError("joint-ft needs the joint model, which was not trained")
        joint = bl.model_from_flat(arch, src.joint)
        return flatten(bl.joint_finetune(joint, x_cal, y_cal, seed, steps=steps, lr=budget.finetune_lr)), None
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

        if method in FLEET_METHODS:
            aligned_kept, buffer = fleet_ablation_buffer(method, aligned, buffer_seed, budget.sigma)
        else:
            aligned_kept = aligned
            buffer = make_run_buffer(aligned, BUFFER_METHODS.get(method, "experts"), buffer_seed, budget.sigma)
        variant = method if method in ("mmas-only", "iwoa-only") else "acomerge"
        res = acomerge(aligned_kept, arch, x_cal, y_cal, config=_aco_config(variant, budget), seed=seed, buffer=buffer)
        curve = [float(v) for v in res.history.get("best_so_far", [])]  # best J on D_Cal per generation
        return torch.as_tensor(res.best_flat, dtype=torch.float32), curve
    raise ValueError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
