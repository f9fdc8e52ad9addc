"""ModelSwarm (Feng et al., 2024): particle swarm optimisation in weight space.

Each particle is one model of the same buffer AcoMerge searches (the aligned experts
plus Gaussian-perturbed copies, 48 models; `fleetlab.fusion.buffer.make_buffer`).
Velocity update with Model Swarms' four terms — inertia, personal best, global best,
and repulsion from the global worst:
    v <- w_v v + w_p r_p (p_i - x) + w_g r_g (g - x) - w_w r_w (g_worst - x)
    x <- x + step * v,    step <- step * decay
with r_* ~ U(0, 1) drawn per particle and term. Utility: class-weighted CE on D_Cal
(lower is better). One swarm iteration (all particles evaluated in one batch) is one
step of the budget; the best position ever visited is returned.
Defaults (inertia 0.4, cognitive 0.3, social 0.3, repel 0.1, step 0.5 decaying by
0.98 per iteration, initial velocity towards a random other particle) follow the
shape of Model Swarms' search, scaled to 130 iterations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..acomerge import AcoMergeConfig
from ..buffer import make_buffer
from .common import BUDGET_STEPS, cal_objective
from ...errors import InputError

# AcoMerge's buffer: each expert plus 15 copies with Gaussian noise of sigma 0.05 (paper).
BUFFER_COPIES = AcoMergeConfig.copies
BUFFER_SIGMA = AcoMergeConfig.sigma


@dataclass(frozen=True)
class SwarmConfig:
    inertia: float = 0.4
    cognitive: float = 0.3
    social: float = 0.3
    repel: float = 0.1
    step: float = 0.5
    step_decay: float = 0.98


def pso(
    buffer: torch.Tensor, arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int = 0,
    steps: int = BUDGET_STEPS, config: SwarmConfig | None = None,
) -> tuple[torch.Tensor, list[float]]:
    """Run the swarm from the particles in `buffer` (M, T). Returns (best flat, best loss per step)."""
    cfg = config or SwarmConfig()
    x = torch.as_tensor(buffer, dtype=torch.float32).clone()
    if x.ndim != 2 or x.shape[0] < 2:
        raise InputError(f"a swarm needs a (M>=2, T) buffer, got shape {tuple(x.shape)}")
    m = x.shape[0]
    gen = torch.Generator().manual_seed(seed)
    loss = cal_objective(arch, x_cal, y_cal)
    f = loss(x)
    partner = (torch.arange(m) + torch.randint(1, m, (m,), generator=gen)) % m  # never itself
    v = x[partner] - x
    p_best, p_f = x.clone(), f.clone()
    g_i = int(torch.argmin(f))
    g_best, g_f = x[g_i].clone(), float(f[g_i])
    g_worst = x[int(torch.argmax(f))].clone()
    step = cfg.step
    history: list[float] = []
    for _ in range(steps):
        r = torch.rand(3, m, 1, generator=gen)
        v = (cfg.inertia * v + cfg.cognitive * r[0] * (p_best - x) + cfg.social * r[1] * (g_best - x)
             - cfg.repel * r[2] * (g_worst - x))
        x = x + step * v
        step *= cfg.step_decay
        f = loss(x)
        better = f < p_f
        p_best[better], p_f[better] = x[better], f[better]
        i = int(torch.argmin(f))
        if float(f[i]) < g_f:
            g_best, g_f = x[i].clone(), float(f[i])
        g_worst = x[int(torch.argmax(f))].clone()
        history.append(g_f)
    return g_best, history


def modelswarm(
    aligned: torch.Tensor, arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int = 0,
    steps: int = BUDGET_STEPS, buffer: torch.Tensor | None = None, config: SwarmConfig | None = None,
) -> torch.Tensor:
    """Flat parameters of the best particle. Without `buffer`, builds AcoMerge's default
    48-model buffer from `aligned` (K, T) with the same seed."""
    if buffer is None:
        buffer = make_buffer(torch.as_tensor(aligned, dtype=torch.float32), copies=BUFFER_COPIES,
                             sigma=BUFFER_SIGMA, seed=seed, kind="experts")
    return pso(buffer, arch, x_cal, y_cal, seed=seed, steps=steps, config=config)[0]
