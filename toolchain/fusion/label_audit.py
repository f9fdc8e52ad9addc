"""A calibration-label audit: which of D_Cal's labels are likely wrong, by confident learning.

The experts never saw D_Cal (they are trained on the source rovers' data only), so their softmax on
D_Cal is an out-of-sample prediction, which is what confident learning needs (Northcutt, Jiang & Chuang,
JAIR 2021). `cleanlab.filter.find_label_issues` estimates from those predictions and the given labels
how often each class is mistaken for each other one, and flags the rows whose label disagrees most
with the prediction, as many as that estimate says are wrong.

Caveat, written in docs/paper_table.md with the measured effect: the experts were trained on other
rovers and soils, so some of their disagreement with a right label is the domain gap, not noise. The
audit therefore never removes more than `MAX_FLAGGED` of the rows, nor a class's last `MIN_PER_CLASS`.
"""

from __future__ import annotations

import numpy as np
import torch

from ..data.contracts import N_CLASSES
from ..models import batched_logits

MAX_FLAGGED = 0.4  # never drop more than this share of D_Cal
MIN_PER_CLASS = 3  # keep at least this many rows of every class present


def expert_probabilities(arch: str, experts: torch.Tensor, x: np.ndarray) -> np.ndarray:
    """(N, 3) mean softmax of the (K, T) flat experts on x: an out-of-sample prediction for D_Cal."""
    with torch.no_grad():
        logits = batched_logits(arch, torch.as_tensor(experts, dtype=torch.float32), torch.as_tensor(x))
    return torch.softmax(logits, dim=2).mean(dim=0).double().numpy()


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
