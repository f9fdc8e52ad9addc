"""Classification metrics of one run, over the three slip classes.

Every figure comes from one confusion matrix (scikit-learn's). Why not scikit-learn's four metric
functions: each validates the labels and builds its own confusion matrix again, and together they
took 4 ms per call, about 8 ms of every MCCV job, more than the fit of a fine-tuned baseline saves
between two of its steps (issue 30). The divisions below are the ones scikit-learn makes, in the
same float64 order, so the numbers are its numbers bit for bit (tests/test_evaluation.py compares
them on random label arrays, classes missing included).
"""

from __future__ import annotations

import numpy as np
from sklearn.metrics import confusion_matrix

from ..data.contracts import N_CLASSES
from ..errors import InputError

LABELS = list(range(N_CLASSES))
SCALAR_METRICS = ("balanced_accuracy", "macro_f1")


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num / den as float64, 0 where den is 0 (scikit-learn's zero_division=0)."""
    num, den = np.asarray(num, dtype=np.float64), np.asarray(den, dtype=np.float64)
    return np.divide(num, den, out=np.zeros_like(num), where=den != 0)


def classification_metrics(y_true: np.ndarray, y_pred: np.ndarray) -> dict:
    """Balanced accuracy, macro-F1, per-class precision/recall and the confusion matrix.

    Balanced accuracy averages recall over the classes present in `y_true` (scikit-learn's
    `balanced_accuracy_score`); macro-F1 and the per-class values cover all three classes, 0 where
    undefined (its `zero_division=0`).
    """
    y_true, y_pred = np.asarray(y_true), np.asarray(y_pred)
    if y_true.shape != y_pred.shape or y_true.size == 0:
        raise InputError(f"need equally long, non-empty label arrays, got {y_true.shape} and {y_pred.shape}")
    for name, labels in (("true", y_true), ("predicted", y_pred)):
        if not np.isin(labels, LABELS).all():
            raise InputError(f"{name} labels must be classes {LABELS}, found {sorted(set(labels.tolist()) - set(LABELS))}")
    cm = confusion_matrix(y_true, y_pred, labels=LABELS)
    tp, true_sum, pred_sum = np.diag(cm), cm.sum(axis=1), cm.sum(axis=0)
    present = true_sum > 0
    f1 = _ratio(2.0 * tp, 1.0 * true_sum + pred_sum)
    return {
        "balanced_accuracy": float(np.mean(tp[present] / true_sum[present])),
        "macro_f1": float(np.mean(f1)),
        "precision": _ratio(tp, pred_sum).tolist(),
        "recall": _ratio(tp, true_sum).tolist(),
        "confusion_matrix": cm.tolist(),
    }


def balanced_accuracy(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Balanced accuracy alone, the same number as `classification_metrics`'s.

    Why not scikit-learn's `balanced_accuracy_score`: where a class never occurs in `y_true` (a small
    traverse, a held-out split) it prints a warning on every call for what is a defined figure, the
    mean recall over the classes present."""
    return classification_metrics(y_true, y_pred)["balanced_accuracy"]
