"""`fleetlab simulate --csv-logs DIR`: each traverse as time-series CSV logs of a rover without an attitude output.

The layout of a rover that logs one CSV per sensor and drive, and no orientation, pose filter or slip:
one folder per rover profile (`DIR/<rover>_<earth|moon>/`), in it per traverse

  imu_<traverse>.csv     t_ms, ax, ay, az (specific force, gravity in, m/s^2), gx, gy, gz (rad/s),
                         at twice the sample rate
  wheels_<traverse>.csv  t_ms, one velocity column per wheel (rad/s, left then right: that side's measured
                         speed), one current column per wheel (A), at the sample rate
  pose_<traverse>.csv    t_ms, x, y, z (m): the true track, one sample longer than the sensors

and beside the folders one rover profile per folder, `DIR/<rover>_<earth|moon>.rover.toml`, with
`[attitude] source = "imu"`. Every traverse's clock starts at 0, so the drives of one folder overlap in
time: the import pairs their files by the common suffix (docs/your_rover.md).

The IMU is a strapdown IMU that turns with the rover. Its attitude is the simulator's true attitude (held
at the physics rate, here joined linearly between physics steps) plus a constant mounting offset: the
mean difference between the simulator's roll/pitch channels and the true attitude, so that the attitude
the import estimates and the simulator's own roll and pitch features agree up to the estimator's error.
  accelerometer  the simulator's linear acceleration (vibration, noise and bias included) + gravity
                 rotated into the body frame at that attitude
  gyroscope      the body rates of that attitude and of the heading (the direction of the true track),
                 + white noise (GYRO_NOISE_RAD_S per sample) + a constant bias per traverse (GYRO_BIAS_RAD_S)
Wheels and currents are the sample-rate channels the bags carry, on the same sample times, so the
windows, distances and labels of an import equal the simulator's own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..contracts import CH
from ..log_import import gravity_body
from .bag import _heading, place, wheel_joints
from .engine import PHYSICS_HZ, Trace
from .rovers import ROVERS

IMU_RATE_FACTOR = 2  # the IMU logs at twice the sample rate (100 Hz at the default 50 Hz)
GYRO_NOISE_RAD_S = 0.003  # white noise per gyro sample (about 0.17 deg/s)
GYRO_BIAS_RAD_S = 0.003  # std of the constant gyro bias drawn per traverse and axis
TIME_COLUMN = "t_ms"


def folder_name(rover: str, gravity: float) -> str:
    return f"{rover}_{place(gravity)}"


def profile_name(rover: str, gravity: float) -> str:
    return f"{folder_name(rover, gravity)}.rover.toml"


def _names(xs) -> str:
    return "[" + ", ".join(f'"{x}"' for x in xs) + "]"


def profile_toml(rover: str, gravity: float) -> str:
    """The rover profile of the simulator's CSV logs for one rover and gravity."""
    left, right = wheel_joints(rover)
    joints = [j.replace("_joint", "") for j in left + right]
    return f"""# Rover profile: fleetlab's simulated {rover} rover ({place(gravity)}, g = {gravity} m/s^2), as
# `fleetlab simulate --csv-logs` logs it: one CSV per sensor and drive, no attitude. Reference: docs/your_rover.md.

[rover]
name = "{rover}"
wheel_radius_m = {ROVERS[rover].wheel_radius_m}

[wheels]
file = "wheels_*.csv"
time_column = "{TIME_COLUMN}"
time_unit = "ms"
velocity_columns = {_names(f"{j}_vel" for j in joints)}
effort_columns = {_names(f"{j}_current" for j in joints)}
velocity_unit = "rad/s"

[imu]
file = "imu_*.csv"
time_column = "{TIME_COLUMN}"
time_unit = "ms"
acc_columns = ["ax", "ay", "az"]
gyro_columns = ["gx", "gy", "gz"]
gyro_unit = "rad/s"
includes_gravity = true
gravity_m_s2 = {gravity}

[attitude]
source = "imu"                          # no orientation in the logs: roll and pitch from gyro + accelerometer

[ground_truth]
file = "pose_*.csv"
time_column = "{TIME_COLUMN}"
time_unit = "ms"
position_columns = ["x", "y", "z"]
"""


def imu_attitude(trace: Trace) -> np.ndarray:
    """(n, 2) roll, pitch (rad) of the simulated IMU at the sample times (see the module docstring)."""
    n = len(trace.samples)
    k = max(1, int(round(trace.rate_hz / PHYSICS_HZ)))
    out = np.empty((n, 2))
    idx = np.arange(n, dtype=np.float64)
    centres = np.arange(0, n, k, dtype=np.float64) + (k - 1) / 2.0  # each physics step holds k samples
    for col, key, ch in ((0, "roll", CH["roll"]), (1, "pitch", CH["pitch"])):
        true = trace.truth[key]
        offset = float(np.mean(trace.samples[:, ch] - true))
        out[:, col] = np.interp(idx, centres, true[::k]) + offset
    return out


def body_rates(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray, dt: float) -> np.ndarray:
    """(n, 3) body angular velocity (rad/s, REP-103 body frame) of Z-Y-X Euler angles sampled every dt."""
    d_roll, d_pitch, d_yaw = (np.gradient(a, dt) for a in (roll, pitch, np.unwrap(yaw)))
    sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
    return np.column_stack([d_roll - sp * d_yaw, cr * d_pitch + sr * cp * d_yaw, -sr * d_pitch + cr * cp * d_yaw])


def imu_signals(trace: Trace, gravity: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps (ms), specific force (m, 3), gyro (m, 3) at IMU_RATE_FACTOR x the sample rate, and the IMU's
    true roll and pitch (m, 2) at those stamps."""
    n, dt = len(trace.samples), 1.0 / trace.rate_hz
    att = imu_attitude(trace)
    yaw = _heading(trace)
    lin = trace.samples[:, [CH["acc_x"], CH["acc_y"], CH["acc_z"]]]
    rates = body_rates(att[:, 0], att[:, 1], yaw, dt)
    # IMU stamps: every sample time and IMU_RATE_FACTOR - 1 between two (the last sample time ends the log)
    m = (n - 1) * IMU_RATE_FACTOR + 1
    x = np.arange(m) / IMU_RATE_FACTOR
    up = lambda a: np.column_stack([np.interp(x, np.arange(n), a[:, j]) for j in range(a.shape[1])])  # noqa: E731
    att_m = up(att)
    force = up(lin) + gravity_body(att_m[:, 0], att_m[:, 1], gravity)
    rng = np.random.default_rng(seed)
    gyro = up(rates) + GYRO_BIAS_RAD_S * rng.standard_normal(3) + GYRO_NOISE_RAD_S * rng.standard_normal((m, 3))
    t_ms = x * 1000.0 / trace.rate_hz
    return t_ms, force, gyro, att_m


def _write(path: Path, header: list[str], cols: list[np.ndarray]) -> None:
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.17g")


def write_traverse_csv_logs(root: Path, name: str, trace: Trace, rover: str, gravity: float) -> Path:
    """Write one traverse's imu_/wheels_/pose_<name>.csv into root/<rover>_<place>/; returns the profile path."""
    folder = Path(root) / folder_name(rover, gravity)
    folder.mkdir(parents=True, exist_ok=True)
    n = len(trace.samples)
    t_ms, force, gyro, _ = imu_signals(trace, gravity, trace.meta["seed"])
    _write(folder / f"imu_{name}.csv", [TIME_COLUMN, "ax", "ay", "az", "gx", "gy", "gz"], [t_ms, force, gyro])
    left, right = wheel_joints(rover)
    joints = [j.replace("_joint", "") for j in left + right]
    vel = [trace.truth["wheel_left"]] * len(left) + [trace.truth["wheel_right"]] * len(right)
    cur = [trace.samples[:, CH["motor_current"]]] * len(joints)
    _write(folder / f"wheels_{name}.csv", [TIME_COLUMN, *(f"{j}_vel" for j in joints), *(f"{j}_current" for j in joints)],
           [np.arange(n) * 1000.0 / trace.rate_hz, *vel, *cur])
    yaw = _heading(trace)
    pos = np.zeros((n + 1, 3))
    pos[1:, 0] = np.cumsum(trace.d_actual_step * np.cos(yaw))
    pos[1:, 1] = np.cumsum(trace.d_actual_step * np.sin(yaw))
    _write(folder / f"pose_{name}.csv", [TIME_COLUMN, "x", "y", "z"], [np.arange(n + 1) * 1000.0 / trace.rate_hz, pos])
    profile = Path(root) / profile_name(rover, gravity)
    profile.write_text(profile_toml(rover, gravity))
    return profile
