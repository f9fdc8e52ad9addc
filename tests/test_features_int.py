"""fleetlab.data.features_int: quantisation and the integer window reference of the C extractor.

The integer statistics are checked against an independent exact computation (Python ints
and Decimal square roots) and the gap rules against a plain sequential re-statement of the
estimator behaviour rules.
"""

from __future__ import annotations

import math
from decimal import ROUND_FLOOR, Decimal, getcontext

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlab.data.features import featurise
from fleetlab.data.features_int import (
    CHANNEL_LSB,
    FEATURE_LSB,
    FLAG_GAP,
    FLAG_INVALID,
    FLAG_SATURATION,
    featurise_int,
    features_float_from_int_sums,
    isqrt_u64,
    quantize_features,
    quantize_samples,
)

getcontext().prec = 60
FEAT_CH = [0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 6, 5]
FEAT_MEAN = [True, False, True, False, True, False, True, False, True, False, True, True]


def exact_window(xs: list[list[int]]) -> tuple[list[int], int]:
    """Features of one window by exact arithmetic: mean half away from zero, std half up."""
    n = len(xs)
    out, sat = [], 0
    for ch, is_mean in zip(FEAT_CH, FEAT_MEAN):
        col = [x[ch] for x in xs]
        s = sum(col)
        if is_mean:
            q = Decimal(abs(s)) / Decimal(n)
            v = int((q + Decimal("0.5")).to_integral_value(rounding=ROUND_FLOOR))
            v = -v if s < 0 else v
        else:
            d = n * sum(c * c for c in col) - s * s
            v = int((Decimal(d).sqrt() / n + Decimal("0.5")).to_integral_value(rounding=ROUND_FLOOR))
        if v > 32767 or v < -32768:
            sat += 1
            v = max(-32768, min(32767, v))
        out.append(v)
    return out, sat


def sequential_reference(samples: np.ndarray, counters: np.ndarray):
    """The estimator rules, one sample at a time (what the C extractor does)."""
    windows, last, slot, rejected, dropped = {}, None, 0, 0, 0
    order = []
    for x, c in zip(samples.tolist(), counters.tolist()):
        c &= 0xFFFF
        if last is not None:
            d = (c - last) & 0xFFFF
            if d == 0 or d >= 32768:
                rejected += 1
                continue
            dropped += d - 1
            slot += d
        last = c
        w = slot // 100
        if w not in windows:
            windows[w] = []
            order.append(w)
        windows[w].append(x)
    if not order:
        return [], rejected, dropped, 0
    # grid windows closed so far: all before the open one, and the open one if its last slot came
    n_win = order[-1] + 1 if slot % 100 == 99 else order[-1]
    return [(w, windows[w]) for w in order if w < n_win], rejected, dropped, n_win


def test_quantize_features_rounds_half_away_and_saturates():
    x = np.zeros((1, 12))
    x[0, 0] = 0.0025  # 2.5 LSB -> 3
    x[0, 1] = -0.0025  # -> -3
    x[0, 2] = 0.014  # current LSB 0.01: 1.4 -> 1
    x[0, 10] = 1e3  # pitch: far beyond int16 -> 32767
    x[0, 11] = -1e3
    q, sat = quantize_features(x, return_saturations=True)
    assert q.dtype == np.int16
    assert q[0, :3].tolist() == [3, -3, 1]
    assert q[0, 10] == 32767 and q[0, 11] == -32768 and sat == 2
    with pytest.raises(ValueError, match="NaN"):
        quantize_features(np.full((2, 12), np.nan))
    with pytest.raises(ValueError, match="shape"):
        quantize_features(np.zeros((2, 7)))


def test_quantize_samples_uses_channel_lsb():
    x = np.array([[1.0, 1.0, 9.81, -0.5, 0.0, 0.1, -0.1]])
    assert quantize_samples(x).tolist() == [[1000, 100, 9810, -500, 0, 1000, -1000]]


def test_isqrt_exact_near_squares():
    r = np.arange(0, 2**31 - 1, 9973, dtype=np.int64)
    for x, want in ((r * r, r), (r * r - 1, np.maximum(r - 1, 0)), (r * r + 2 * r, r)):
        assert np.array_equal(isqrt_u64(np.maximum(x, 0)), want)
    assert int(isqrt_u64(np.array([4 * 10**13]))[0]) == math.isqrt(4 * 10**13)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 100),
    seed=st.integers(0, 2**32 - 1),
    scale=st.sampled_from([1, 3, 100, 32768]),
)
def test_window_statistics_match_exact_arithmetic(n, seed, scale):
    rng = np.random.default_rng(seed)
    x = rng.integers(-scale, scale, size=(n + 1, 7)).clip(-32768, 32767).astype(np.int16)
    # n samples in window 0 (slot 0 starts the grid), then one in window 1 that closes it
    slots = [0] + np.sort(rng.choice(np.arange(1, 100), size=n - 1, replace=False)).tolist() + [100]
    w = featurise_int(x, np.array(slots))
    want, sat = exact_window(x[:n].astype(int).tolist())
    assert w.features.shape == (1, 12)
    assert w.features[0].tolist() == want
    assert int(w.saturations[0]) == sat
    assert int(w.n_samples[0]) == n


def test_extreme_window_saturates_std():
    x = np.zeros((100, 7), np.int16)
    x[::2, 0], x[1::2, 0] = -32768, 32767  # std 32767.5 -> 32768 -> clamp
    w = featurise_int(x)
    assert w.features[0, 1] == 32767 and w.saturations[0] == 1 and w.flags[0] & FLAG_SATURATION


def test_gap_free_matches_float_featuriser():
    rng = np.random.default_rng(5)
    x = rng.integers(-20000, 20000, size=(1000, 7)).astype(np.int16)
    w = featurise_int(x)
    f = featurise(x * CHANNEL_LSB)
    assert w.features.shape == f.shape == (10, 12)
    assert np.abs(w.features - f / FEATURE_LSB).max() <= 0.5 + 1e-6
    assert (w.flags == 0).all() and (w.n_samples == 100).all() and w.samples_dropped == 0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), start=st.integers(0, 65535))
def test_gaps_late_and_duplicates_follow_the_rules(seed, start):
    rng = np.random.default_rng(seed)
    steps = rng.choice([1, 1, 1, 1, 2, 5, 0, -3, 150], size=600)
    counters = (start + np.cumsum(steps)) & 0xFFFF
    x = rng.integers(-500, 500, size=(600, 7)).astype(np.int16)
    w = featurise_int(x, counters)
    ref, rejected, dropped, n_grid = sequential_reference(x, counters)
    assert w.samples_rejected == rejected and w.samples_dropped == dropped
    assert w.window_index.tolist() == [idx for idx, _ in ref]
    for k, (idx, xs) in enumerate(ref):
        want, _ = exact_window([list(map(int, s)) for s in xs])
        assert w.features[k].tolist() == want
        assert int(w.n_samples[k]) == len(xs)
        assert bool(w.flags[k] & FLAG_GAP) == (len(xs) < 100)
        assert bool(w.flags[k] & FLAG_INVALID) == (len(xs) < 5)
    # every closed grid window with < 100 samples counts, the skipped empty ones too
    full = sum(1 for _, xs in ref if len(xs) == 100)
    assert w.windows_flagged == n_grid - full


def test_float_features_from_int_sums():
    rng = np.random.default_rng(2)
    x = rng.integers(-32768, 32767, size=(300, 7)).astype(np.int64)
    win = x.reshape(3, 100, 7)
    got = features_float_from_int_sums(win.sum(1), (win * win).sum(1), np.full(3, 100))
    want = featurise(x * CHANNEL_LSB)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_featurise_int_rejects_bad_input():
    with pytest.raises(ValueError, match="int16"):
        featurise_int(np.zeros((10, 7), np.float64))
    with pytest.raises(ValueError, match="shape"):
        featurise_int(np.zeros((10, 6), np.int16))
    with pytest.raises(ValueError, match="counters"):
        featurise_int(np.zeros((10, 7), np.int16), np.arange(9))
    empty = featurise_int(np.zeros((0, 7), np.int16))
    assert empty.features.shape == (0, 12)
