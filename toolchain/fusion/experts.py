"""Expert models: one SN-S/SN-D per data source, all from one shared random init.

Sources are the target rover in the Earth analog (`earth`, D_Earth) and every
fleet rover on the Moon (`fleet_<rover>`). Starting every expert from the same
initial weights (as the paper's reference setup does) keeps them in one basin of
the loss landscape, which makes per-parameter fusion meaningful; Git Re-Basin
alignment (`rebasin.py`) then removes any remaining hidden-unit permutation.
"""

from __future__ import annotations

import copy

from ..data.dataset import EARTH, Dataset
from ..models import SlipNet, build
from ..models.train import EXPERT_EPOCHS, train_classifier
from ..errors import InputError


def expert_roles(dataset: Dataset) -> list[str]:
    """`earth` first (it is the Re-Basin reference), then the fleet roles in name order."""
    dataset.check_roles()
    return [EARTH, *dataset.fleet_roles]


def train_experts(
    dataset: Dataset, arch: str, seed: int, epochs: int = EXPERT_EPOCHS, progress: bool = True, device: str = "cpu"
) -> dict[str, SlipNet]:
    """Train one expert per source role with class-weighted CE and Adam (lr 0.0035, batch 32).

    Returns {role: model in eval mode}, ordered `earth`, then `fleet_*`. The shuffling
    seed of expert i is `seed + i`, so the same seed always gives the same experts.
    `device`: where they train (`train_classifier`).
    """
    if epochs < 1:
        raise InputError(f"epochs must be at least 1, got {epochs}")
    init = build(arch, seed=seed)
    experts: dict[str, SlipNet] = {}
    for i, role in enumerate(expert_roles(dataset)):
        x, y = dataset.xy(role)
        model = copy.deepcopy(init)
        desc = f"expert {role}" if progress else None
        experts[role] = train_classifier(model, x, y, epochs=epochs, seed=seed + i, desc=desc, device=device)
    return experts
