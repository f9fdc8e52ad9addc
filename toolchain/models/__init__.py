"""SN-S / SN-D slip classifiers, their flat-parameter view, training and persistence."""

from .mlp import ARCHS, SlipNet, batched_logits, build, flatten, load_flat, n_params
from .persist import load_model, save_model

__all__ = ["ARCHS", "SlipNet", "batched_logits", "build", "flatten", "load_flat", "n_params", "load_model", "save_model"]
