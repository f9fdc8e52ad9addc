"""The expert buffer: the M candidate values AcoMerge chooses from at every parameter.

Row layout of the (M, T) buffer (M = K · (1 + copies)):
  rows 0..K−1  the unperturbed (aligned) experts, so their paths exist in the graph;
  rows K..M−1  the augmentation candidates, `copies` per expert, expert-major.

Kinds (the paper's buffer ablation, all the same size M):
  'experts'          E×M: each expert plus `copies` copies with i.i.d. absolute
                     Gaussian noise N(0, σ²) on every parameter (paper: σ = 0.05).
  'centroid_random'  E×K + CR×(M−K): the experts plus candidates drawn around the
                     experts' centroid, N(centroid, s²) with s the per-parameter
                     spread of the experts plus σ — they cover about the same volume
                     as the perturbed experts but lose the proximity to trained solutions.
  'random'           R×M: every row i.i.d. N(μ, sd²) with μ, sd the mean and standard
                     deviation of all expert weights — no trained solution in the buffer.
"""

from __future__ import annotations

import torch
from ..errors import InputError

BUFFER_KINDS = ("experts", "centroid_random", "random")


def make_buffer(
    experts_flat: torch.Tensor, copies: int = 15, sigma: float = 0.05, seed: int = 0, kind: str = "experts"
) -> torch.Tensor:
    """(K, T) experts -> (K·(1+copies), T) float32 buffer, seeded (own torch.Generator)."""
    if experts_flat.dim() != 2 or experts_flat.shape[0] < 1:
        raise InputError(f"experts must be a (K, T) tensor, got shape {tuple(experts_flat.shape)}")
    if copies < 0 or sigma < 0:
        raise InputError(f"copies and sigma must be non-negative (got {copies}, {sigma})")
    if kind not in BUFFER_KINDS:
        raise InputError(f"unknown buffer kind {kind!r}; choose one of {', '.join(BUFFER_KINDS)}")
    experts = experts_flat.detach().to(torch.float32)
    k, t = experts.shape
    n_extra = k * copies
    gen = torch.Generator().manual_seed(seed)
    noise = torch.randn(n_extra, t, generator=gen)
    if kind == "experts":
        extra = experts.repeat_interleave(copies, dim=0) + sigma * noise
        return torch.cat([experts, extra])
    if kind == "centroid_random":
        spread = experts.std(dim=0, unbiased=False) + sigma
        return torch.cat([experts, experts.mean(dim=0) + spread * noise])
    everything = torch.randn(k + n_extra, t, generator=gen)
    return experts.mean() + experts.std() * everything
