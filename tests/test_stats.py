"""Corrected resampled t-test (Nadeau & Bengio), checked against a hand-worked example."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fleetlab.evaluation.stats import correction_factor, corrected_resampled_ttest


def student_t3_cdf(t: float) -> float:
    """Closed-form CDF of Student's t with 3 degrees of freedom (independent of scipy):
    F(t) = 1/2 + (1/pi) * (u / (1 + u^2) + atan(u)),  u = t / sqrt(3)."""
    u = t / math.sqrt(3.0)
    return 0.5 + (u / (1.0 + u * u) + math.atan(u)) / math.pi


def test_hand_worked_example_nadeau_bengio_form():
    # Paired scores over n = 4 runs; differences d = a - b = [1, 2, 3, 4].
    a = np.array([1.5, 2.5, 3.5, 4.5])
    b = np.array([0.5, 0.5, 0.5, 0.5])
    # mean(d) = 2.5; var(d, ddof=1) = ((1.5² + 0.5²) * 2) / 3 = 5/3.
    # n_train = 100 (|D_Cal|), n_test = 50: factor = 1/4 + 50/100 = 0.75.
    # t = 2.5 / sqrt(0.75 * 5/3) = 2.5 / sqrt(1.25) = sqrt(5) = 2.2360680
    # p = 2 * (1 - F_3(sqrt 5)) with the closed form above = 0.111367
    res = corrected_resampled_ttest(a, b, n_train=100, n_test=50)
    assert res.df == 3
    assert res.mean_diff == pytest.approx(2.5)
    assert res.var_diff == pytest.approx(5 / 3)
    assert res.correction == pytest.approx(0.75)
    assert res.t == pytest.approx(math.sqrt(5.0), rel=1e-12)
    assert res.p == pytest.approx(2 * (1 - student_t3_cdf(math.sqrt(5.0))), rel=1e-9)
    assert res.p == pytest.approx(0.111367, abs=2e-6)


def test_hand_worked_example_reference_form():
    # Same data, the reference notes' factor 1/4 + 100/50 = 2.25:
    # t = 2.5 / sqrt(2.25 * 5/3) = 2.5 / sqrt(3.75) = 1.2909944; p = 0.287190
    res = corrected_resampled_ttest([1.5, 2.5, 3.5, 4.5], [0.5] * 4, n_train=100, n_test=50, form="reference")
    assert res.correction == pytest.approx(2.25)
    assert res.t == pytest.approx(2.5 / math.sqrt(3.75), rel=1e-12)
    assert res.p == pytest.approx(2 * (1 - student_t3_cdf(2.5 / math.sqrt(3.75))), rel=1e-9)
    assert res.p == pytest.approx(0.287190, abs=2e-6)


def test_sign_and_symmetry():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0.6, 0.02, 30), rng.normal(0.58, 0.02, 30)
    ab = corrected_resampled_ttest(a, b, 150, 1200)
    ba = corrected_resampled_ttest(b, a, 150, 1200)
    assert ab.t == pytest.approx(-ba.t)
    assert ab.p == pytest.approx(ba.p)
    assert 0.0 <= ab.p <= 1.0


def test_correction_makes_the_test_more_conservative():
    rng = np.random.default_rng(1)
    a, b = rng.normal(0.62, 0.02, 30), rng.normal(0.60, 0.02, 30)
    plain_like = corrected_resampled_ttest(a, b, n_train=1e9, n_test=1e-9 + 1e-12)  # factor -> 1/n
    corrected = corrected_resampled_ttest(a, b, n_train=150, n_test=1200)
    assert corrected.correction > plain_like.correction
    assert corrected.p > plain_like.p
    assert abs(corrected.t) < abs(plain_like.t)


def test_zero_variance_and_bad_input():
    same = corrected_resampled_ttest([0.5, 0.5, 0.5], [0.5, 0.5, 0.5], 10, 10)
    assert (same.t, same.p) == (0.0, 1.0)
    shifted = corrected_resampled_ttest([0.6, 0.6, 0.6], [0.5, 0.5, 0.5], 10, 10)
    assert shifted.t == math.inf and shifted.p == 0.0
    with pytest.raises(ValueError, match="equal length"):
        corrected_resampled_ttest([1, 2, 3], [1, 2], 10, 10)
    with pytest.raises(ValueError, match="at least 2"):
        corrected_resampled_ttest([1], [2], 10, 10)
    with pytest.raises(ValueError, match="positive"):
        correction_factor(5, 0, 10)
    with pytest.raises(ValueError, match="unknown t-test form"):
        correction_factor(5, 10, 10, form="plain")
