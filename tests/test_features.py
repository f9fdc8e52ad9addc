import numpy as np
import pytest

from fleetlab.data.contracts import FEATURE_SOURCES, CH, N_CHANNELS
from fleetlab.data.features import WindowSpec, featurise, featurise_trace, window_sums


def _direct(samples, spw, stride):
    """Per-window computation written the plain way, one window and one feature at a time."""
    rows = []
    start = 0
    while start + spw <= len(samples):
        w = samples[start : start + spw]
        row = []
        for channel, stat in FEATURE_SOURCES:
            col = w[:, CH[channel]]
            if stat == "mean":
                row.append(sum(col) / len(col))
            else:
                m = sum(col) / len(col)
                row.append((sum((v - m) ** 2 for v in col) / len(col)) ** 0.5)
        rows.append(row)
        start += stride
    return np.array(rows).reshape(-1, 12)


@pytest.mark.parametrize("n", [0, 99, 100, 101, 1000, 1057])
def test_features_match_direct_computation(n):
    rng = np.random.default_rng(n)
    samples = rng.normal(size=(n, N_CHANNELS)) * [2, 30, 0.5, 0.5, 9.8, 0.1, 0.1] + [1, 50, 0, 0, 9.8, 0, 0]
    got = featurise(samples)
    want = _direct(samples, 100, 100)
    assert got.shape == want.shape == (n // 100, 12)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_overlapping_stride_uses_sliding_windows():
    rng = np.random.default_rng(0)
    samples = rng.normal(size=(530, N_CHANNELS))
    spec = WindowSpec(samples_per_window=100, samples_per_stride=50)
    np.testing.assert_allclose(featurise(samples, spec), _direct(samples, 100, 50), atol=1e-12)


def test_feature_order_and_population_std():
    samples = np.zeros((100, N_CHANNELS))
    samples[:, CH["wheel_speed"]] = np.r_[np.zeros(50), np.full(50, 2.0)]  # mean 1, population std 1
    samples[:, CH["pitch"]] = 0.25
    samples[:, CH["roll"]] = -0.5
    f = featurise(samples)[0]
    assert f[0] == 1.0 and f[1] == 1.0  # ddof=0 (ddof=1 would give 1.005)
    assert f[10] == 0.25 and f[11] == -0.5  # pitch mean before roll mean


def test_rate_sets_window_length():
    assert WindowSpec.for_rate(50).samples_per_window == 100
    assert WindowSpec.for_rate(10).samples_per_window == 20
    with pytest.raises(ValueError, match="at least 5"):
        WindowSpec.for_rate(1.0)


def test_nonfinite_and_bad_shape_are_refused():
    x = np.zeros((200, N_CHANNELS))
    x[150, 3] = np.nan
    with pytest.raises(ValueError, match="row 150"):
        featurise(x)
    with pytest.raises(ValueError, match="shape"):
        featurise(np.zeros((200, 6)))


def test_trace_labels_from_distance_sums():
    n = 300
    d_cmd = np.full(n, 0.01)  # 1.0 m commanded per window
    d_act = np.r_[np.full(100, 0.008), np.full(100, 0.002), np.full(100, 0.0001)]
    w = featurise_trace(np.zeros((n, N_CHANNELS)), d_act, d_cmd)
    np.testing.assert_allclose(w.d_commanded, [1.0, 1.0, 1.0])
    np.testing.assert_allclose(w.slip, [0.2, 0.8, 0.99])
    assert w.label.tolist() == [0, 2, 2]
    np.testing.assert_allclose(window_sums(d_act), w.d_actual)
    assert w.n_samples.tolist() == [100] * 3 and w.duration_s.tolist() == [2.0] * 3
