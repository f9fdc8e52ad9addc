"""Calibration labels as a rover gets them: noise models for the slip class of D_Cal.

On the Moon the slip of a calibration window is measured by visual odometry (VO) against the
wheels' commanded distance, not known exactly. Three models corrupt exact labels:

- `symmetric:RATE`  each label, with probability RATE, becomes one of the two other classes (uniform);
- `adjacent:RATE`   each label, with probability RATE, becomes a neighbouring class (low <-> moderate,
                    moderate <-> high; moderate goes either way): the confusion a biased distance makes;
- `vo:SCALE`        the window's travelled distance is measured again by the VO model below (its error
                    magnitudes times SCALE; 1 = the defaults), the slip recomputed from it
                    (`labels.slip_ratio`) and thresholded into the classes as exact labels are.

The VO model (`VoModel`, defaults and their sources in docs/paper_table.md, "Noisy calibration labels"):
a scale error per traverse, a distance error that grows with the distance travelled in the window,
tracking dropouts (the rover then keeps its wheel odometry, i.e. measures no slip) that are more
frequent on low-texture terrain, and a time offset between the VO frames and the wheel windows (a
window's VO distance takes a share of the previous window's).

A VO label also says how sure it is: VO reports when it did not converge, and its error model gives
each measured distance a standard deviation. `vo_class_probabilities` turns one reading into the
probability of each slip class; `acomerge-vo` fuses on those instead of the hard class.

Every draw comes from the generator it is given, so a corruption is reproducible by seed; nothing
here touches the test rows of an evaluation (the caller corrupts D_Cal only).
"""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.special import ndtr

from .contracts import CLASS_THRESHOLDS, MIN_COMMANDED_DISTANCE_M, N_CLASSES
from .csvio import CsvFormatError
from .labels import slip_class, slip_ratio
from ..errors import InputError

KINDS = ("symmetric", "adjacent", "vo")


@dataclass(frozen=True)
class VoModel:
    """Visual odometry's error on one window's travelled distance (magnitudes at SCALE 1)."""

    drift: float = 0.02  # 1-sigma distance error per metre travelled in the window (2 % of distance)
    scale_sigma: float = 0.01  # 1-sigma scale error, one draw per traverse
    dropout: float = 0.04  # chance a window's VO fails to converge (MER: 3 % Spirit, 5 % Opportunity)
    dropout_low_texture: float = 0.15  # the same on low-texture terrain (fine regolith, no rocks)
    lag_s: float = 0.2  # VO frames lag the wheel windows by this much time
    resolution_m: float = 0.002  # smallest motion VO resolves (MER: 2 mm): the error's floor

    def scaled(self, scale: float) -> "VoModel":
        """Every error magnitude times `scale` (probabilities capped at 1)."""
        return VoModel(self.drift * scale, self.scale_sigma * scale, min(1.0, self.dropout * scale),
                       min(1.0, self.dropout_low_texture * scale), self.lag_s * scale, self.resolution_m * scale)

    def error_sigma(self, measured: np.ndarray) -> np.ndarray:
        """1-sigma error of a measured window distance: the distance error and the traverse's scale error
        together. The lag is left out: it is a share of the window before, not an error of known size."""
        m = np.abs(np.asarray(measured, dtype=np.float64))
        return np.hypot(self.drift * m + self.resolution_m, self.scale_sigma * m)

    def measure(self, d_actual: np.ndarray, groups: np.ndarray, duration_s: np.ndarray, rng: np.random.Generator,
                low_texture: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(VO distance per window, which windows dropped out). Rows of one group (traverse) are in time order."""
        d = np.asarray(d_actual, dtype=np.float64)
        groups = np.asarray(groups)
        n = d.size
        # time offset: a window's VO distance takes the share lag/duration from the window before it
        prev = np.r_[d[:1], d[:-1]]
        first = np.r_[True, groups[1:] != groups[:-1]]
        prev = np.where(first, d, prev)
        share = np.clip(self.lag_s / np.maximum(np.asarray(duration_s, dtype=np.float64), 1e-3), 0.0, 1.0)
        seen = (1.0 - share) * d + share * prev
        # one scale error per traverse, then an error growing with the distance travelled
        _, traverse = np.unique(groups, return_inverse=True)
        scale = 1.0 + self.scale_sigma * rng.standard_normal(traverse.max() + 1 if n else 0)
        sigma = self.drift * np.abs(seen) + self.resolution_m
        measured = seen * scale[traverse] + sigma * rng.standard_normal(n)
        p_drop = np.full(n, self.dropout) if low_texture is None else np.where(low_texture, self.dropout_low_texture,
                                                                               self.dropout)
        dropped = rng.random(n) < p_drop
        return measured, dropped


@dataclass(frozen=True)
class LabelNoise:
    """A noise model and its strength: `KIND:RATE`, parsed by `parse`."""

    kind: str
    rate: float

    @classmethod
    def parse(cls, text: str) -> "LabelNoise":
        kind, sep, value = text.partition(":")
        kind = kind.strip().lower()
        if kind not in KINDS or not sep:
            raise InputError(f"label noise {text!r}: write KIND:RATE with KIND one of {', '.join(KINDS)} "
                             f"(e.g. adjacent:0.2, vo:1)")
        try:
            rate = float(value)
        except ValueError:
            raise InputError(f"label noise {text!r}: {value!r} is not a number") from None
        if not np.isfinite(rate) or rate < 0 or (kind != "vo" and rate > 1):
            raise InputError(f"label noise {text!r}: the rate must be in [0, 1] (vo: a scale >= 0)")
        return cls(kind, rate)

    def __str__(self) -> str:
        return f"{self.kind}:{self.rate:g}"

    def apply(self, y: np.ndarray, rng: np.random.Generator, d_actual: np.ndarray | None = None,
              d_commanded: np.ndarray | None = None, groups: np.ndarray | None = None,
              duration_s: np.ndarray | None = None, vo: VoModel = VoModel()) -> np.ndarray:
        """Noisy labels of rows `y` (int64; `y` itself is not changed). For `vo`, the rows of one group
        (traverse) are in time order and every row of the traverse is given (the lag reaches the window before)."""
        return self.apply_with_probabilities(y, rng, d_actual, d_commanded, groups, duration_s, vo)[0]

    def apply_with_probabilities(self, y: np.ndarray, rng: np.random.Generator, d_actual: np.ndarray | None = None,
                                 d_commanded: np.ndarray | None = None, groups: np.ndarray | None = None,
                                 duration_s: np.ndarray | None = None,
                                 vo: VoModel = VoModel()) -> tuple[np.ndarray, np.ndarray | None]:
        """(noisy labels, their class probabilities (n, 3) or None): `apply`, and for `vo` what the VO reading
        says of each label (`vo_class_probabilities` under the same scaled model: a rover knows its VO's
        error model). Symmetric and adjacent flips come with no reading, so with no probabilities."""
        y = np.asarray(y, dtype=np.int64)
        if self.kind == "symmetric":
            flip = rng.random(y.size) < self.rate
            step = rng.integers(1, N_CLASSES, y.size)  # 1 or 2 classes on: one of the two others, uniformly
            return np.where(flip, (y + step) % N_CLASSES, y), None
        if self.kind == "adjacent":
            flip = rng.random(y.size) < self.rate
            up = rng.random(y.size) < 0.5
            to = np.where(y == 0, 1, np.where(y == N_CLASSES - 1, N_CLASSES - 2, np.where(up, y + 1, y - 1)))
            return np.where(flip, to, y), None
        if d_actual is None or d_commanded is None:
            raise InputError("label noise vo needs each window's travelled and commanded distance "
                             "(total_dist_actual, total_dist_cmd)")
        n = y.size
        groups = np.zeros(n, dtype=np.int64) if groups is None else groups
        duration_s = np.full(n, 2.0) if duration_s is None else duration_s
        model = vo.scaled(self.rate)
        measured, dropped = model.measure(d_actual, groups, duration_s, rng)
        return vo_calibration_labels(measured, dropped, d_commanded, model)

    def record(self, y: np.ndarray, noisy: np.ndarray, vo: VoModel = VoModel()) -> dict:
        """JSON-ready: which model, how many of the labels `y` it changed, per true class."""
        changed = np.asarray(noisy) != np.asarray(y)
        out = {"kind": self.kind, "rate": self.rate, "corrupted": int(changed.sum()), "of": int(changed.size),
               "corrupted_per_class": np.bincount(np.asarray(y)[changed], minlength=N_CLASSES).tolist()}
        if self.kind == "vo":
            out["vo_model"] = asdict(vo.scaled(self.rate))
        return out


def vo_class_probabilities(measured: np.ndarray, d_commanded: np.ndarray, dropped: np.ndarray,
                           vo: VoModel = VoModel()) -> np.ndarray:
    """(n, 3) probability of each slip class given VO's measured distance of each window and its error
    (`VoModel.error_sigma`, Gaussian); a dropped window (VO did not converge) has no measurement, so its row
    is all zero. The class regions are those of `labels.slip_class`: with s = 1 − d / d_cmd, low is
    |s| <= 0.3, i.e. d in [0.7, 1.3]·d_cmd, and |s| <= 0.6 is d in [0.4, 1.6]·d_cmd. A window that was
    hardly commanded to move has slip 0 by definition (`slip_ratio`): low for sure. Where the error is 0
    the row is the hard class."""
    m = np.asarray(measured, dtype=np.float64)
    dc = np.asarray(d_commanded, dtype=np.float64)
    sigma = vo.error_sigma(m)
    low_t, moderate_t = CLASS_THRESHOLDS
    sure = sigma <= 0
    z_sigma = np.where(sure, 1.0, sigma)

    def below(bound: np.ndarray) -> np.ndarray:  # P(true distance <= bound)
        return ndtr((bound - m) / z_sigma)

    p_low = below((1 + low_t) * dc) - below((1 - low_t) * dc)
    p_within = below((1 + moderate_t) * dc) - below((1 - moderate_t) * dc)  # P(|s| <= 0.6)
    probs = np.stack([p_low, p_within - p_low, 1.0 - p_within], axis=1).clip(0.0, 1.0)
    hard = np.eye(N_CLASSES)[slip_class(slip_ratio(m, dc))]
    probs = np.where((sure | (dc < MIN_COMMANDED_DISTANCE_M))[:, None], hard, probs)
    probs /= probs.sum(axis=1, keepdims=True)
    return np.where(np.asarray(dropped, dtype=bool)[:, None], 0.0, probs)


VO_LABEL_COLUMNS = ("slip_percentage", "slip_class", "total_dist_vo", "slip_percentage_vo", "slip_class_vo",
                    "vo_dropout")


def vo_labels(d_actual: np.ndarray, d_commanded: np.ndarray, duration_s: np.ndarray, rng: np.random.Generator,
              low_texture: bool, vo: VoModel = VoModel()) -> dict[str, np.ndarray]:
    """One traverse's windows (in time order) measured by the VO model: the true slip and class beside the
    VO distance, slip and class (a dropout keeps the wheel odometry), columns `VO_LABEL_COLUMNS`."""
    n = len(d_actual)
    measured, dropped = vo.measure(d_actual, np.zeros(n, dtype=np.int64), duration_s, rng,
                                   low_texture=np.full(n, low_texture))
    measured = believed_distance(measured, dropped, d_commanded)
    true_slip, vo_slip = slip_ratio(d_actual, d_commanded), slip_ratio(measured, d_commanded)
    return dict(zip(VO_LABEL_COLUMNS, (100.0 * true_slip, slip_class(true_slip), measured, 100.0 * vo_slip,
                                       slip_class(vo_slip), dropped.astype(np.int64))))


VO_READING_COLUMNS = ("total_dist_vo", "vo_dropout")  # what a rover's VO gives of each window (in VO_LABEL_COLUMNS too)


def read_vo_readings(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """(VO's distance, whether VO dropped out) of each window in a VO label file: one row per window of its
    traverse's CSV, in the same order, with the columns `VO_READING_COLUMNS` (others, such as the true slip the
    simulator writes beside them, are not read). A dropout's distance may be empty or NaN: it is not used."""
    path = Path(path)
    try:
        rows = list(csv.reader(path.read_text(encoding="utf-8-sig").splitlines()))
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the VO label file ({e})") from None
    if not rows:
        raise CsvFormatError(path, 1, "empty file (no header)")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in VO_READING_COLUMNS if c not in header]
    if missing:
        raise CsvFormatError(path, 1, f"the VO label file needs the columns {list(VO_READING_COLUMNS)}; missing {missing}")
    at = [header.index(c) for c in VO_READING_COLUMNS]
    distance, dropped = [], []
    for lineno, fields in enumerate(rows[1:], start=2):
        if not fields or all(not f.strip() for f in fields):
            continue
        if len(fields) != len(header):
            raise CsvFormatError(path, lineno, f"expected {len(header)} fields, found {len(fields)}")
        raw_d, raw_drop = (fields[i].strip() for i in at)
        if raw_drop not in ("0", "1"):
            raise CsvFormatError(path, lineno, f"column vo_dropout: {raw_drop!r} is not 0 or 1")
        try:
            d = float(raw_d) if raw_d else float("nan")
        except ValueError:
            raise CsvFormatError(path, lineno, f"column total_dist_vo: {raw_d!r} is not a number") from None
        if raw_drop == "0" and not np.isfinite(d):
            raise CsvFormatError(path, lineno, "column total_dist_vo: no finite distance, and VO did not drop out")
        distance.append(d)
        dropped.append(raw_drop == "1")
    return np.array(distance, dtype=np.float64), np.array(dropped, dtype=bool)


def vo_calibration_labels(measured: np.ndarray, dropped: np.ndarray, d_commanded: np.ndarray,
                          vo: VoModel = VoModel()) -> tuple[np.ndarray, np.ndarray]:
    """(labels, class probabilities) of windows read by VO: the class of VO's slip, or low where VO dropped out
    (the wheel odometry stands), and what the reading says of each class (`vo_class_probabilities`)."""
    seen = believed_distance(measured, dropped, d_commanded)  # a dropout's own distance is never used
    return slip_class(slip_ratio(seen, d_commanded)), vo_class_probabilities(seen, d_commanded, dropped, vo)


def believed_distance(measured: np.ndarray, dropped: np.ndarray, d_commanded: np.ndarray) -> np.ndarray:
    """The distance a rover takes for each window: VO's, or where VO did not converge the commanded one (no VO
    update: the wheel odometry stands, so the window shows no slip)."""
    return np.where(dropped, np.asarray(d_commanded, dtype=np.float64), measured)
