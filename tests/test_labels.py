import numpy as np

from fleetlab.data.labels import slip_class, slip_ratio


def test_slip_definition():
    np.testing.assert_allclose(slip_ratio([0.8, 1.0, 0.0], [1.0, 1.0, 1.0]), [0.2, 0.0, 1.0])


def test_negative_slip_is_kept_and_classed_by_magnitude():
    s = slip_ratio([1.5, 1.2], [1.0, 1.0])  # skid: travelled more than commanded
    np.testing.assert_allclose(s, [-0.5, -0.2])
    assert slip_class(s).tolist() == [1, 0]


def test_clipped_to_plus_minus_one():
    s = slip_ratio([5.0, -1.0], [1.0, 1.0])
    np.testing.assert_allclose(s, [-1.0, 1.0])
    assert slip_class(s).tolist() == [2, 2]


def test_tiny_commanded_distance_means_zero_slip():
    s = slip_ratio([0.0, 0.0, 0.04], [0.0, 0.0499, 0.05])
    assert s.tolist() == [0.0, 0.0, 1 - 0.04 / 0.05]
    assert slip_class(s[:2]).tolist() == [0, 0]


def test_stationary_window_zero_distance_no_division_warning():
    with np.errstate(all="raise"):
        assert slip_ratio([0.0], [0.0]).tolist() == [0.0]


def test_class_boundaries_are_inclusive_upper():
    assert slip_class([0.3, 0.30001, 0.6, 0.60001, -0.3, -0.6]).tolist() == [0, 1, 1, 2, 0, 1]
