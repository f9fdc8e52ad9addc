"""Multi-teacher ensemble distillation (Hinton et al., 2015) on D_Cal.

The experts are frozen teachers; their temperature-softened class distributions are
averaged. A fresh student is trained on D_Cal with
    loss = alpha * T^2 * KL(p_teachers || p_student at T) + (1 - alpha) * weighted CE
(the T^2 factor keeps the soft-target gradients on the scale of the hard-label ones).
Defaults: T = 2, alpha = 0.5, Adam lr 0.01, batch 32, BUDGET_STEPS updates — the same
optimiser settings as Model Base, which is the same student without the teachers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch.nn import functional as F

from ...models import SlipNet, batched_logits, build
from ...models.train import EXPERT_BATCH, adam, class_weights
from .common import BUDGET_STEPS, as_tensor_xy
from ...errors import InputError

DISTILL_LR = 0.01
TEMPERATURE = 2.0
ALPHA = 0.5


@torch.no_grad()
def teacher_distribution(arch: str, teachers: torch.Tensor, x: torch.Tensor, temperature: float) -> torch.Tensor:
    """Mean over teachers (K, T) of softmax(logits / T): (N, C)."""
    return torch.softmax(batched_logits(arch, teachers, x) / temperature, dim=-1).mean(dim=0)


def distill_loss(student_logits, soft_targets, y, weights, temperature: float, alpha: float) -> torch.Tensor:
    kl = F.kl_div(F.log_softmax(student_logits / temperature, dim=-1), soft_targets, reduction="batchmean")
    ce = F.cross_entropy(student_logits, y, weight=weights)
    return alpha * temperature**2 * kl + (1.0 - alpha) * ce


def distill(
    teachers: torch.Tensor | Sequence[torch.Tensor], arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int = 0,
    steps: int = BUDGET_STEPS, lr: float = DISTILL_LR, batch_size: int = EXPERT_BATCH,
    temperature: float = TEMPERATURE, alpha: float = ALPHA,
) -> SlipNet:
    """A student (init from `seed`) distilled from the teachers' flats (K, T) on D_Cal."""
    if not 0.0 <= alpha <= 1.0 or temperature <= 0:
        raise InputError(f"need 0 <= alpha <= 1 and temperature > 0, got alpha={alpha}, T={temperature}")
    teachers = torch.stack(list(teachers)) if not torch.is_tensor(teachers) else teachers
    xt, yt = as_tensor_xy(x_cal, y_cal)
    soft = teacher_distribution(arch, teachers.float(), xt, temperature)
    weights = class_weights(y_cal)
    student = build(arch, seed=seed)
    opt = adam(student.parameters(), lr, fused=True)
    gen = torch.Generator().manual_seed(seed)
    n, batch_size = len(yt), min(batch_size, len(yt))
    done = 0
    student.train()
    with torch.random.fork_rng():
        torch.manual_seed(seed)  # dropout masks
        while done < steps:
            order = torch.randperm(n, generator=gen)
            for i in range(0, n, batch_size):
                idx = order[i : i + batch_size]
                opt.zero_grad()
                distill_loss(student(xt[idx]), soft[idx], yt[idx], weights, temperature, alpha).backward()
                opt.step()
                done += 1
                if done >= steps:
                    break
    return student.eval()
