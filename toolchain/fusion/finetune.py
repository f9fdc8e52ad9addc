"""Full fine-tuning of a model on D_Cal: the Earth+FullFinetune reference point.

The budget is counted in optimiser steps (default 130, the same number of
optimisation steps AcoMerge gets as generations).
"""

from __future__ import annotations

import copy

import numpy as np

from ..models import SlipNet
from ..models.train import EXPERT_BATCH, EXPERT_LR, FC_RATE, train_classifier
from .acomerge import AcoMergeConfig
from ..errors import InputError

FINETUNE_STEPS = AcoMergeConfig.generations  # same budget as AcoMerge's generations


def finetune(
    model: SlipNet,
    x: np.ndarray,
    y: np.ndarray,
    steps: int = FINETUNE_STEPS,
    lr: float = EXPERT_LR,
    batch_size: int = EXPERT_BATCH,
    seed: int = 0,
    loss: str = "ce",
    noise_rate: float = FC_RATE,
) -> SlipNet:
    """A fine-tuned COPY of `model`: `steps` Adam updates on class-weighted CE (or `loss` 'gce', or 'fc' assuming
    adjacent label noise at `noise_rate`) over (x, y).

    The input model is left untouched. Seeded (batch order and dropout masks).
    """
    if steps < 1:
        raise InputError(f"fine-tune steps must be at least 1, got {steps}")
    if len(y) == 0:
        raise InputError("cannot fine-tune on an empty calibration set")
    tuned = copy.deepcopy(model)
    return train_classifier(tuned, x, y, epochs=None, steps=steps, lr=lr, batch_size=batch_size, seed=seed,
                            fused_adam=True, loss=loss, noise_rate=noise_rate)  # per-run work: the fast Adam (models/train.py, adam)
