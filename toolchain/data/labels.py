"""Slip labels from travelled and commanded distance (docs/architecture.md, contract 2)."""

from __future__ import annotations

import numpy as np

from .contracts import CLASS_THRESHOLDS, MIN_COMMANDED_DISTANCE_M, SLIP_CLIP


def slip_ratio(d_actual: np.ndarray, d_commanded: np.ndarray) -> np.ndarray:
    """s = 1 - d_actual / d_commanded, clipped to +-1; 0 where d_commanded < 0.05 m."""
    d_actual = np.asarray(d_actual, dtype=np.float64)
    d_commanded = np.asarray(d_commanded, dtype=np.float64)
    moving = d_commanded >= MIN_COMMANDED_DISTANCE_M
    safe = np.where(moving, d_commanded, 1.0)
    s = np.clip(1.0 - d_actual / safe, -SLIP_CLIP, SLIP_CLIP)
    return np.where(moving, s, 0.0)


def slip_class(slip: np.ndarray) -> np.ndarray:
    """Class from |slip|: 0 if <= 0.3, 1 if <= 0.6, else 2 (int64)."""
    mag = np.abs(np.asarray(slip, dtype=np.float64))
    low, moderate = CLASS_THRESHOLDS
    return np.where(mag <= low, 0, np.where(mag <= moderate, 1, 2)).astype(np.int64)
