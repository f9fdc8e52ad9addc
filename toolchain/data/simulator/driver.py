"""The driver: a sequence of drive segments (cruise speed, straight or arc turn) and stops.

The wheel-speed controller is assumed to track its set-point through a
first-order lag, whatever the soil does (slip changes how far the rover gets,
not how fast the wheels turn), so wheel speed and yaw rate can be generated
for the whole traverse before the physics runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from .rovers import Rover

SPEED_LAG_S = 1.0  # wheel-speed controller time constant
YAW_LAG_S = 0.8


@dataclass(frozen=True)
class DriverStyle:
    # Long segments: a rover operator commands a drive leg of a minute or more, and slip
    # stays persistent over many 2 s windows, as in the real rover traverses.
    segment_s: tuple[float, float] = (30.0, 120.0)  # drive segment length
    stop_probability: float = 0.06  # chance that a segment is a stop
    stop_s: tuple[float, float] = (3.0, 9.0)  # long enough to cover a whole 2 s window
    turn_probability: float = 0.4  # chance that a drive segment starts with an arc turn
    turn_deg: tuple[float, float] = (20.0, 120.0)  # heading change of an arc turn


@dataclass
class Commands:
    wheel_speed: np.ndarray  # (n,) rad/s, wheel angular speed after the controller lag
    wheel_accel: np.ndarray  # (n,) rad/s^2
    yaw_rate: np.ndarray  # (n,) rad/s


def _first_order_lag(x: np.ndarray, tau_s: float, dt: float) -> np.ndarray:
    a = np.exp(-dt / tau_s)
    return lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])[0] if len(x) else x


def drive_commands(rover: Rover, n_samples: int, rate_hz: float, rng: np.random.Generator,
                   style: DriverStyle = DriverStyle()) -> Commands:
    """Wheel speed and yaw rate for n_samples; the traverse starts at rest."""
    dt = 1.0 / rate_hz
    speed = np.zeros(n_samples)
    yaw = np.zeros(n_samples)
    i = int(rng.uniform(1.0, 3.0) * rate_hz)  # a short initial stop
    while i < n_samples:
        if rng.random() < style.stop_probability:
            i += int(rng.uniform(*style.stop_s) * rate_hz)
            continue
        n = int(rng.uniform(*style.segment_s) * rate_hz)
        v = rng.uniform(*rover.speed_range_mps)
        speed[i : i + n] = v / rover.wheel_radius_m
        if rng.random() < style.turn_probability:
            # An arc turn changes the heading by a bounded angle, then the leg goes on straight;
            # circling for a whole long leg would make the slope under the rover oscillate.
            rate = rng.uniform(0.3, 1.0) * rover.max_yaw_rate
            turn_n = min(n, int(np.radians(rng.uniform(*style.turn_deg)) / rate * rate_hz))
            yaw[i : i + turn_n] = rng.choice([-1.0, 1.0]) * rate
        i += n
    wheel_speed = _first_order_lag(speed, SPEED_LAG_S, dt)
    return Commands(
        wheel_speed=wheel_speed,
        wheel_accel=np.gradient(wheel_speed, dt) if n_samples > 1 else np.zeros(n_samples),
        yaw_rate=_first_order_lag(yaw, YAW_LAG_S, dt),
    )
