"""DARE and TIES merging operations on task vectors, written out one step at a time.

Task vectors tau_k = expert_k - base (shape (K, T), or (P, K, T) for P candidates).
- DARE (Yu et al., 2024): drop each entry with probability 1 - density, rescale the
  survivors by 1 / density so the expected task vector is unchanged.
- TIES (Yadav et al., 2023): trim (keep the `density` fraction of largest magnitudes),
  elect a sign per parameter (sign of the summed task vectors), disjoint merge (mean
  over only the experts whose entry is non-zero and agrees with the elected sign).
- DARE-TIES: DARE in place of the TIES trim, then sign election and disjoint merge.

The random drop uses uniform draws `u` supplied by the caller, so one fixed set of
draws gives a deterministic merge as a function of the densities (the mask of an
entry is `u < density`: raising the density only ever adds survivors).
"""

from __future__ import annotations

import torch


def dare(tau: torch.Tensor, density: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Drop-and-rescale: keep entries with u < density, scale the kept ones by 1/density."""
    density = density.clamp(min=1e-6, max=1.0)
    return torch.where(u < density, tau / density, torch.zeros_like(tau))


def ties_trim(tau: torch.Tensor, density: float) -> torch.Tensor:
    """Keep the round(density * n) largest-magnitude entries of each task vector (last dim)."""
    n = tau.shape[-1]
    keep = max(1, min(n, round(density * n)))
    threshold = tau.abs().topk(keep, dim=-1).values[..., -1:]
    return torch.where(tau.abs() >= threshold, tau, torch.zeros_like(tau))


def elect_sign(tau: torch.Tensor) -> torch.Tensor:
    """Per-parameter sign of the summed task vectors over the expert axis (-2); ties -> +1."""
    total = tau.sum(dim=-2)
    return torch.where(total >= 0, torch.ones_like(total), -torch.ones_like(total))


def disjoint_merge(tau: torch.Tensor, sign: torch.Tensor) -> torch.Tensor:
    """Mean over the experts whose entry is non-zero and has the elected sign; 0 if none."""
    agree = (tau != 0) & (torch.sign(tau) == sign.unsqueeze(-2))
    count = agree.sum(dim=-2)
    total = torch.where(agree, tau, torch.zeros_like(tau)).sum(dim=-2)
    return torch.where(count > 0, total / count.clamp(min=1), torch.zeros_like(total))


def ties_merge(base: torch.Tensor, tau: torch.Tensor, density: float = 0.2, scale: float = 1.0) -> torch.Tensor:
    """Plain TIES-merging: trim, elect sign, disjoint merge, add `scale` times the result."""
    trimmed = ties_trim(tau, density)
    return base + scale * disjoint_merge(trimmed, elect_sign(trimmed))


def dare_ties_merge(
    base: torch.Tensor, tau: torch.Tensor, weight: torch.Tensor, density: torch.Tensor, u: torch.Tensor
) -> torch.Tensor:
    """DARE-TIES with per-entry weights and densities (already expanded to the tau shape).

    base (T,), tau (K, T), weight/density (..., K, T), u (K, T) -> merged (..., T).
    Each task vector is DARE-sparsified, scaled by its weight, then sign-elected and
    disjoint-merged onto the base.
    """
    sparse = weight * dare(tau, density, u)
    return base + disjoint_merge(sparse, elect_sign(sparse))
