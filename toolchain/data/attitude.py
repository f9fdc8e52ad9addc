"""Roll and pitch from a strapdown IMU (gyroscope + accelerometer): `[attitude] source = "imu"`.

The filter is Mahony's nonlinear complementary filter on the rotation group (Mahony, Hamel, Pflimlin,
IEEE TAC 2008, the "explicit complementary filter" with gyro-bias estimation), run on the quaternion:

    e      = a/|a| x v            v: gravity's direction in the body frame predicted by the estimate
    b     <- b - KI e dt          gyro bias (its roll and pitch components are observable from gravity)
    q     <- q (x) exp((w - b + KP e) dt / 2)

The gyroscope carries the attitude through fast motion; the accelerometer pulls it slowly (time
constant 1 / KP) towards gravity's direction. Why this filter: it works on the quaternion, so a turn on
a slope (yaw rate mixing into roll and pitch) costs nothing, unlike a complementary filter on Euler
angles; it estimates the gyro bias, which a plain complementary filter turns into a constant attitude
error of bias / KP; it has two gains and no noise model to tune (a Kalman filter would need the
vibration spectrum of each terrain).

A rover's accelerometer also feels its own linear acceleration (speed changes, the centripetal
acceleration of a turn) and chassis vibration, and on the Moon gravity is only 1.62 m/s^2, so the
accelerometer's share is small (KP = 0.05 /s: a 20 s time constant), the accelerometer is low-passed
first (ACC_CUTOFF_HZ, zero phase) and not used while the body turns faster than DYNAMIC_RATE_RAD_S
(the centripetal acceleration would tilt the estimate). The gyro bias starts from the mean gyro reading
where the rover stands still (`still_bias`: no vibration, no rotation), so that the slow integral term
has little to learn.

A sample is *high-dynamic* when the body turns faster than DYNAMIC_RATE_RAD_S or the low-passed
acceleration norm differs from g by more than DYNAMIC_ACC_SHARE of g; a window in which more than
UNTRUSTED_SHARE of the IMU samples are high-dynamic is counted `attitude_untrusted_windows` by the
import (the estimate there leans on the gyro alone or on an accelerometer disturbed by motion; on the
simulator's lunar traverses such windows have about 1.7 times the error of the others).

The import has the whole log, so the filter runs backward over the run (to arrive at its start with a
converged attitude and gyro bias), then forward, then backward again from where the forward pass ended,
and the last two are averaged: neither carries a start-up transient, and the lag each has in its own
direction of time mostly cancels (as `scipy.signal.filtfilt` does for a linear filter). Each run of IMU
messages without a pause longer than `max_gap_s` is filtered on its own.

Accuracy on the simulator's traverses: `fleetlab bench attitude` (figures in docs/your_rover.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

NS = 1_000_000_000
KP = 0.05  # 1/s: accelerometer gain (time constant 20 s)
KI = 0.0002  # 1/s^2: gyro-bias integral gain
ACC_CUTOFF_HZ = 1.0  # low-pass of the accelerometer before the filter and the dynamics test
DYNAMIC_ACC_SHARE = 0.2  # high dynamics: ||a| - g| above this share of g (low-passed a) ...
DYNAMIC_RATE_RAD_S = 0.35  # ... or |gyro| above this (20 deg/s)
UNTRUSTED_SHARE = 0.25  # a window with more high-dynamic IMU samples than this is counted untrusted
INIT_S = 1.0  # the first backward pass starts from the accelerometer tilt averaged over this long
STILL_S = 0.5  # a still period: this long ...
STILL_ACC_STD = 0.05  # ... with the accelerometer norm varying less than this (m/s^2, std) ...
STILL_GYRO_STD = 0.01  # ... and every gyro axis less than this (rad/s, std) ...
STILL_GYRO_MAX = 0.035  # ... and the gyro reading less than this (2 deg/s: a steady turn is not still)


@dataclass(frozen=True)
class AttitudeEstimate:
    roll: np.ndarray  # (n,) rad
    pitch: np.ndarray  # (n,) rad
    dynamic: np.ndarray  # (n,) bool: high dynamics at this sample (accelerometer not used)


def tilt(acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad, REP-103 Z-Y-X) of the gravity direction an accelerometer at rest reads."""
    ax, ay, az = acc[:, 0], acc[:, 1], acc[:, 2]
    return np.arctan2(ay, az), np.arctan2(-ax, np.hypot(ay, az))


def _quat_from_tilt(roll: float, pitch: float) -> tuple[float, float, float, float]:
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return cr * cp, sr * cp, cr * sp, -sr * sp  # w, x, y, z of Rz(0) Ry(pitch) Rx(roll)


def _mahony(dt: np.ndarray, acc: np.ndarray, gyro: np.ndarray, use_acc: np.ndarray,
            q0: tuple[float, float, float, float], kp: float, ki: float,
            bias0: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple[np.ndarray, tuple, tuple]:
    """(n, 2) roll, pitch of the quaternion filter over one run of samples (dt[i]: time since sample i - 1),
    and its last quaternion and gyro bias."""
    qw, qx, qy, qz = q0
    bx, by, bz = bias0
    out = np.empty((len(dt), 2))
    ax_, ay_, az_ = acc[:, 0].tolist(), acc[:, 1].tolist(), acc[:, 2].tolist()
    gx_, gy_, gz_ = gyro[:, 0].tolist(), gyro[:, 1].tolist(), gyro[:, 2].tolist()
    dts, use = dt.tolist(), use_acc.tolist()
    sqrt, atan2, asin = math.sqrt, math.atan2, math.asin
    for i in range(len(dts)):
        h = dts[i]
        wx, wy, wz = gx_[i] - bx, gy_[i] - by, gz_[i] - bz
        if use[i]:
            ax, ay, az = ax_[i], ay_[i], az_[i]
            norm = sqrt(ax * ax + ay * ay + az * az)
            if norm > 0.0:
                ax, ay, az = ax / norm, ay / norm, az / norm
                # gravity's direction in the body frame: third row of the body-to-world rotation
                vx = 2.0 * (qx * qz - qw * qy)
                vy = 2.0 * (qw * qx + qy * qz)
                vz = qw * qw - qx * qx - qy * qy + qz * qz
                ex, ey, ez = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
                bx -= ki * ex * h
                by -= ki * ey * h
                bz -= ki * ez * h
                wx, wy, wz = wx + kp * ex, wy + kp * ey, wz + kp * ez
        # q <- q (x) (1, w h / 2), then normalised
        hx, hy, hz = 0.5 * h * wx, 0.5 * h * wy, 0.5 * h * wz
        qw, qx, qy, qz = (qw - qx * hx - qy * hy - qz * hz, qx + qw * hx + qy * hz - qz * hy,
                          qy + qw * hy - qx * hz + qz * hx, qz + qw * hz + qx * hy - qy * hx)
        norm = 1.0 / sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw * norm, qx * norm, qy * norm, qz * norm
        out[i, 0] = atan2(2.0 * (qw * qx + qy * qz), 1.0 - 2.0 * (qx * qx + qy * qy))
        out[i, 1] = asin(max(-1.0, min(1.0, 2.0 * (qw * qy - qz * qx))))
    return out, (qw, qx, qy, qz), (bx, by, bz)


def still_bias(gyro: np.ndarray, acc: np.ndarray, rate_hz: float) -> np.ndarray:
    """Gyro bias (3,) as the mean gyro reading while the rover stands still, else zeros.

    Still: over STILL_S around a sample the accelerometer norm and every gyro axis vary by less than
    STILL_ACC_STD and STILL_GYRO_STD (standard deviations) and the gyro reads less than STILL_GYRO_MAX:
    a rover at rest feels no vibration and no rotation, and its gyro then reads its bias (plus noise)."""
    w = max(3, int(round(STILL_S * rate_hz)))
    if len(gyro) < w:
        return np.zeros(3)
    from numpy.lib.stride_tricks import sliding_window_view

    acc_std = sliding_window_view(np.linalg.norm(acc, axis=1), w).std(axis=1)
    windows = sliding_window_view(gyro, w, axis=0)
    gyro_std = windows.std(axis=2).max(axis=1)
    gyro_max = np.linalg.norm(windows.mean(axis=2), axis=1)
    still = np.flatnonzero((acc_std < STILL_ACC_STD) & (gyro_std < STILL_GYRO_STD) & (gyro_max < STILL_GYRO_MAX))
    if len(still) * 2 < w:
        return np.zeros(3)
    rows = np.unique((still[:, None] + np.arange(w)).ravel())
    return gyro[rows].mean(axis=0)


def _lowpass(acc: np.ndarray, rate_hz: float) -> np.ndarray:
    if len(acc) < 16 or rate_hz <= 4 * ACC_CUTOFF_HZ:
        return acc
    sos = butter(2, ACC_CUTOFF_HZ, fs=rate_hz, output="sos")
    return sosfiltfilt(sos, acc, axis=0, padlen=min(len(acc) - 1, int(3 * rate_hz / ACC_CUTOFF_HZ)))


def _run(t_ns: np.ndarray, acc: np.ndarray, gyro: np.ndarray, gravity: float, kp: float, ki: float,
         two_pass: bool) -> tuple[np.ndarray, np.ndarray]:
    """Roll/pitch (n, 2) and the high-dynamics flags (n,) of one gap-free run."""
    n = len(t_ns)
    dt = np.diff(t_ns).astype(np.float64) / NS
    rate = 1.0 / float(np.median(dt)) if n > 1 else 1.0
    smooth = _lowpass(acc, rate)
    turning = np.linalg.norm(gyro, axis=1) > DYNAMIC_RATE_RAD_S
    dynamic = turning | (np.abs(np.linalg.norm(smooth, axis=1) - gravity) > DYNAMIC_ACC_SHARE * gravity)
    use = ~turning
    first = max(1, min(n, int(round(INIT_S * rate))))

    def start(rows: slice) -> tuple[float, float, float, float]:
        r, p = tilt(smooth[rows].mean(axis=0, keepdims=True))
        return _quat_from_tilt(float(r[0]), float(p[0]))

    bias = tuple(still_bias(gyro, acc, rate))
    fdt, bdt = np.concatenate([[0.0], dt]), np.concatenate([[0.0], dt[::-1]])

    def backward(q0, b0):  # the same filter on the reversed samples with the rotation reversed
        out, q, b = _mahony(bdt, smooth[::-1], -gyro[::-1], use[::-1], q0, kp, ki, tuple(-x for x in b0))
        return out[::-1], q, tuple(-x for x in b)

    if not two_pass or n < 2:
        return _mahony(fdt, smooth, gyro, use, start(slice(0, first)), kp, ki, bias)[0], dynamic
    # A first backward pass brings the filter to the start of the run converged (attitude and gyro bias),
    # so that neither of the two passes averaged below carries a start-up transient.
    _, q_start, b_start = backward(start(slice(n - first, n)), bias)
    fwd, q_end, b_end = _mahony(fdt, smooth, gyro, use, q_start, kp, ki, b_start)
    bwd, _, _ = backward(q_end, b_end)
    return 0.5 * (fwd + bwd), dynamic


def estimate_attitude(t_ns: np.ndarray, acc: np.ndarray, gyro: np.ndarray, gravity: float, max_gap_s: float,
                      kp: float = KP, ki: float = KI, two_pass: bool = True) -> AttitudeEstimate:
    """Roll and pitch at every IMU stamp from specific force (m/s^2, gravity in) and body rates (rad/s).

    t_ns must increase; each run without a pause longer than max_gap_s is filtered on its own.
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    acc, gyro = np.asarray(acc, dtype=np.float64), np.asarray(gyro, dtype=np.float64)
    att, dyn = np.empty((len(t_ns), 2)), np.zeros(len(t_ns), dtype=bool)
    cuts = np.flatnonzero(np.diff(t_ns) > int(round(max_gap_s * NS))) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(t_ns)]):
        if b > a:
            att[a:b], dyn[a:b] = _run(t_ns[a:b], acc[a:b], gyro[a:b], gravity, kp, ki, two_pass)
    return AttitudeEstimate(att[:, 0], att[:, 1], dyn)
