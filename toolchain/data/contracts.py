"""The data contracts shared by every part of fleetlab (see docs/architecture.md).

Changing anything here changes the feature vector that the exported C estimator
expects, so the firmware, the exporter and the DBC must follow.
"""

from __future__ import annotations

# Raw telemetry channels, one value per sample, in physical units.
# wheel_speed and motor_current are means of absolute values over all wheels.
RAW_CHANNELS: tuple[str, ...] = (
    "wheel_speed",  # rad/s
    "motor_current",  # A
    "acc_x",  # m/s^2, body frame, linear acceleration: gravity removed (as in the Fleet-To-Lab files)
    "acc_y",
    "acc_z",
    "roll",  # rad
    "pitch",  # rad
)
N_CHANNELS = len(RAW_CHANNELS)
CH = {name: i for i, name in enumerate(RAW_CHANNELS)}

# Integer LSB of each raw channel as carried on CAN (dbc/slipest.dbc).
# The C feature extractor works in these units; value_physical = raw * LSB.
RAW_LSB: dict[str, float] = {
    "wheel_speed": 0.001,
    "motor_current": 0.01,
    "acc_x": 0.001,
    "acc_y": 0.001,
    "acc_z": 0.001,
    "roll": 0.0001,
    "pitch": 0.0001,
}

# The 12 features, in the order of the Fleet-To-Lab CSV columns.
FEATURE_NAMES: tuple[str, ...] = (
    "feat_w_vel_mean",
    "feat_w_vel_std",
    "feat_curr_mean",
    "feat_curr_std",
    "feat_acc_x_mean",
    "feat_acc_x_std",
    "feat_acc_y_mean",
    "feat_acc_y_std",
    "feat_acc_z_mean",
    "feat_acc_z_std",
    "feat_pitch_mean",
    "feat_roll_mean",
)
N_FEATURES = len(FEATURE_NAMES)

# (channel, statistic) behind each feature, in feature order.
FEATURE_SOURCES: tuple[tuple[str, str], ...] = (
    ("wheel_speed", "mean"),
    ("wheel_speed", "std"),
    ("motor_current", "mean"),
    ("motor_current", "std"),
    ("acc_x", "mean"),
    ("acc_x", "std"),
    ("acc_y", "mean"),
    ("acc_y", "std"),
    ("acc_z", "mean"),
    ("acc_z", "std"),
    ("pitch", "mean"),
    ("roll", "mean"),
)

# Every column of a Fleet-To-Lab CSV file, in order.
LABEL_COLUMNS: tuple[str, ...] = (
    "total_dist_actual",
    "total_dist_cmd",
    "slip_percentage",
    "slip_class",
    "n_samples",
    "win_duration_s",
)
CSV_COLUMNS: tuple[str, ...] = FEATURE_NAMES + LABEL_COLUMNS

# Windowing.
WINDOW_S = 2.0
STRIDE_S = 2.0
MIN_SAMPLES_PER_WINDOW = 5
DEFAULT_RATE_HZ = 50.0

# Labels.
SLIP_CLIP = 1.0
MIN_COMMANDED_DISTANCE_M = 0.05
CLASS_THRESHOLDS = (0.3, 0.6)  # |slip| <= 0.3 -> 0, <= 0.6 -> 1, else 2
CLASS_NAMES = ("low", "moderate", "high")
N_CLASSES = len(CLASS_NAMES)
