"""How far apart the simulated Earth analog and Moon are, seen by an Earth-trained SN-S.

Train an SN-S on the Earth-analog traverses except a held-out few, then score
balanced accuracy on the held-out Earth traverses and on the target rover's
lunar traverses. A real Earth-to-Moon gap shows up as a clearly lower lunar
score; that gap is what fleet fusion is meant to close.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compute import torch_threads
from ..data.dataset import EARTH, TARGET
from ..data.simulator.engine import Trace
from ..models import build
from ..models.train import predict, train_classifier
from .metrics import balanced_accuracy
from ..errors import InputError


@dataclass(frozen=True)
class DomainGap:
    earth_heldout_bacc: float
    target_moon_bacc: float
    n_train: int
    n_earth_heldout: int
    n_target: int

    @property
    def gap(self) -> float:
        return self.earth_heldout_bacc - self.target_moon_bacc


def _stack(traces: list[Trace]) -> tuple[np.ndarray, np.ndarray]:
    windows = [t.windows() for t in traces]
    return (np.concatenate([w.features for w in windows]).astype(np.float32),
            np.concatenate([w.label for w in windows]))


def earth_to_moon_gap(traces: list[tuple[str, str, Trace]], seed: int = 0, heldout_fraction: float = 0.3,
                      steps: int = 1500) -> DomainGap:
    """Balanced accuracy of an Earth-trained SN-S on held-out Earth traverses and on target-Moon data.

    The last `heldout_fraction` of the Earth traverses (whole traverses, so no
    window of a held-out traverse is seen in training) form the Earth test set.
    """
    earth = [t for role, _, t in traces if role == EARTH]
    target = [t for role, _, t in traces if role == TARGET]
    if len(earth) < 2 or not target:
        raise InputError("need at least two Earth traverses and one target traverse")
    n_test = max(1, round(heldout_fraction * len(earth)))
    x_tr, y_tr = _stack(earth[:-n_test])
    x_te, y_te = _stack(earth[-n_test:])
    x_moon, y_moon = _stack(target)
    with torch_threads(1):  # a 543-parameter net trains fastest on one thread
        model = train_classifier(build("sn-s", seed=seed), x_tr, y_tr, epochs=None, steps=steps, seed=seed)
    return DomainGap(
        earth_heldout_bacc=balanced_accuracy(y_te, predict(model, x_te)),
        target_moon_bacc=balanced_accuracy(y_moon, predict(model, x_moon)),
        n_train=len(y_tr),
        n_earth_heldout=len(y_te),
        n_target=len(y_moon),
    )
