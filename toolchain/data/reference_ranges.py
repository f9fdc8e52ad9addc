"""How far a dataset's features are from a reference's, and what usually causes it.

Each feature's range is summarised by its 5th and 95th percentiles and the 95th percentile of its
magnitude (`feature_ranges`). A feature is *far outside* a reference when its magnitude is more than
FAR times larger, or FAR times smaller for the two features whose size is set by the rover's units
rather than by how calm the drive was (mean wheel speed and mean current: a quiet drive has small
accelerations, stds and angles, which is no mistake), or (between two datasets, `data compare`) when
the two central 90 % ranges do not overlap and lie further apart than either is wide. The warning names the likely causes of that
feature: a unit (a known factor between the two is named: g vs m/s^2, deg vs rad, rpm vs rad/s, milli),
gravity left in or taken out twice, a sign, the axis order.

`fleetlab data import` checks the imported windows against REFERENCE, the ranges of the two reference
datasets fleetlab ships or reads: the Fleet-To-Lab files (all roles; `tests/test_csv_rover.py`
recomputes them from the files) and the built-in simulator's scenario (seed 1, scale 0.2).
"""

from __future__ import annotations

import numpy as np

from .contracts import FEATURE_NAMES

FAR = 10.0  # a magnitude more than FAR times the reference's (or less than 1 / FAR of it) is far outside
SIZED_BY_UNITS = ("feat_w_vel_mean", "feat_curr_mean")  # also far outside when FAR times smaller

# feature -> (p5, p95, 95th percentile of |x|) of each reference dataset
REFERENCE: dict[str, dict[str, tuple[float, float, float]]] = {
    "Fleet-To-Lab": {
        "feat_w_vel_mean": (0.674, 3.020, 3.020), "feat_w_vel_std": (0.0112, 0.5473, 0.5473),
        "feat_curr_mean": (34.69, 79.55, 79.55), "feat_curr_std": (2.181, 32.41, 32.41),
        "feat_acc_x_mean": (-0.0627, 0.0679, 0.0876), "feat_acc_x_std": (0.1073, 1.275, 1.275),
        "feat_acc_y_mean": (-0.0687, 0.0800, 0.0917), "feat_acc_y_std": (0.0932, 1.114, 1.114),
        "feat_acc_z_mean": (-0.0867, 0.0785, 0.1385), "feat_acc_z_std": (0.1803, 4.688, 4.688),
        "feat_pitch_mean": (-0.4295, 0.3262, 0.4814), "feat_roll_mean": (-0.4737, 0.3449, 0.4922),
    },
    "the simulator": {
        "feat_w_vel_mean": (0.6928, 4.304, 4.304), "feat_w_vel_std": (0.0095, 0.0791, 0.0791),
        "feat_curr_mean": (0.0914, 0.9252, 0.9252), "feat_curr_std": (0.0111, 0.0352, 0.0352),
        "feat_acc_x_mean": (-0.1218, 0.1579, 0.1929), "feat_acc_x_std": (0.0607, 0.7384, 0.7384),
        "feat_acc_y_mean": (-0.1145, 0.1071, 0.1532), "feat_acc_y_std": (0.0504, 0.6045, 0.6045),
        "feat_acc_z_mean": (-0.2026, 0.2473, 0.3397), "feat_acc_z_std": (0.0950, 1.170, 1.170),
        "feat_pitch_mean": (-0.2922, 0.2646, 0.3105), "feat_roll_mean": (-0.3552, 0.3527, 0.4125),
    },
}

# factors between units a log is often written in by mistake, and what to say
_UNIT_FACTORS = ((9.80665, "g instead of m/s^2 (or the reverse)"), (180.0 / np.pi, "degrees instead of radians"),
                 (60.0 / (2 * np.pi), "rpm instead of rad/s"), (1000.0, "milli-units (mA, mm, mg) instead of units"),
                 (3.6, "km/h instead of m/s"))
_GRAVITY = (9.81, 1.62)
_CAUSES = {
    "w_vel": "the unit (wheels.velocity_unit: rad/s, rpm, deg/s, m/s, km/h; velocity_scale)",
    "curr": "the unit or scale (wheels.current_per_effort: mA, or an effort that is not a current)",
    "acc_mean": "gravity (imu.includes_gravity, imu.gravity_m_s2), the axis order of imu.acc_columns (x forward, "
                "y left, z up), a sign, or the unit (imu.acc_unit)",
    "acc_std": "the unit (imu.acc_unit, acc_scale) or the axis order of imu.acc_columns",
    "angle": "the unit (attitude.angle_unit: rad or deg), roll and pitch swapped, or a sign or frame that is not "
             "REP-103 (x forward, y left, z up)",
}


def _kind(feature: str) -> str:
    if "w_vel" in feature or "curr" in feature:
        return "w_vel" if "w_vel" in feature else "curr"
    if "acc" in feature:
        return "acc_mean" if feature.endswith("_mean") else "acc_std"
    return "angle"


def feature_ranges(x: np.ndarray) -> dict[str, tuple[float, float, float]]:
    """feature -> (p5, p95, 95th percentile of |x|) of windows x (n, 12)."""
    x = np.asarray(x, dtype=np.float64)
    if not len(x):
        return {}
    p5, p95 = np.percentile(x, 5, axis=0), np.percentile(x, 95, axis=0)
    mag = np.percentile(np.abs(x), 95, axis=0)
    return {n: (float(p5[i]), float(p95[i]), float(mag[i])) for i, n in enumerate(FEATURE_NAMES)}


def far_outside(feature: str, mine: tuple[float, float, float], ref: tuple[float, float, float],
                shift: bool = True) -> bool:
    """Magnitude more than FAR times larger (or smaller, SIZED_BY_UNITS), or (shift) central ranges apart by
    more than either's width."""
    lo, hi, mag = mine
    rlo, rhi, rmag = ref
    if mag > FAR * rmag or (feature in SIZED_BY_UNITS and mag * FAR < rmag):
        return True
    gap = max(rlo - hi, lo - rhi)
    return shift and gap > max(hi - lo, rhi - rlo, 1e-12)


def likely_causes(feature: str, mine: tuple[float, float, float], ref: tuple[float, float, float]) -> str:
    """The causes to check first for one feature, the one the figures point at named first."""
    lo, hi, mag = mine
    rlo, rhi, rmag = ref
    found = []
    if mag > 0 and rmag > 0:
        ratio = max(mag / rmag, rmag / mag)
        for factor, what in _UNIT_FACTORS:
            if abs(np.log(ratio / factor)) < np.log(1.3):
                found.append(f"{what}? (a factor of {ratio:.3g})")
    kind = _kind(feature)
    if kind == "acc_mean":
        mid, rmid = (lo + hi) / 2, (rlo + rhi) / 2
        if any(abs(abs(mid - rmid) - g) < 0.3 * g for g in _GRAVITY):
            found.append(f"gravity left in or taken out twice? (off by {mid - rmid:+.3g} m/s^2)")
    overlaps = lambda a, b: a[0] <= b[1] and b[0] <= a[1]  # noqa: E731
    if kind in ("acc_mean", "angle") and overlaps((-hi, -lo), (rlo, rhi)) and not overlaps((lo, hi), (rlo, rhi)):
        found.append("a sign? (the negated range fits)")
    return "; ".join(found + [f"check {_CAUSES[kind]}"])


def import_range_warnings(x: np.ndarray) -> list[str]:
    """One line per feature of imported windows x (n, 12) whose magnitude is far from every reference's.

    Why every one: the references differ among themselves (currents: the simulator's are below 1 A, the
    Fleet-To-Lab rover's 35-80 A), so a rover in range of one of them is no sign of a unit mistake; `data
    compare` holds a dataset against the one reference it is compared with."""
    mine = feature_ranges(x)
    out = []
    for f, m in mine.items():
        off = [(name, ref[f]) for name, ref in REFERENCE.items() if far_outside(f, m, ref[f], shift=False)]
        if len(off) < len(REFERENCE):
            continue
        vs = ", ".join(f"{m[2] / r[2]:.3g}x {name}'s ({r[2]:.3g})" for name, r in off)
        out.append(f"{f}: 95 % of |x| below {m[2]:.3g}, {vs}: {likely_causes(f, m, off[0][1])}; if the values are "
                   "right, a model trained on that reference will not transfer to this rover as it is")
    return out


def compare_range_warnings(mine: dict[str, tuple[float, float, float]],
                           ref: dict[str, tuple[float, float, float]], label: str = "A", ref_label: str = "B") -> list[str]:
    """One line per feature whose range in `mine` is far outside its range in `ref`."""
    out = []
    for f in FEATURE_NAMES:
        if f in mine and f in ref and far_outside(f, mine[f], ref[f]):
            m, r = mine[f], ref[f]
            out.append(f"{f}: {label} {m[0]:.3g}..{m[1]:.3g} (|x| < {m[2]:.3g}) vs {ref_label} {r[0]:.3g}..{r[1]:.3g} "
                       f"(|x| < {r[2]:.3g}): {likely_causes(f, m, r)}")
    return out
