"""Evolutionary Model Merge (Akiba et al., 2025), parameter-space variant.

CMA-ES (the `cma` package) searches layer-wise DARE-TIES coefficients: for every
fleet expert k and layer l (each hidden block, and the head) one merge weight and
one DARE density. Base and task vectors as in `common.merge_base` (Earth expert as
base). Fitness: class-weighted CE on D_Cal of the merged model; one CMA-ES
generation (its default population, all candidates evaluated in one batch) is one
step of the budget. DARE's random drop uses one fixed set of draws per run, so the
fitness is a deterministic function of the coefficients (common random numbers).
Start: weight 0.5, density 0.5, step size 0.2 — merges of half strength and half
the entries; weights bounded to [0, 1.5], densities to [0.05, 1].
"""

from __future__ import annotations

import cma
import numpy as np
import torch

from .common import BUDGET_STEPS, cal_objective, layer_slices, merge_base
from .dare_ties import dare_ties_merge
from ...errors import InputError

WEIGHT_BOUNDS = (0.0, 1.5)
DENSITY_BOUNDS = (0.05, 1.0)
X0_WEIGHT, X0_DENSITY, SIGMA0 = 0.5, 0.5, 0.2


def expand_layerwise(values: torch.Tensor, arch: str) -> torch.Tensor:
    """(..., K, L) per-layer values -> (..., K, T) per-parameter values."""
    sizes = torch.tensor([s.stop - s.start for s in layer_slices(arch)])
    return torch.repeat_interleave(values, sizes, dim=-1)


def evomerge(
    aligned: torch.Tensor, arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int = 0,
    steps: int = BUDGET_STEPS, popsize: int | None = None,
) -> torch.Tensor:
    """Flat parameters of the best DARE-TIES merge found by CMA-ES. `aligned` (K, T), Earth first."""
    base, tau = merge_base(aligned)
    n_k, n_l = tau.shape[0], len(layer_slices(arch))
    if layer_slices(arch)[-1].stop != base.numel():
        raise InputError(f"experts have {base.numel()} parameters, not an {arch} model")
    u = torch.rand(tau.shape, generator=torch.Generator().manual_seed(seed))
    loss = cal_objective(arch, x_cal, y_cal)
    dim = n_k * n_l

    def merged(xs: np.ndarray) -> torch.Tensor:
        xs_t = torch.as_tensor(np.asarray(xs), dtype=torch.float32).reshape(-1, 2, n_k, n_l)
        weight = expand_layerwise(xs_t[:, 0], arch)
        density = expand_layerwise(xs_t[:, 1], arch)
        return dare_ties_merge(base, tau, weight, density, u)

    lower = [WEIGHT_BOUNDS[0]] * dim + [DENSITY_BOUNDS[0]] * dim
    upper = [WEIGHT_BOUNDS[1]] * dim + [DENSITY_BOUNDS[1]] * dim
    opts = {"bounds": [lower, upper], "seed": int(seed) % (2**31 - 1) + 1, "verbose": -9, "maxiter": steps}
    if popsize:
        opts["popsize"] = popsize
    es = cma.CMAEvolutionStrategy([X0_WEIGHT] * dim + [X0_DENSITY] * dim, SIGMA0, opts)
    best_x, best_f = np.array(es.x0, dtype=float), float(loss(merged(es.x0[None]))[0])
    for _ in range(steps):
        if es.stop():
            break
        xs = es.ask()
        f = loss(merged(np.array(xs))).double().numpy()
        es.tell(xs, f.tolist())
        i = int(np.argmin(f))
        if f[i] < best_f:  # keep the best ever evaluated candidate
            best_x, best_f = np.array(xs[i], dtype=float), float(f[i])
    return merged(best_x[None])[0]
