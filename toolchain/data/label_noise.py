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

Every draw comes from the generator it is given, so a corruption is reproducible by seed; nothing
here touches the test rows of an evaluation (the caller corrupts D_Cal only).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .contracts import N_CLASSES
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
        y = np.asarray(y, dtype=np.int64)
        if self.kind == "symmetric":
            flip = rng.random(y.size) < self.rate
            step = rng.integers(1, N_CLASSES, y.size)  # 1 or 2 classes on: one of the two others, uniformly
            return np.where(flip, (y + step) % N_CLASSES, y)
        if self.kind == "adjacent":
            flip = rng.random(y.size) < self.rate
            up = rng.random(y.size) < 0.5
            to = np.where(y == 0, 1, np.where(y == N_CLASSES - 1, N_CLASSES - 2, np.where(up, y + 1, y - 1)))
            return np.where(flip, to, y)
        if d_actual is None or d_commanded is None:
            raise InputError("label noise vo needs each window's travelled and commanded distance "
                             "(total_dist_actual, total_dist_cmd)")
        n = y.size
        groups = np.zeros(n, dtype=np.int64) if groups is None else groups
        duration_s = np.full(n, 2.0) if duration_s is None else duration_s
        measured, dropped = vo.scaled(self.rate).measure(d_actual, groups, duration_s, rng)
        measured = np.where(dropped, d_commanded, measured)  # no VO update: the wheel odometry stands
        return slip_class(slip_ratio(measured, d_commanded))

    def record(self, y: np.ndarray, noisy: np.ndarray, vo: VoModel = VoModel()) -> dict:
        """JSON-ready: which model, how many of the labels `y` it changed, per true class."""
        changed = np.asarray(noisy) != np.asarray(y)
        out = {"kind": self.kind, "rate": self.rate, "corrupted": int(changed.sum()), "of": int(changed.size),
               "corrupted_per_class": np.bincount(np.asarray(y)[changed], minlength=N_CLASSES).tolist()}
        if self.kind == "vo":
            out["vo_model"] = asdict(vo.scaled(self.rate))
        return out


VO_LABEL_COLUMNS = ("slip_percentage", "slip_class", "total_dist_vo", "slip_percentage_vo", "slip_class_vo",
                    "vo_dropout")


def vo_labels(d_actual: np.ndarray, d_commanded: np.ndarray, duration_s: np.ndarray, rng: np.random.Generator,
              low_texture: bool, vo: VoModel = VoModel()) -> dict[str, np.ndarray]:
    """One traverse's windows (in time order) measured by the VO model: the true slip and class beside the
    VO distance, slip and class (a dropout keeps the wheel odometry), columns `VO_LABEL_COLUMNS`."""
    n = len(d_actual)
    measured, dropped = vo.measure(d_actual, np.zeros(n, dtype=np.int64), duration_s, rng,
                                   low_texture=np.full(n, low_texture))
    measured = np.where(dropped, d_commanded, measured)
    true_slip, vo_slip = slip_ratio(d_actual, d_commanded), slip_ratio(measured, d_commanded)
    return dict(zip(VO_LABEL_COLUMNS, (100.0 * true_slip, slip_class(true_slip), measured, 100.0 * vo_slip,
                                       slip_class(vo_slip), dropped.astype(np.int64))))
