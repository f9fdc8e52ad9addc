"""AdaMerging (Yang et al., 2024) adapted to D_Cal: learned per-tensor merge coefficients.

merged = base + sum_k lambda[k, t] * tau_k restricted to tensor t, with base = the
Earth expert and tau_k = (aligned fleet expert k) - base (see `common.merge_base`).
The original learns lambda by entropy minimisation on unlabelled test data; here,
as in the paper, lambda is learned on D_Cal by Adam on class-weighted CE (full
batch: D_Cal is a few hundred rows), BUDGET_STEPS updates. lambda starts at 0.3,
the original's initial value; the learning rate 0.01 lets the coefficients move by
about one unit over 130 steps.
"""

from __future__ import annotations

import numpy as np
import torch

from ...models.train import adam, class_weights
from .common import BUDGET_STEPS, as_tensor_xy, merge_base, tensor_slices, weighted_ce_many
from ...errors import InputError

ADAMERGING_LR = 0.01
ADAMERGING_INIT = 0.3


def tensor_index(arch: str) -> torch.Tensor:
    """For every flat parameter, the index of the tensor it belongs to."""
    slices = tensor_slices(arch)
    idx = torch.empty(slices[-1].stop, dtype=torch.long)
    for t, s in enumerate(slices):
        idx[s] = t
    return idx


def merge_with_coefficients(base: torch.Tensor, tau: torch.Tensor, coef: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """base (T,) + sum_k coef[k, index] * tau[k] -> (T,); differentiable in coef."""
    return base + (coef[:, index] * tau).sum(dim=0)


def adamerging(
    aligned: torch.Tensor, arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int = 0,
    steps: int = BUDGET_STEPS, lr: float = ADAMERGING_LR, init: float = ADAMERGING_INIT,
) -> torch.Tensor:
    """Flat parameters of the AdaMerging model. `aligned` is (K, T), Earth expert first.

    Deterministic (full-batch gradients); `seed` is accepted for a uniform baseline signature.
    """
    del seed
    base, tau = merge_base(aligned)
    index = tensor_index(arch)
    if index.numel() != base.numel():
        raise InputError(f"experts have {base.numel()} parameters, {arch} has {index.numel()}")
    xt, yt = as_tensor_xy(x_cal, y_cal)
    w = class_weights(y_cal)
    coef = torch.full((tau.shape[0], int(index.max()) + 1), float(init), requires_grad=True)
    opt = adam([coef], lr, fused=True)
    for _ in range(steps):
        opt.zero_grad()
        loss = weighted_ce_many(arch, merge_with_coefficients(base, tau, coef, index).unsqueeze(0), xt, yt, w)[0]
        loss.backward()
        opt.step()
    with torch.no_grad():
        return merge_with_coefficients(base, tau, coef, index)
