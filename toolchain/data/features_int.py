"""Integer features: the exact reference of the C streaming extractor (firmware_c).

Everything here works in the raw LSB units of the CAN signals (contracts.RAW_LSB):
a raw sample is 7 int16 values, a feature vector is 12 int16 values, and the
std of a channel uses the LSB of that channel.

Integer procedure per window and channel (mirrored in firmware_c/src/slipest_features.c):

    n = samples present in the window (1..100), x_i int16
    S = sum x_i            (int64; |S| <= 100 * 2^15)
    Q = sum x_i^2          (int64; Q <= 100 * 2^30)
    mean_q = round_half_away_from_zero(S / n)
           = sign(S) * floor((2|S| + n) / (2n))
    D      = n*Q - S^2     (>= 0, exact; = n^2 * population variance)
    std_q  = round_half_up(sqrt(D) / n)
           = floor((floor(isqrt(4D) / n) + 1) / 2)
      (k <= sqrt(D)/n + 1/2  <=>  (2k-1) n <= 2 sqrt(D)  <=>  (2k-1) n <= isqrt(4D),
       since the left side is an integer; isqrt = floor of the exact square root)
    every feature is saturated to int16 (only a std of exactly 32768 can exceed it);
    each saturated value counts one saturation event.

Windowing and gaps (the estimator behaviour rules; see docs/firmware.md):
    the grid starts at the first accepted sample; slot = counter - start (16-bit counters,
    unwrapped); window w holds slots [100 w, 100 w + 100). A sample whose counter is not
    ahead of the last accepted one (16-bit delta 0 or >= 32768) is rejected and counted.
    Every skipped slot counts one dropped sample. A window is emitted when its last slot is
    filled or when a sample of a later window arrives; the final window of a stream is
    emitted only if its last slot was filled. Windows without any sample are not emitted
    (their index is skipped, they still count as flagged). Flags: bit0 gap (n < 100),
    bit2 invalid input (n < 5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contracts import FEATURE_SOURCES, MIN_SAMPLES_PER_WINDOW, N_CHANNELS, N_FEATURES, RAW_CHANNELS, RAW_LSB
from .features import finite_matrix
from ..errors import InputError

INT16_MIN, INT16_MAX = -32768, 32767
SAMPLES_PER_WINDOW = 100
FLAG_GAP = 0x01
FLAG_SATURATION = 0x02
FLAG_INVALID = 0x04
FLAG_FEATURES_INPUT = 0x08

CHANNEL_LSB = np.array([RAW_LSB[c] for c in RAW_CHANNELS])
FEATURE_LSB = np.array([RAW_LSB[c] for c, _ in FEATURE_SOURCES])
_CH_INDEX = {c: i for i, c in enumerate(RAW_CHANNELS)}
_FEAT_CHANNEL = np.array([_CH_INDEX[c] for c, _ in FEATURE_SOURCES])
_FEAT_IS_MEAN = np.array([stat == "mean" for _, stat in FEATURE_SOURCES])


def _round_half_away(x: np.ndarray) -> np.ndarray:
    return np.sign(x) * np.floor(np.abs(x) + 0.5)


def _quantize(x: np.ndarray, lsb: np.ndarray, what: str, width: int) -> tuple[np.ndarray, int]:
    x = finite_matrix(x, width, what)
    q = _round_half_away(x / lsb)
    saturated = int(np.count_nonzero((q < INT16_MIN) | (q > INT16_MAX)))
    return np.clip(q, INT16_MIN, INT16_MAX).astype(np.int16), saturated


def saturated_values(x_float: np.ndarray) -> np.ndarray:
    """(n, 7) bool: the values of raw samples (n,7) that int16 CAN units cannot carry (quantize_samples clips them)."""
    q = _round_half_away(np.asarray(x_float, dtype=np.float64) / CHANNEL_LSB)
    return (q < INT16_MIN) | (q > INT16_MAX)


def saturated_rows(x_float: np.ndarray) -> np.ndarray:
    """(n,) bool: rows of raw samples (n,7) holding a value that int16 CAN units cannot carry (quantize_samples clips it)."""
    return saturated_values(x_float).any(axis=1)


def quantize_features(x_float: np.ndarray, return_saturations: bool = False):
    """Float features (N,12) in physical units -> int16 (N,12) in raw LSB units.

    round-half-away-from-zero(x / LSB), saturated to int16. With return_saturations,
    returns (q, number of saturated values).
    """
    q, sat = _quantize(x_float, FEATURE_LSB, "features", N_FEATURES)
    return (q, sat) if return_saturations else q


def quantize_samples(x_float: np.ndarray, return_saturations: bool = False):
    """Raw samples (n,7) in physical units (RAW_CHANNELS order) -> int16 (n,7) CAN raw units."""
    q, sat = _quantize(x_float, CHANNEL_LSB, "samples", N_CHANNELS)
    return (q, sat) if return_saturations else q


def isqrt_u64(x: np.ndarray) -> np.ndarray:
    """Exact floor(sqrt(x)) for int64 arrays with 0 <= x < 2^62."""
    x = np.asarray(x, dtype=np.int64)
    r = np.floor(np.sqrt(x.astype(np.float64))).astype(np.int64)
    # float sqrt is off by at most one here; fix it up exactly
    r = np.where(r * r > x, r - 1, r)
    r = np.where((r + 1) * (r + 1) <= x, r + 1, r)
    return r


def int_window_stats(sums: np.ndarray, sumsq: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact integer mean and std (both int64, unsaturated) from per-window sums.

    sums, sumsq: (W, C) int64; n: (W,) int64 >= 1.
    """
    s = np.asarray(sums, dtype=np.int64)
    q = np.asarray(sumsq, dtype=np.int64)
    nn = np.asarray(n, dtype=np.int64)[:, None]
    mean = np.sign(s) * ((2 * np.abs(s) + nn) // (2 * nn))
    d = nn * q - s * s
    std = (isqrt_u64(4 * d) // nn + 1) // 2
    return mean, std


@dataclass(frozen=True)
class IntWindows:
    features: np.ndarray  # (W,12) int16, raw LSB units (zeros for windows with no sample)
    n_samples: np.ndarray  # (W,) int64 samples present
    flags: np.ndarray  # (W,) uint8: bit0 gap, bit1 saturation, bit2 invalid (n < 5)
    window_index: np.ndarray  # (W,) int64 index on the window grid (window_counter = index mod 65536)
    saturations: np.ndarray  # (W,) int64 saturated feature values per window
    samples_dropped: int  # slots skipped before the last accepted sample
    samples_rejected: int  # samples not ahead of the previous one (late/duplicate)
    windows_flagged: int  # windows with a gap, including skipped empty windows


def _unwrap(counters: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Accepted-sample mask and unwrapped slot of each accepted sample.

    Sequential rule: a sample is accepted iff its 16-bit delta to the last *accepted*
    counter is in 1..32767. Vectorised fast path when every delta is valid.
    """
    c = np.asarray(counters, dtype=np.int64) & 0xFFFF
    if len(c) == 0:
        return np.zeros(0, bool), np.zeros(0, np.int64)
    delta = (np.diff(c) & 0xFFFF)
    if np.all((delta >= 1) & (delta <= 32767)):
        return np.ones(len(c), bool), np.concatenate([[0], np.cumsum(delta)])
    accepted = np.zeros(len(c), bool)
    slots = np.zeros(len(c), np.int64)
    accepted[0] = True
    last, slot = int(c[0]), 0
    for i in range(1, len(c)):
        d = (int(c[i]) - last) & 0xFFFF
        if 1 <= d <= 32767:
            slot += d
            last = int(c[i])
            accepted[i] = True
            slots[i] = slot
    return accepted, slots


def featurise_int(samples: np.ndarray, counters: np.ndarray | None = None) -> IntWindows:
    """int16 raw samples (n,7) + optional 16-bit counters -> integer windows (see module doc).

    Without counters the samples are consecutive (counter = index), which gives the
    same windows as `fleetlab.data.features.featurise` on `samples * LSB`.
    """
    x = np.asarray(samples)
    if x.ndim != 2 or x.shape[1] != N_CHANNELS:
        raise InputError(f"samples must have shape (n, {N_CHANNELS}), got {x.shape}")
    if not np.issubdtype(x.dtype, np.integer) or (x.size and (x.min() < INT16_MIN or x.max() > INT16_MAX)):
        raise InputError("samples must be integers in int16 range (raw CAN units); use quantize_samples")
    if counters is None:
        counters = np.arange(len(x), dtype=np.int64)
    counters = np.asarray(counters)
    if counters.shape != (len(x),):
        raise InputError(f"counters must have shape ({len(x)},), got {counters.shape}")
    accepted, slots = _unwrap(counters)
    x = x[accepted].astype(np.int64)
    slots = slots[accepted]
    # every slot skipped before the last accepted sample counts, emitted window or not
    dropped = int(slots[-1] + 1 - len(x)) if len(x) else 0
    rejected = int(len(accepted) - np.count_nonzero(accepted))
    spw = SAMPLES_PER_WINDOW
    if len(x) == 0:
        empty = np.zeros(0, np.int64)
        return IntWindows(np.zeros((0, N_FEATURES), np.int16), empty, empty.astype(np.uint8), empty, empty, 0, rejected, 0)
    win = slots // spw
    last_slot = int(slots[-1])
    # the final window is emitted only if its last slot was filled
    n_win = win[-1] + 1 if last_slot % spw == spw - 1 else win[-1]
    keep = win < n_win
    x, win, slots = x[keep], win[keep], slots[keep]
    n_per = np.bincount(win, minlength=n_win).astype(np.int64)
    present = np.flatnonzero(n_per > 0)
    sums = np.zeros((n_win, N_CHANNELS), np.int64)
    sumsq = np.zeros((n_win, N_CHANNELS), np.int64)
    np.add.at(sums, win, x)
    np.add.at(sumsq, win, x * x)
    n = n_per[present]
    mean, std = int_window_stats(sums[present], sumsq[present], n)
    feats = np.where(_FEAT_IS_MEAN, mean[:, _FEAT_CHANNEL], std[:, _FEAT_CHANNEL])
    sat = np.count_nonzero((feats < INT16_MIN) | (feats > INT16_MAX), axis=1).astype(np.int64)
    feats = np.clip(feats, INT16_MIN, INT16_MAX).astype(np.int16)
    flags = np.zeros(len(present), np.uint8)
    flags[n < spw] |= FLAG_GAP
    flags[n < MIN_SAMPLES_PER_WINDOW] |= FLAG_INVALID
    flags[sat > 0] |= FLAG_SATURATION
    return IntWindows(
        features=feats,
        n_samples=n,
        flags=flags,
        window_index=present.astype(np.int64),
        saturations=sat,
        samples_dropped=dropped,
        samples_rejected=rejected,
        windows_flagged=int(np.count_nonzero(n_per < spw)),
    )


def features_float_from_int_sums(sums: np.ndarray, sumsq: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Float features (W,12) in physical units from exact integer sums (the C float path)."""
    s = np.asarray(sums, dtype=np.float64)
    d = (np.asarray(n, np.int64)[:, None] * np.asarray(sumsq, np.int64) - np.asarray(sums, np.int64) ** 2).astype(np.float64)
    nn = np.asarray(n, dtype=np.float64)[:, None]
    mean = s / nn * CHANNEL_LSB
    std = np.sqrt(d) / nn * CHANNEL_LSB
    return np.where(_FEAT_IS_MEAN, mean[:, _FEAT_CHANNEL], std[:, _FEAT_CHANNEL])
