"""Windowed features from raw telemetry (docs/architecture.md, contract 1).

One vectorised implementation, used by the simulator and by anything that
featurises raw telemetry; the C streaming extractor is checked against it.
Windows are consecutive blocks of `samples_per_window` samples starting at
sample 0, advanced by `samples_per_stride`; a trailing partial window is not
emitted (the C extractor never closes it either).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contracts import (
    CH,
    DEFAULT_RATE_HZ,
    FEATURE_SOURCES,
    MIN_SAMPLES_PER_WINDOW,
    N_CHANNELS,
    STRIDE_S,
    WINDOW_S,
)
from .labels import slip_class, slip_ratio
from ..errors import InputError


@dataclass(frozen=True)
class WindowSpec:
    samples_per_window: int
    samples_per_stride: int

    @classmethod
    def for_rate(cls, rate_hz: float = DEFAULT_RATE_HZ) -> "WindowSpec":
        spw = int(round(WINDOW_S * rate_hz))
        stride = int(round(STRIDE_S * rate_hz))
        if spw < MIN_SAMPLES_PER_WINDOW:
            raise InputError(
                f"rate {rate_hz} Hz gives {spw} samples per {WINDOW_S} s window; "
                f"at least {MIN_SAMPLES_PER_WINDOW} are needed"
            )
        return cls(spw, stride)

    def n_windows(self, n_samples: int) -> int:
        if n_samples < self.samples_per_window:
            return 0
        return (n_samples - self.samples_per_window) // self.samples_per_stride + 1


def _windows(x: np.ndarray, spec: WindowSpec) -> np.ndarray:
    """View of x (n, ...) as (n_windows, samples_per_window, ...) without copying."""
    n_win = spec.n_windows(len(x))
    if spec.samples_per_stride == spec.samples_per_window:
        return x[: n_win * spec.samples_per_window].reshape(n_win, spec.samples_per_window, *x.shape[1:])
    view = np.lib.stride_tricks.sliding_window_view(x, spec.samples_per_window, axis=0)
    view = view[:: spec.samples_per_stride][:n_win]
    return np.moveaxis(view, -1, 1)


# Column index into the per-window statistics for each feature, in feature order.
_MEAN_COLS = np.array([CH[c] for c, stat in FEATURE_SOURCES if stat == "mean"])
_STD_COLS = np.array([CH[c] for c, stat in FEATURE_SOURCES if stat == "std"])
_IS_MEAN = np.array([stat == "mean" for _, stat in FEATURE_SOURCES])


def finite_matrix(x: np.ndarray, width: int, what: str) -> np.ndarray:
    """x as float64 (n, width); a clear error for another shape or any NaN/Inf (names the first row)."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != width:
        raise InputError(f"{what} must have shape (n, {width}), got {x.shape}")
    if not np.isfinite(x).all():
        row = int(np.argwhere(~np.isfinite(x))[0, 0])
        raise InputError(f"{what} contain NaN/Inf (first at row {row})")
    return x


def featurise(samples: np.ndarray, spec: WindowSpec | None = None) -> np.ndarray:
    """Raw samples (n, 7) in RAW_CHANNELS order -> features (n_windows, 12) float64.

    Mean and population std (ddof=0) per window, in FEATURE_NAMES order.
    """
    samples = finite_matrix(samples, N_CHANNELS, "samples")
    spec = spec or WindowSpec.for_rate()
    win = _windows(samples, spec)
    mean = win.mean(axis=1)
    std = win.std(axis=1)
    out = np.empty((win.shape[0], len(FEATURE_SOURCES)))
    out[:, _IS_MEAN] = mean[:, _MEAN_COLS]
    out[:, ~_IS_MEAN] = std[:, _STD_COLS]
    return out


def window_sums(x: np.ndarray, spec: WindowSpec | None = None) -> np.ndarray:
    """Per-window sum of a per-sample quantity (e.g. distance increments)."""
    spec = spec or WindowSpec.for_rate()
    return _windows(np.asarray(x, dtype=np.float64), spec).sum(axis=1)


@dataclass(frozen=True)
class LabelledWindows:
    features: np.ndarray  # (n, 12)
    d_actual: np.ndarray  # (n,) m
    d_commanded: np.ndarray  # (n,) m
    slip: np.ndarray  # (n,) ratio, clipped
    label: np.ndarray  # (n,) int class
    n_samples: np.ndarray  # (n,) samples per window
    duration_s: np.ndarray  # (n,)


def featurise_trace(
    samples: np.ndarray,
    d_actual_step: np.ndarray,
    d_commanded_step: np.ndarray,
    rate_hz: float = DEFAULT_RATE_HZ,
) -> LabelledWindows:
    """Features and labels of one traverse from per-sample telemetry and distance increments."""
    spec = WindowSpec.for_rate(rate_hz)
    features = featurise(samples, spec)
    d_act = window_sums(d_actual_step, spec)
    d_cmd = window_sums(d_commanded_step, spec)
    slip = slip_ratio(d_act, d_cmd)
    n = len(features)
    return LabelledWindows(
        features=features,
        d_actual=d_act,
        d_commanded=d_cmd,
        slip=slip,
        label=slip_class(slip),
        n_samples=np.full(n, spec.samples_per_window, dtype=np.int64),
        duration_s=np.full(n, spec.samples_per_window / rate_hz),
    )
