"""One calibration set D_Cal and its test rows: drawn from the target data, or read from a file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .csvio import read_windows_csv
from .dataset import TARGET, Dataset
from .splits import make_split
from ..errors import InputError


@dataclass
class CalibrationSet:
    x_cal: np.ndarray
    y_cal: np.ndarray
    x_test: np.ndarray
    y_test: np.ndarray
    info: dict  # JSON-ready description: source, sizes, drawn indices or dropped rows


def calibration_set(dataset: Dataset, protocol: str, cal_size: int, seed: int,
                    calibration_csv: Path | None = None) -> CalibrationSet:
    """D_Cal drawn with `make_split(protocol, ...)` from the target rows, or, with
    `calibration_csv`, the windows of that file (target rows also in it are not test rows)."""
    x, y = dataset.xy(TARGET)
    if calibration_csv is None:
        split = make_split(protocol, y, dataset.groups(TARGET), cal_size, seed)
        info = {"source": f"{protocol} split of the target data", "protocol": protocol,
                "size": int(len(split.cal)), "indices": split.cal.tolist(), "test_size": int(len(split.test))}
        return CalibrationSet(x[split.cal], y[split.cal], x[split.test], y[split.test], info)
    table = read_windows_csv(calibration_csv)
    if len(table) == 0:
        raise InputError(f"{calibration_csv}: calibration file has no usable rows")
    x_cal, y_cal = table.features.astype(np.float32), table.label
    # Target rows that also appear in the calibration file are not test rows: drop and count them.
    cal_rows = {row.tobytes() for row in x_cal}
    in_cal = np.array([row.tobytes() in cal_rows for row in x])
    info = {"source": str(calibration_csv), "size": int(len(y_cal)), "test_size": int((~in_cal).sum()),
            "test_rows_dropped_as_calibration": int(in_cal.sum()), "rejected_nonfinite": table.rejected_nonfinite}
    if (~in_cal).sum() == 0:
        raise InputError(f"{calibration_csv}: every target row is in the calibration file; nothing left to test on")
    return CalibrationSet(x_cal, y_cal, x[~in_cal], y[~in_cal], info)
