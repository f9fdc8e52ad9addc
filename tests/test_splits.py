import numpy as np
import pytest

from fleetlab.data.splits import make_split


def _data():
    rng = np.random.default_rng(0)
    y = rng.choice(3, size=1000, p=[0.65, 0.22, 0.13])
    groups = np.repeat(np.arange(8), 125)
    return y, groups


@pytest.mark.parametrize("size", [150, 200])
def test_paper_split_is_stratified_and_seeded(size):
    y, g = _data()
    s = make_split("paper", y, g, size, seed=3)
    assert len(s.cal) == size and len(s.cal) + len(s.test) == len(y)
    assert np.intersect1d(s.cal, s.test).size == 0
    share = np.bincount(y[s.cal], minlength=3) / size
    np.testing.assert_allclose(share, np.bincount(y, minlength=3) / len(y), atol=0.01)
    assert np.array_equal(s.cal, make_split("paper", y, g, size, seed=3).cal)
    assert not np.array_equal(s.cal, make_split("paper", y, g, size, seed=4).cal)


def test_traverse_split_never_shares_a_traverse():
    y, g = _data()
    for seed in range(10):
        s = make_split("traverse", y, g, 150, seed)
        assert len(s.cal) == 150
        assert not set(g[s.cal]) & set(g[s.test])
        assert len(s.test) >= 125


def test_split_errors():
    y, g = _data()
    with pytest.raises(ValueError, match="unknown split protocol"):
        make_split("random", y, g, 150, 0)
    with pytest.raises(ValueError, match="exceeds"):
        make_split("paper", y, g, 2000, 0)
    with pytest.raises(ValueError, match="traverse split needs"):
        make_split("traverse", y, np.zeros_like(g), 150, 0)
