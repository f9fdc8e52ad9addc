"""Networks trained in a moment for the tests that export a model: real weights (a rule-based slip label
on built-in windows), not a random net, so the bundle's vectors exercise every class."""

from __future__ import annotations

import numpy as np
import torch

from fleetlab.export.vectors import builtin_windows
from fleetlab.fusion.registry import Budget, FusionInputs
from fleetlab.models import build, flatten
from fleetlab.models.train import train_classifier


def trained_model(arch: str, seed: int, windows: int, steps: int):
    x = builtin_windows(windows, np.random.default_rng(seed)).astype(np.float32)
    y = np.digitize(x[:, 3] / np.maximum(x[:, 2], 1e-3), [0.08, 0.3]).astype(np.int64)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny batches: threads only add overhead
    try:
        return train_classifier(build(arch, seed=seed), x, y, steps=steps, seed=seed)
    finally:
        torch.set_num_threads(threads)


def small_model(seed: int = 5):
    """An SN-S trained briefly (600 windows, 150 steps)."""
    return trained_model("sn-s", seed, windows=600, steps=150)


def quick_model(arch: str, seed: int = 4):
    """Any architecture, trained more briefly still (400 windows, 40 steps): the deep ones are slower."""
    return trained_model(arch, seed, windows=400, steps=40)


def fusion_inputs(budget: Budget, seed: int = 1, y_cal_probs=None) -> FusionInputs:
    """One small calibration draw (90 rows, labels a rule of one feature) over three untrained SN-S experts;
    `y_cal_probs`, if given, is a function of the labels."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(90, 12)).astype(np.float32)
    y = np.digitize(x[:, 3], [-0.4, 0.6]).astype(np.int64)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)])
    return FusionInputs("sn-s", ("earth", "a", "b"), flats, flats, None, x, y, seed=seed, buffer_seed=2,
                        budget=budget, y_cal_probs=None if y_cal_probs is None else y_cal_probs(y))
