"""Fusion methods by name: one signature in, one result type out.

A method is a function `fit(inputs: FusionInputs) -> FusedModel`. It is added with one
`register(...)` call (see `fusion/methods.py` for the paper's methods, which the `fleetlab.fusion`
package registers when it is imported); `fleetlab fuse
--method NAME`, `fleetlab evaluate --methods` and their `--help` read this registry, so a
new method needs no other edit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from ..models import SlipNet, build, load_flat
from ..models.train import EXPERT_LR, FC_RATE
from .acomerge import AcoMergeConfig
from ..errors import InputError

_ACO = AcoMergeConfig()


@dataclass(frozen=True)
class Budget:
    """The shared budget of one comparison; defaults are the paper's (AcoMergeConfig)."""

    steps: int = _ACO.generations  # AcoMerge generations = optimisation steps of every method
    ants: int = _ACO.n_ants  # AcoMerge ants per generation
    sigma: float = _ACO.sigma  # std of the perturbed copies in the expert buffer
    finetune_lr: float = EXPERT_LR  # Adam rate of Earth/Joint + FullFinetune (the experts' rate)
    copies: int = _ACO.copies  # perturbed copies per expert in the buffer: 3 experts x (1 + 15) = 48
    threads: int = 1  # torch intra-op threads of a search that batches its candidates
    device: str = "cpu"  # where AcoMerge searches: 'cpu' (the reference) or a GPU, 'cuda[:N]'
    rng: str = "device"  # where a GPU search draws its random numbers: 'device' or 'host' (AcoMergeConfig.rng)
    # the adjacent label-noise rate ε that the forward-corrected methods (`*-fc`, issue 46) assume D_Cal has
    noise_rate: float = FC_RATE


@dataclass(frozen=True)
class FusionInputs:
    """Everything a method may use: the source models and one calibration draw."""

    arch: str
    roles: tuple[str, ...]  # expert roles, Earth first
    experts: torch.Tensor  # (K, T) float32 flat experts as trained
    aligned: torch.Tensor  # (K, T) the same, Git Re-Basin aligned to the Earth expert
    joint: torch.Tensor | None  # (T,) the joint model, when a method asked for it
    x_cal: np.ndarray
    y_cal: np.ndarray
    seed: int  # the method's own search seed
    buffer_seed: int  # shared by the methods of one draw, so buffer-based methods see one buffer
    budget: Budget = field(default_factory=Budget)
    # (N, 3) what each D_Cal label's own measurement says of it: the probability of each class (all zero:
    # no measurement, e.g. VO did not converge); None where the labels come without one
    y_cal_probs: np.ndarray | None = None


@dataclass
class FusedModel:
    """What every method returns: a flat parameter vector of `arch`, plus its metadata."""

    method: str
    arch: str
    flat: torch.Tensor  # (T,) float32
    curve: list[float] | None = None  # best fitness on D_Cal per step, for searches that keep one
    details: dict = field(default_factory=dict)  # method-specific, JSON-ready (e.g. AcoMerge's history)

    def module(self) -> SlipNet:
        """The fused network in eval mode."""
        return load_flat(build(self.arch), self.flat).eval()


FitFunction = Callable[[FusionInputs], FusedModel]
# Several calibration draws of one budget at once (results in input order): a method that can
# batch its runs (AcoMerge on a GPU) registers one beside its `fit`.
FitManyFunction = Callable[[list[FusionInputs]], list[FusedModel]]


@dataclass(frozen=True)
class MethodSpec:
    name: str
    fit: FitFunction
    label: str  # name in tables and reports
    group: str  # table group ("Merging", ...); ablation groups are only run on request
    needs_joint: bool = False  # the joint model must be trained first
    fit_many: FitManyFunction | None = None  # batched runs, where the method has them
    needs_label_probs: bool = False  # fits on FusionInputs.y_cal_probs, so the labels must come with them


# Groups that only run through their ablation switch, never through `--methods all`.
ABLATION_GROUPS = ("Buffer ablation", "Fleet ablation")
# Groups that `--methods` may name but `--methods all` leaves out: variants for a question of their own
# (noise-robust fusion, issue 46), which would lengthen the paper's table without answering it.
OPT_IN_GROUPS = ("Noise-robust",)
_REGISTRY: dict[str, MethodSpec] = {}


def register(name: str, fit: FitFunction, label: str | None = None, group: str = "Other",
             needs_joint: bool = False, fit_many: FitManyFunction | None = None,
             needs_label_probs: bool = False) -> MethodSpec:
    """Add a method under `name` (lower-case, no commas or spaces); names are unique."""
    if not name or name != name.strip().lower() or any(c in name for c in ", "):
        raise InputError(f"method name {name!r}: use lower-case letters, digits and dashes")
    if name in _REGISTRY and _REGISTRY[name].fit is not fit:
        raise InputError(f"fusion method {name!r} is registered already")
    spec = MethodSpec(name, fit, label or name, group, needs_joint, fit_many, needs_label_probs)
    _REGISTRY[name] = spec
    return spec


def unregister(name: str) -> None:
    """Remove a method (for throw-away methods in tests); unknown names are ignored."""
    _REGISTRY.pop(name, None)


def get(name: str) -> MethodSpec:
    if name not in _REGISTRY:
        raise InputError(f"unknown fusion method {name!r}; choose from {', '.join(selectable())}")
    return _REGISTRY[name]


def all_methods() -> dict[str, MethodSpec]:
    """Every registered method, in registration order (the paper's table order first)."""
    return dict(_REGISTRY)


def selectable() -> tuple[str, ...]:
    """Names that `--methods` / `--method` accept: every method outside the ablation groups."""
    return tuple(n for n, s in all_methods().items() if s.group not in ABLATION_GROUPS)


def default_methods() -> tuple[str, ...]:
    """What `--methods all` runs: every selectable method outside the opt-in groups."""
    return tuple(n for n in selectable() if all_methods()[n].group not in OPT_IN_GROUPS)


def in_group(group: str) -> tuple[str, ...]:
    return tuple(n for n, s in all_methods().items() if s.group == group)


LABEL_PROBS_HINT = ("exact labels, `--label-noise vo:SCALE`, or a calibration file with VO's readings "
                    "(`fleetlab fuse --vo-labels`)")


def check_inputs(name: str, inputs: list[FusionInputs]) -> MethodSpec:
    """The spec of `name`, once `inputs` hold what it needs."""
    spec = get(name)
    if spec.needs_joint and any(i.joint is None for i in inputs):
        raise InputError(f"{name} needs the joint model, which was not trained")
    if spec.needs_label_probs and any(i.y_cal_probs is None for i in inputs):
        raise InputError(f"{name} needs each calibration label's class probabilities from its own measurement, "
                         f"and these labels have none: use {LABEL_PROBS_HINT}")
    return spec


def fit_many(name: str, inputs: list[FusionInputs]) -> list[FusedModel]:
    """Run method `name` on several draws: batched where it registered `fit_many`, else one by one."""
    spec = check_inputs(name, inputs)
    return spec.fit_many(inputs) if spec.fit_many else [spec.fit(i) for i in inputs]


def fit(name: str, inputs: FusionInputs) -> FusedModel:
    """Run method `name` on `inputs`."""
    return check_inputs(name, [inputs]).fit(inputs)
