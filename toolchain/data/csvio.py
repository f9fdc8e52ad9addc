"""Read and write window tables in the Fleet-To-Lab CSV format (18 columns, CRLF or LF)."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .contracts import CSV_COLUMNS, N_CLASSES, N_FEATURES
from .features import LabelledWindows
from ..errors import InputError


class CsvFormatError(InputError):
    """A CSV file that does not follow the Fleet-To-Lab format; names file and line."""

    def __init__(self, path: Path | str, line: int | None, message: str):
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {message}")
        self.path = Path(path)
        self.line = line


@dataclass
class WindowTable:
    """Rows of one or more window CSV files."""

    features: np.ndarray  # (n, 12) float64
    d_actual: np.ndarray  # (n,)
    d_commanded: np.ndarray  # (n,)
    slip_pct: np.ndarray  # (n,) percent
    label: np.ndarray  # (n,) int64
    n_samples: np.ndarray  # (n,) int64
    duration_s: np.ndarray  # (n,)
    rejected_nonfinite: int = 0  # rows dropped because a value was NaN/Inf
    rejected_lines: list[int] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.label)

    def class_counts(self) -> list[int]:
        return np.bincount(self.label, minlength=N_CLASSES).tolist()

    @classmethod
    def from_windows(cls, w: LabelledWindows) -> "WindowTable":
        return cls(
            features=w.features,
            d_actual=w.d_actual,
            d_commanded=w.d_commanded,
            slip_pct=100.0 * w.slip,
            label=w.label,
            n_samples=w.n_samples,
            duration_s=w.duration_s,
        )

    @classmethod
    def concat(cls, tables: list["WindowTable"]) -> "WindowTable":
        if not tables:
            raise InputError("no tables to concatenate")
        cat = lambda name: np.concatenate([getattr(t, name) for t in tables])  # noqa: E731
        return cls(
            features=cat("features"),
            d_actual=cat("d_actual"),
            d_commanded=cat("d_commanded"),
            slip_pct=cat("slip_pct"),
            label=cat("label"),
            n_samples=cat("n_samples"),
            duration_s=cat("duration_s"),
            rejected_nonfinite=sum(t.rejected_nonfinite for t in tables),
        )


def read_windows_csv(path: Path | str) -> WindowTable:
    """Parse one Fleet-To-Lab CSV file.

    Raises CsvFormatError (file and line) on a wrong header, a wrong number of
    fields, a value that is not a number or a class outside 0..2. Rows holding
    NaN/Inf are rejected and counted in `rejected_nonfinite`, never returned.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise CsvFormatError(path, None, f"not UTF-8 text ({e.reason})") from None
    reader = csv.reader(text.splitlines())
    try:
        header = next(reader)
    except StopIteration:
        raise CsvFormatError(path, 1, "empty file (no header)") from None
    header = [h.strip() for h in header]
    if tuple(header) != CSV_COLUMNS:
        missing = [c for c in CSV_COLUMNS if c not in header]
        extra = [c for c in header if c not in CSV_COLUMNS]
        detail = f"missing {missing}" if missing else ""
        detail += f"{'; ' if detail else ''}unexpected {extra}" if extra else ""
        raise CsvFormatError(path, 1, f"header is not the 18 Fleet-To-Lab columns in order ({detail or 'wrong order'})")

    rows: list[list[float]] = []
    rejected: list[int] = []
    for lineno, fields in enumerate(reader, start=2):
        if not fields or all(not f.strip() for f in fields):
            continue  # blank line (e.g. trailing newline)
        if len(fields) != len(CSV_COLUMNS):
            raise CsvFormatError(path, lineno, f"expected {len(CSV_COLUMNS)} fields, found {len(fields)}")
        values = []
        for name, raw in zip(CSV_COLUMNS, fields):
            try:
                values.append(float(raw))
            except ValueError:
                raise CsvFormatError(path, lineno, f"column {name}: {raw!r} is not a number") from None
        if not all(math.isfinite(v) for v in values):
            rejected.append(lineno)
            continue
        cls_value = values[N_FEATURES + 3]
        if cls_value not in (0.0, 1.0, 2.0):
            raise CsvFormatError(path, lineno, f"column slip_class: {cls_value:g} is not 0, 1 or 2")
        rows.append(values)

    a = np.array(rows, dtype=np.float64).reshape(-1, len(CSV_COLUMNS))
    f = N_FEATURES
    return WindowTable(
        features=a[:, :f].copy(),
        d_actual=a[:, f],
        d_commanded=a[:, f + 1],
        slip_pct=a[:, f + 2],
        label=a[:, f + 3].astype(np.int64),
        n_samples=a[:, f + 4].astype(np.int64),
        duration_s=a[:, f + 5],
        rejected_nonfinite=len(rejected),
        rejected_lines=rejected,
    )


def write_windows_csv(path: Path | str, table: WindowTable, line_ending: str = "\r\n") -> None:
    """Write a table in the Fleet-To-Lab format (CRLF by default, like the originals)."""
    cols = np.column_stack(
        [
            table.features,
            table.d_actual,
            table.d_commanded,
            table.slip_pct,
            table.label,
            table.n_samples,
            table.duration_s,
        ]
    )
    int_cols = {N_FEATURES + 3, N_FEATURES + 4}
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write(",".join(CSV_COLUMNS) + line_ending)
        for row in cols:
            fh.write(
                ",".join(str(int(v)) if i in int_cols else repr(float(v)) for i, v in enumerate(row))
                + line_ending
            )


# Windows without ground truth (`fleetlab data import` without [ground_truth]): the features and what the
# wheels say, no label columns at all, so that no reader takes them for labelled windows.
UNLABELLED_SUFFIX = ".unlabelled.csv"
UNLABELLED_COLUMNS: tuple[str, ...] = CSV_COLUMNS[:N_FEATURES] + ("total_dist_cmd", "n_samples", "win_duration_s")


def read_unlabelled_csv(path: Path | str) -> np.ndarray:
    """The features (n, 12) of an unlabelled window file; rows holding NaN/Inf are left out."""
    path = Path(path)
    lines = path.read_text(encoding="utf-8-sig").splitlines()
    header = tuple(h.strip() for h in lines[0].split(",")) if lines else ()
    if header != UNLABELLED_COLUMNS:
        raise CsvFormatError(path, 1, f"header is not the {len(UNLABELLED_COLUMNS)} columns of an unlabelled window "
                             "file (the 12 features, total_dist_cmd, n_samples, win_duration_s)")
    rows = [ln for ln in lines[1:] if ln.strip()]
    try:
        a = np.array([[float(v) for v in ln.split(",")] for ln in rows], dtype=np.float64).reshape(-1, len(header))
    except ValueError as e:
        raise CsvFormatError(path, None, f"not a number: {e}") from None
    return a[np.isfinite(a).all(axis=1), :N_FEATURES]
