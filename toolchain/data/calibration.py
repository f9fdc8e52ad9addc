"""One calibration set D_Cal and its test rows: drawn from the target data, or read from a file."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .csvio import read_windows_csv
from .dataset import TARGET, Dataset
from .label_noise import VoModel, read_vo_readings, vo_calibration_labels
from .splits import make_split
from ..errors import InputError


@dataclass
class CalibrationSet:
    x_cal: np.ndarray
    y_cal: np.ndarray
    x_test: np.ndarray
    y_test: np.ndarray
    info: dict  # JSON-ready description: source, sizes, drawn indices or dropped rows
    y_cal_probs: np.ndarray | None = None  # (N, 3) the class probabilities of VO's readings, where D_Cal has them


def calibration_set(dataset: Dataset, protocol: str, cal_size: int, seed: int,
                    calibration_csv: Path | None = None, vo_labels: Path | None = None,
                    vo: VoModel = VoModel()) -> CalibrationSet:
    """D_Cal drawn with `make_split(protocol, ...)` from the target rows, or, with
    `calibration_csv`, the windows of that file (target rows also in it are not test rows). With
    `vo_labels` (a VO label file of the same windows, `label_noise.read_vo_readings`) D_Cal's labels are
    VO's, and its readings' class probabilities under the error model `vo` come with them."""
    if vo_labels is not None and calibration_csv is None:
        raise InputError("VO readings (--vo-labels) belong to the windows of a calibration file: give --calibration too")
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
    probs = None
    if vo_labels is not None:
        y_cal, probs, vo_info = _vo_labelled(table, y_cal, vo_labels, vo, calibration_csv)
        info["labels"] = vo_info
    return CalibrationSet(x_cal, y_cal, x[~in_cal], y[~in_cal], info, probs)


def _vo_labelled(table, file_labels: np.ndarray, vo_labels: Path, vo: VoModel,
                 calibration_csv: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """(VO's labels, their class probabilities, what the report says of them) for the windows of `table`."""
    if table.rejected_nonfinite:  # a rejected window would shift every VO row after it onto the wrong window
        raise InputError(f"{calibration_csv}: {table.rejected_nonfinite} window(s) with NaN/Inf were rejected, so the "
                         f"rows of {vo_labels} no longer line up with the windows; remove them from both files")
    measured, dropped = read_vo_readings(vo_labels)
    if measured.size != len(table):
        raise InputError(f"{vo_labels}: {measured.size} VO readings for the {len(table)} windows of {calibration_csv}; "
                         "the file needs one row per window, in order")
    labels, probs = vo_calibration_labels(measured, dropped, table.d_commanded, vo)
    return labels, probs, {"source": f"visual odometry ({vo_labels})", "vo_model": asdict(vo),
                           "vo_dropouts": int(dropped.sum()),
                           "differ_from_file_labels": int((labels != file_labels).sum())}
