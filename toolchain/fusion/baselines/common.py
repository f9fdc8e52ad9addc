"""Pieces shared by the baselines: the step budget, the D_Cal objective, merge bases.

Every baseline gets the same budget of optimisation steps as AcoMerge gets
pheromone updates (AcoMergeConfig.generations): one Adam update, one CMA-ES generation or one PSO
iteration counts as one step.
"""

from __future__ import annotations

import numpy as np
import torch

from ...models import SlipNet, batched_logits, build, load_flat
from ...models.mlp import param_shapes
from ..acomerge import AcoMergeConfig
from ...errors import InputError

BUDGET_STEPS = AcoMergeConfig.generations  # the paper's shared budget of optimisation steps


def as_tensor_xy(x: np.ndarray, y: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    if len(y) == 0:
        raise InputError("the calibration set is empty")
    xt = torch.as_tensor(np.asarray(x, dtype=np.float32))
    yt = torch.as_tensor(np.asarray(y, dtype=np.int64))
    if xt.ndim != 2 or xt.shape[0] != yt.shape[0]:
        raise InputError(f"calibration features {tuple(xt.shape)} do not match {tuple(yt.shape)} labels")
    return xt, yt


def weighted_ce_many(arch: str, flats: torch.Tensor, x: torch.Tensor, y: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Class-weighted cross-entropy of P flat models on (x, y): (P, T) -> (P,), eval semantics.

    Same normalisation as torch's weighted 'mean' reduction (divided by the summed
    weights of the targets), so it equals `weighted_ce` of each model.
    """
    logits = batched_logits(arch, flats, x)  # (P, N, C)
    logp = torch.log_softmax(logits, dim=-1)
    picked = logp.gather(2, y.view(1, -1, 1).expand(logits.shape[0], -1, 1)).squeeze(2)  # (P, N)
    w = weights[y]
    return -(picked * w).sum(dim=1) / w.sum()


def cal_objective(arch: str, x: np.ndarray, y: np.ndarray):
    """(P, T) -> (P,) weighted CE on D_Cal: the very fitness AcoMerge minimises, batched."""
    from ..fitness import CalibrationFitness

    as_tensor_xy(x, y)  # same input checks as the gradient-based baselines
    return CalibrationFitness(arch, x, y)


def model_from_flat(arch: str, flat: torch.Tensor) -> SlipNet:
    return load_flat(build(arch), torch.as_tensor(flat, dtype=torch.float32).detach().clone()).eval()


def tensor_slices(arch: str) -> list[slice]:
    """Where each parameter tensor lives in the flat vector (flat order of models.mlp)."""
    out, offset = [], 0
    for shape in param_shapes(arch):
        n = int(np.prod(shape))
        out.append(slice(offset, offset + n))
        offset += n
    return out


def layer_slices(arch: str) -> list[slice]:
    """One slice per layer: each hidden block (Linear w, b, LayerNorm w, b) and the head (w, b)."""
    t = tensor_slices(arch)
    blocks = [slice(t[i].start, t[i + 3].stop) for i in range(0, len(t) - 2, 4)]
    return blocks + [slice(t[-2].start, t[-1].stop)]


def merge_base(aligned: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Base and task vectors for the task-arithmetic baselines (AdaMerging, DARE-TIES).

    There is no common pre-trained model here: the experts share a random init, but
    Re-Basin permutes the non-reference experts, so that init is no longer a common
    origin. The base is therefore the Earth expert (row 0, the Re-Basin reference):
    the target rover's own pre-landing model plays the role of the pre-trained model,
    and each fleet expert contributes its difference from it as a task vector.
    Returns (base (T,), task_vectors (K-1, T)).
    """
    aligned = torch.as_tensor(aligned, dtype=torch.float32)
    if aligned.ndim != 2 or aligned.shape[0] < 2:
        raise InputError(f"need at least two aligned experts as a (K, T) tensor, got shape {tuple(aligned.shape)}")
    return aligned[0], aligned[1:] - aligned[0]
