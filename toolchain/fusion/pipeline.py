"""The fusion pipeline shared by `fleetlab fuse`, `fleetlab evaluate` and the demo:
source experts (and the joint model) -> Git Re-Basin alignment -> one registered method.

The source models depend on the source data only, never on a calibration draw, so an
evaluation prepares them once and fuses many times.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from ..data.dataset import Dataset
from ..models import flatten
from ..models.train import EXPERT_EPOCHS
from . import registry
from .registry import Budget, FusedModel, FusionInputs


@dataclass
class Sources:
    """Models trained on the source data (independent of D_Cal): experts, aligned, joint."""

    arch: str
    roles: list[str]
    experts: np.ndarray  # (K, T) float32, Earth first, as trained
    aligned: np.ndarray  # (K, T) float32, Git Re-Basin aligned to the Earth expert
    joint: np.ndarray | None  # (T,) the joint model, if a method needs it
    seconds: dict[str, float]


def source_device(device: str, rng: str) -> str:
    """Where the source models train: on the search's GPU (each step one replayed CUDA graph, 4-10x
    a CPU thread's speed), except with rng='host', whose point is to follow the CPU reference run:
    its sources must then be the CPU's, bit for bit."""
    return device if device != "cpu" and rng == "device" else "cpu"


def train_expert_flats(dataset: Dataset, arch: str, seed: int, epochs: int = EXPERT_EPOCHS,
                       progress: bool = True, device: str = "cpu") -> tuple[list[str], np.ndarray]:
    """(roles, (K, T) flat experts), one expert per source role, Earth first."""
    from .experts import train_experts

    experts = train_experts(dataset, arch, seed=seed, epochs=epochs, progress=progress, device=device)
    return list(experts), torch.stack([flatten(m) for m in experts.values()]).numpy()


def train_joint_flat(dataset: Dataset, arch: str, seed: int, epochs: int = EXPERT_EPOCHS,
                     progress: bool = True, device: str = "cpu") -> np.ndarray:
    """The joint model (trained on Earth and every fleet rover pooled), flat."""
    from .baselines import train_joint

    return flatten(train_joint(dataset, arch, seed=seed, epochs=epochs, progress=progress, device=device)).numpy()


def align_sources(arch: str, roles: list[str], experts: np.ndarray, joint: np.ndarray | None,
                  seconds: dict[str, float]) -> Sources:
    """Align the experts to the Earth expert (row 0) with Git Re-Basin."""
    from .baselines import model_from_flat
    from .rebasin import align_to_reference

    t0 = time.perf_counter()
    models = [model_from_flat(arch, torch.as_tensor(e)) for e in experts]
    aligned = torch.stack(align_to_reference(models, arch, reference=0))
    seconds = {**seconds, "rebasin": time.perf_counter() - t0}
    return Sources(arch=arch, roles=list(roles), experts=experts, aligned=aligned.to(torch.float32).numpy(),
                   joint=joint, seconds=seconds)


def prepare_sources(dataset: Dataset, arch: str, seed: int, epochs: int = EXPERT_EPOCHS, joint: bool = False,
                    progress: bool = True, device: str = "cpu") -> Sources:
    """Train the experts (and the joint model if asked) on `device`, then align them: one process, in turn."""
    t0 = time.perf_counter()
    roles, experts = train_expert_flats(dataset, arch, seed, epochs, progress, device)
    seconds = {"experts": time.perf_counter() - t0}
    joint_flat = None
    if joint:
        t0 = time.perf_counter()
        joint_flat = train_joint_flat(dataset, arch, seed, epochs, progress, device)
        seconds["joint"] = time.perf_counter() - t0
    return align_sources(arch, roles, experts, joint_flat, seconds)


def needs_joint(methods) -> bool:
    return any(registry.get(m).needs_joint for m in methods)


def _inputs(src: Sources, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, buffer_seed: int,
            budget: Budget, y_cal_probs: np.ndarray | None = None) -> FusionInputs:
    return FusionInputs(
        arch=src.arch, roles=tuple(src.roles), experts=torch.as_tensor(src.experts),
        aligned=torch.as_tensor(src.aligned), joint=None if src.joint is None else torch.as_tensor(src.joint),
        x_cal=x_cal, y_cal=y_cal, seed=seed, buffer_seed=buffer_seed, budget=budget, y_cal_probs=y_cal_probs)


def fuse(method: str, src: Sources, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, buffer_seed: int,
         budget: Budget = Budget(), y_cal_probs: np.ndarray | None = None) -> FusedModel:
    """Fit registered method `method` on one calibration set (`y_cal_probs`: FusionInputs)."""
    return registry.fit(method, _inputs(src, x_cal, y_cal, seed, buffer_seed, budget, y_cal_probs))


def fuse_many(method: str, src: Sources, draws: list[tuple[np.ndarray, np.ndarray, int, int, np.ndarray | None]],
              budget: Budget = Budget()) -> list[FusedModel]:
    """Fit `method` on several calibration sets (x_cal, y_cal, seed, buffer_seed, y_cal_probs), batched
    where the method can batch its runs (AcoMerge on a GPU), in order."""
    return registry.fit_many(method, [_inputs(src, x, y, s, b, budget, p) for x, y, s, b, p in draws])
