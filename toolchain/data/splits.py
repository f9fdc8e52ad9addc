"""Calibration / test splits of the target-rover Moon data.

`paper`: stratified random rows (the paper's protocol; windows of one traverse
can land on both sides). `traverse`: leakage-free, calibration rows come from
some traverses (files) and the test set is every row of the other traverses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.model_selection import train_test_split
from ..errors import InputError

PROTOCOLS = ("paper", "traverse")


@dataclass(frozen=True)
class Split:
    cal: np.ndarray  # row indices of D_Cal
    test: np.ndarray  # row indices of the test set

    def __post_init__(self):
        if np.intersect1d(self.cal, self.test).size:
            raise AssertionError("calibration and test rows overlap")


def _stratified_pick(y: np.ndarray, rows: np.ndarray, size: int, seed: int) -> np.ndarray:
    """`size` rows of `rows`, stratified by class where every class has at least 2 rows."""
    if size > len(rows):
        raise InputError(f"calibration size {size} exceeds the {len(rows)} rows available")
    if size == len(rows):
        return np.sort(rows)
    counts = np.bincount(y[rows])
    stratify = y[rows] if counts[counts > 0].min() >= 2 else None
    picked, _ = train_test_split(rows, train_size=size, random_state=seed, stratify=stratify)
    return np.sort(picked)


def paper_split(y: np.ndarray, cal_size: int, seed: int) -> Split:
    rows = np.arange(len(y))
    cal = _stratified_pick(y, rows, cal_size, seed)
    return Split(cal=cal, test=np.setdiff1d(rows, cal))


def traverse_split(y: np.ndarray, groups: np.ndarray, cal_size: int, seed: int) -> Split:
    """Whole traverses go to calibration until they hold `cal_size` rows; D_Cal is drawn from
    them (stratified) and the test set is every row of the remaining traverses."""
    rng = np.random.default_rng(seed)
    traverses = rng.permutation(np.unique(groups))
    sizes = np.array([np.sum(groups == g) for g in traverses])
    n_cal = int(np.searchsorted(np.cumsum(sizes), cal_size) + 1)
    if n_cal >= len(traverses):
        raise InputError(
            f"traverse split needs {cal_size} calibration rows and at least one other traverse for testing; "
            f"the {len(traverses)} traverses hold {sizes.sum()} rows"
        )
    cal_pool = np.flatnonzero(np.isin(groups, traverses[:n_cal]))
    cal = _stratified_pick(y, cal_pool, cal_size, seed)
    return Split(cal=cal, test=np.flatnonzero(np.isin(groups, traverses[n_cal:])))


def make_split(protocol: str, y: np.ndarray, groups: np.ndarray, cal_size: int, seed: int) -> Split:
    if protocol == "paper":
        return paper_split(y, cal_size, seed)
    if protocol == "traverse":
        return traverse_split(y, groups, cal_size, seed)
    raise InputError(f"unknown split protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")
