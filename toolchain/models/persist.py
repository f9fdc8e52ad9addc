"""Save and load a trained model together with its metadata."""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import torch

from ..data.contracts import FEATURE_NAMES
from ..errors import InputError, first_line
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
    """Return (model in eval mode, metadata dict). Refuses files that are not fleetlab models.

    Every refusal is one ValueError line naming the file: a missing or unreadable file, bytes that are
    not a torch checkpoint (garbage, truncated), a checkpoint of something else, or a fleetlab file
    whose fields were edited so that they no longer make a model."""
    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except OSError as e:
        raise InputError(f"{path}: cannot read model file ({e.strerror or type(e).__name__})") from None
    except pickle.UnpicklingError:
        # torch's own text here advises weights_only=False, i.e. running the file's code: not for a model
        raise InputError(f"{path}: cannot read model file (not a torch checkpoint of tensors and plain values: "
                         "damaged, or another format)") from None
    except EOFError:
        raise InputError(f"{path}: cannot read model file (empty or cut short)") from None
    except Exception as e:  # torch raises many types for a damaged file (its zip reader's, ...)
        raise InputError(f"{path}: cannot read model file ({type(e).__name__}: {first_line(e)})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise InputError(f"{path}: not a fleetlab model file (expected format {FORMAT})")
    fields = {"arch": str, "feature_names": (list, tuple), "state_dict": dict, "meta": dict}
    bad = [name for name, kind in fields.items() if not isinstance(payload.get(name), kind)]
    if bad:
        raise InputError(f"{path}: damaged fleetlab model file (missing or wrong fields: {', '.join(bad)})")
    if tuple(payload["feature_names"]) != FEATURE_NAMES:
        raise InputError(f"{path}: model expects a different feature order: {payload['feature_names']}")
    try:
        model = build(payload["arch"])
    except ValueError as e:  # an architecture name this version does not know (an edit, or a newer fleetlab)
        raise InputError(f"{path}: fleetlab model of an architecture this version cannot build ({e})") from None
    problem = _weights_problem(payload["state_dict"], model.state_dict(), payload["arch"])
    if problem:
        raise InputError(f"{path}: damaged fleetlab model file ({problem})")
    model.load_state_dict(payload["state_dict"])
    model.eval()
    meta = dict(payload["meta"], arch=payload["arch"])
    return model, meta


def _weights_problem(got: dict, expected: dict, arch: str) -> str | None:
    """What keeps `got` from loading into a model whose state dict is `expected`, in a few words, or None."""
    missing, extra = sorted(set(expected) - set(got)), sorted(set(got) - set(expected))
    if missing or extra:
        return f"weights missing: {missing or 'none'}, unexpected: {extra or 'none'}"
    for name, value in expected.items():
        if not isinstance(got[name], torch.Tensor) or got[name].shape != value.shape:
            shape = tuple(got[name].shape) if isinstance(got[name], torch.Tensor) else type(got[name]).__name__
            return f"{name} is {shape} where a {arch} has {tuple(value.shape)}"
        if not torch.isfinite(got[name]).all():
            return f"{name} holds NaN or infinity"
    return None
