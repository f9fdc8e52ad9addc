"""The fine-tuned baselines: Model Base, Earth + FullFinetune, Joint + FullFinetune.

All three spend BUDGET_STEPS Adam updates on D_Cal with class-weighted CE
(`fleetlab.fusion.finetune`). Defaults: the expert learning rate 0.0035 and
batch 32 for fine-tuning a trained model (the paper grid-searched these on D_Cal;
these are its reference training settings); a fresh model (Model Base) starts far
from any solution, so it gets a larger rate, 0.01.
"""

from __future__ import annotations

import numpy as np

from ...data.dataset import Dataset
from ...models import SlipNet, build
from ...models.train import EXPERT_BATCH, EXPERT_EPOCHS, EXPERT_LR, FC_RATE, train_classifier
from ..experts import expert_roles
from ..finetune import finetune
from .common import BUDGET_STEPS

MODEL_BASE_LR = 0.01


def model_base(
    arch: str, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, steps: int = BUDGET_STEPS,
    lr: float = MODEL_BASE_LR, batch_size: int = EXPERT_BATCH,
) -> SlipNet:
    """A fresh model (init from `seed`) trained on D_Cal only: the no-transfer lower bound."""
    return finetune(build(arch, seed=seed), x_cal, y_cal, steps=steps, lr=lr, batch_size=batch_size, seed=seed)


def earth_finetune(
    earth_expert: SlipNet, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, steps: int = BUDGET_STEPS,
    lr: float = EXPERT_LR, batch_size: int = EXPERT_BATCH, loss: str = "ce", noise_rate: float = FC_RATE,
) -> SlipNet:
    """Earth + FullFinetune: every weight of the Earth expert fine-tuned on D_Cal (a copy); `loss` 'gce' or 'fc'
    (assuming adjacent noise at `noise_rate`) for noisy labels (models/train.py)."""
    return finetune(earth_expert, x_cal, y_cal, steps=steps, lr=lr, batch_size=batch_size, seed=seed, loss=loss,
                    noise_rate=noise_rate)


def joint_sources(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """D_Earth ∪ every fleet rover's data: the pooled source data of Joint training."""
    parts = [dataset.xy(role) for role in expert_roles(dataset)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def train_joint(dataset: Dataset, arch: str, seed: int, epochs: int = EXPERT_EPOCHS, progress: bool = True,
                device: str = "cpu") -> SlipNet:
    """One model trained on the pooled source data with the experts' recipe and init seed.

    It does not depend on the calibration draw, so an evaluation trains it once per seed.
    """
    x, y = joint_sources(dataset)
    desc = "joint model" if progress else None
    return train_classifier(build(arch, seed=seed), x, y, epochs=epochs, seed=seed, desc=desc, device=device)


def joint_finetune(
    joint_model: SlipNet, x_cal: np.ndarray, y_cal: np.ndarray, seed: int, steps: int = BUDGET_STEPS,
    lr: float = EXPERT_LR, batch_size: int = EXPERT_BATCH,
) -> SlipNet:
    """Joint + FullFinetune: the jointly trained model fine-tuned on D_Cal (a copy)."""
    return finetune(joint_model, x_cal, y_cal, steps=steps, lr=lr, batch_size=batch_size, seed=seed)
