"""Save and load a trained model together with its metadata."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from ..data.contracts import FEATURE_NAMES
from .mlp import arch_of, build

FORMAT = "fleetlab-model/1"


def save_model(path: Path | str, model, meta: dict[str, Any] | None = None) -> Path:
    """Write state dict + metadata (architecture, feature order, anything in `meta`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FORMAT,
        "arch": arch_of(model),
        "feature_names": list(FEATURE_NAMES),
        "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
        "meta": dict(meta or {}),
    }
    torch.save(payload, path)
    return path


def load_model(path: Path | str):
    """Return (model in eval mode, metadata dict). Refuses files that are not fleetlab models."""
    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for a damaged file
        raise ValueError(f"{path}: cannot read model file ({type(e).__name__}: {e})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path}: not a fleetlab model file (expected format {FORMAT})")
    if tuple(payload["feature_names"]) != FEATURE_NAMES:
        raise ValueError(f"{path}: model expects a different feature order: {payload['feature_names']}")
    model = build(payload["arch"])
    model.load_state_dict(payload["state_dict"])
    model.eval()
    meta = dict(payload["meta"], arch=payload["arch"])
    return model, meta
