"""Networks trained in a moment for the tests that export a model: real weights (a rule-based slip label
on built-in windows), not a random net, so the bundle's vectors exercise every class."""

from __future__ import annotations

import numpy as np
import torch

from fleetlab.export.vectors import builtin_windows
from fleetlab.models import build
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
