"""How learnable a dataset's target task is, measured with SN-S (the learnability half of
`fleetlab data compare`; the pure statistics are in `fleetlab.data.compare`).

* Leave-one-traverse-out (LOTO): an SN-S trained on all target traverses but one, scored
  on the one left out; the mean over traverses is the supervised ceiling on unseen terrain.
* Earth expert zero-shot: the Earth expert (trained on the Earth analog as in
  `fleetlab fuse`) scored on all target rows without any calibration.
* Earth + FullFinetune at |D_Cal| = 150 under the paper protocol (random rows) and the
  leakage-free traverse protocol, over a few draws of D_Cal.

All scores are balanced accuracy. Everything is seeded, so a report repeats exactly.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np

from ..compute import torch_threads
from ..data.dataset import EARTH, TARGET, Dataset
from ..data.splits import make_split
from ..fusion.baselines import earth_finetune
from ..models import build
from ..models.train import EXPERT_EPOCHS, predict, train_classifier
from .metrics import balanced_accuracy
from ..errors import InputError

CAL_SIZE = 150


@dataclass(frozen=True)
class Learnability:
    loto_bacc_mean: float
    loto_bacc_per_traverse: list[float]
    earth_zero_shot_bacc: float
    earth_ft_paper_bacc: float | None  # None when the target cannot hold a 150-row D_Cal
    earth_ft_traverse_bacc: float | None
    runs: int
    epochs: int

    def as_dict(self) -> dict:
        return asdict(self)


def _bacc(model, x: np.ndarray, y: np.ndarray) -> float:
    return balanced_accuracy(y, predict(model, x))


def loto(dataset: Dataset, seed: int = 0, epochs: int = EXPERT_EPOCHS) -> list[float]:
    """Balanced accuracy of each target traverse, scored by an SN-S trained on the others."""
    x, y = dataset.xy(TARGET)
    groups = dataset.groups(TARGET)
    if len(np.unique(groups)) < 2:
        raise InputError(f"{dataset.root}: leave-one-traverse-out needs at least two target traverses")
    init = build("sn-s", seed=seed)
    scores = []
    with torch_threads(1):
        for g in np.unique(groups):
            train, test = groups != g, groups == g
            model = train_classifier(copy.deepcopy(init), x[train], y[train], epochs=epochs, seed=seed)
            scores.append(_bacc(model, x[test], y[test]))
    return scores


def earth_expert(dataset: Dataset, seed: int = 0, epochs: int = EXPERT_EPOCHS):
    """The Earth expert as `fleetlab fuse` trains it (SN-S, all Earth-analog rows)."""
    x_e, y_e = dataset.xy(EARTH)
    return train_classifier(build("sn-s", seed=seed), x_e, y_e, epochs=epochs, seed=seed)


def earth_zero_shot(dataset: Dataset, seed: int = 0, epochs: int = EXPERT_EPOCHS) -> float:
    """Balanced accuracy of the Earth expert on every target row, without calibration."""
    with torch_threads(1):
        return _bacc(earth_expert(dataset, seed, epochs), *dataset.xy(TARGET))


def _earth_finetune_score(earth, x, y, groups, protocol: str, runs: int) -> float | None:
    scores = []
    for r in range(runs):
        try:
            split = make_split(protocol, y, groups, CAL_SIZE, seed=r)
        except ValueError:
            return None  # too few rows or traverses for this protocol
        model = earth_finetune(earth, x[split.cal], y[split.cal], seed=r)
        scores.append(_bacc(model, x[split.test], y[split.test]))
    return float(np.mean(scores))


def learnability(dataset: Dataset, seed: int = 0, runs: int = 5, epochs: int = EXPERT_EPOCHS) -> Learnability:
    """The learnability figures of one dataset (it needs `earth` and `target` roles)."""
    missing = [r for r in (EARTH, TARGET) if r not in dataset.roles]
    if missing:
        raise InputError(f"{dataset.root}: learnability needs the roles {', '.join(missing)}")
    if runs < 1:
        raise InputError(f"runs must be at least 1, got {runs}")
    with torch_threads(1):  # a 543-parameter net trains fastest on one thread
        per_traverse = loto(dataset, seed, epochs)
        earth = earth_expert(dataset, seed, epochs)
        x, y = dataset.xy(TARGET)
        groups = dataset.groups(TARGET)
        return Learnability(
            loto_bacc_mean=float(np.mean(per_traverse)),
            loto_bacc_per_traverse=per_traverse,
            earth_zero_shot_bacc=_bacc(earth, x, y),
            earth_ft_paper_bacc=_earth_finetune_score(earth, x, y, groups, "paper", runs),
            earth_ft_traverse_bacc=_earth_finetune_score(earth, x, y, groups, "traverse", runs),
            runs=runs,
            epochs=epochs,
        )
