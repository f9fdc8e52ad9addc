"""SN-S / SN-D slip classifiers, their flat-parameter view, training and persistence."""

from .mlp import ARCHS, SlipNet, batched_logits, build, canonical_arch, flatten, hidden_sizes, load_flat, n_params
from .persist import load_model, save_model

__all__ = ["ARCHS", "SlipNet", "batched_logits", "build", "canonical_arch", "hidden_sizes", "flatten", "load_flat", "n_params", "load_model", "save_model"]
