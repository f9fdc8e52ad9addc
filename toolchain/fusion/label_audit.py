"""A calibration-label audit: which of D_Cal's labels are likely wrong, by confident learning.

Confident learning (Northcutt, Jiang & Chuang, JAIR 2021; `cleanlab.filter.find_label_issues`) needs an
out-of-sample prediction for every row: from it and the given labels it estimates how often each class
is mistaken for each other one, and flags the rows whose label disagrees most with the prediction, as
many as that estimate says are wrong. The prediction here is cross-validated on D_Cal itself
(`crossval_probabilities`: the Earth expert fine-tuned on the other folds predicts each fold), the
recipe the method's authors give. The experts' own predictions are out-of-sample too, but they were
trained on other rovers and soils: on the real files they flagged right labels by the domain gap and
cost 0.07 balanced accuracy with exact labels (docs/paper_table.md). The audit never removes more than
`MAX_FLAGGED` of the rows, nor a class's last `MIN_PER_CLASS`.
"""

from __future__ import annotations

import numpy as np
import torch

from ..data.contracts import N_CLASSES
from ..models import batched_logits

MAX_FLAGGED = 0.4  # never drop more than this share of D_Cal
FOLDS = 5  # cross-validation folds of the audit's out-of-sample prediction
MIN_PER_CLASS = 3  # keep at least this many rows of every class present


def crossval_probabilities(arch: str, start: torch.Tensor, x: np.ndarray, y: np.ndarray, seed: int, steps: int,
                           lr: float, folds: int = FOLDS) -> np.ndarray:
    """(N, 3) out-of-sample softmax for every row of (x, y): the flat model `start` fine-tuned on the other
    folds (stratified, seeded) predicts each fold."""
    from sklearn.model_selection import StratifiedKFold

    from ..models import build, flatten, load_flat
    from .finetune import finetune

    y = np.asarray(y, dtype=np.int64)
    folds = max(2, min(folds, int(np.bincount(y).max())))
    probs = np.zeros((len(y), N_CLASSES))
    present = np.bincount(y, minlength=N_CLASSES) >= folds
    split = StratifiedKFold(n_splits=folds, shuffle=True, random_state=seed)
    # a class with fewer rows than folds cannot be stratified: those rows are spread by the split anyway
    for k, (fit, held) in enumerate(split.split(x, np.where(present[y], y, -1))):
        tuned = finetune(load_flat(build(arch), start), x[fit], y[fit], steps=steps, lr=lr, seed=seed + k)
        with torch.no_grad():
            logits = batched_logits(arch, flatten(tuned).unsqueeze(0), torch.as_tensor(x[held]))[0]
        probs[held] = torch.softmax(logits, dim=1).double().numpy()
    return probs


def flag_labels(y: np.ndarray, probs: np.ndarray) -> np.ndarray:
    """(N,) bool: the labels confident learning takes for wrong, within the caps above."""
    from cleanlab.filter import find_label_issues

    y = np.asarray(y, dtype=np.int64)
    present = np.unique(y)
    if present.size < 2:  # confident learning compares classes: nothing to say about one
        return np.zeros(y.size, dtype=bool)
    # cleanlab wants every class it is told of to be present: remap the present ones to 0..k-1
    remap = np.full(N_CLASSES, -1)
    remap[present] = np.arange(present.size)
    p = probs[:, present]
    p = p / p.sum(axis=1, keepdims=True)
    ranked = find_label_issues(labels=remap[y], pred_probs=p, filter_by="prune_by_noise_rate",
                               return_indices_ranked_by="self_confidence", n_jobs=1)  # a job is one process
    flagged = np.zeros(y.size, dtype=bool)
    left = np.bincount(y, minlength=N_CLASSES)
    for i in ranked[: int(MAX_FLAGGED * y.size)]:  # most likely wrong first
        if left[y[i]] > MIN_PER_CLASS:
            flagged[i] = True
            left[y[i]] -= 1
    return flagged
