"""Rover descriptions: mass, wheels, motors and drive geometry.

Every wheel is driven. Motor current per wheel follows from the wheel torque
T = H r (gross thrust times radius) through the gearbox and the motor torque
constant: I = T / (k_t G eta) + I_0 while the wheel turns. Skid-steered rovers
turn by dragging their wheels sideways, which costs extra thrust; rovers with
explicitly steered wheels turn almost for free.
"""

from __future__ import annotations

from dataclasses import dataclass
from ...errors import InputError

GRAVITY_EARTH = 9.81  # m/s^2
GRAVITY_MOON = 1.62  # m/s^2


@dataclass(frozen=True)
class Rover:
    name: str
    mass_kg: float
    n_wheels: int
    wheel_radius_m: float
    wheel_width_m: float
    tread_m: float  # extra shearing length of grousers / tyre tread in the contact patch
    wheelbase_m: float  # front-to-rear axle distance (pitch is sensed over it)
    track_m: float  # left-to-right wheel distance (roll is sensed over it)
    steering: str  # "skid" or "explicit"
    motor_kt: float  # motor torque constant, N m / A
    gear_ratio: float
    gear_efficiency: float
    no_load_current_a: float
    speed_range_mps: tuple[float, float]  # cruise speeds the driver picks from
    max_yaw_rate: float  # rad/s during arc turns
    vibration_gain: float  # m/s^2 of chassis vibration per m/s of wheel rim speed on rough soil

    def __post_init__(self) -> None:
        if self.steering not in ("skid", "explicit"):
            raise InputError(f"rover {self.name}: steering must be 'skid' or 'explicit', not {self.steering!r}")
        if min(self.mass_kg, self.wheel_radius_m, self.wheel_width_m, self.wheelbase_m, self.track_m) <= 0:
            raise InputError(f"rover {self.name}: mass and dimensions must be positive")
        if self.n_wheels < 3:
            raise InputError(f"rover {self.name}: needs at least 3 wheels, has {self.n_wheels}")

    @property
    def turn_drag(self) -> float:
        """Lateral scrubbing resistance while turning, as a fraction of weight x tan(phi) x geometry."""
        # Only part of each contact patch slides sideways (the rest shears elastically).
        base = 0.25 * self.wheelbase_m / (2.0 * self.track_m)
        return base if self.steering == "skid" else 0.15 * base


# Built-in rovers: a small skid-steered target rover (the one the estimator is
# for) and two fleet rovers that differ in size, wheel count, motors and steering.
ROVERS: dict[str, Rover] = {
    r.name: r
    for r in (
        Rover(
            name="leo",
            mass_kg=6.5,
            n_wheels=4,
            wheel_radius_m=0.065,
            wheel_width_m=0.07,
            tread_m=0.02,
            wheelbase_m=0.36,
            track_m=0.36,
            steering="skid",
            motor_kt=0.010,
            gear_ratio=73.0,
            gear_efficiency=0.7,
            no_load_current_a=0.10,
            speed_range_mps=(0.08, 0.35),
            max_yaw_rate=0.5,
            vibration_gain=1.2,
        ),
        Rover(
            name="scout",
            mass_kg=14.0,
            n_wheels=6,
            wheel_radius_m=0.095,
            wheel_width_m=0.08,
            tread_m=0.03,
            wheelbase_m=0.60,
            track_m=0.50,
            steering="explicit",
            motor_kt=0.035,
            gear_ratio=100.0,
            gear_efficiency=0.65,
            no_load_current_a=0.08,
            speed_range_mps=(0.05, 0.25),
            max_yaw_rate=0.35,
            vibration_gain=0.8,
        ),
        Rover(
            name="hauler",
            mass_kg=50.0,
            n_wheels=4,
            wheel_radius_m=0.165,
            wheel_width_m=0.11,
            tread_m=0.035,
            wheelbase_m=0.51,
            track_m=0.55,
            steering="skid",
            motor_kt=0.044,
            gear_ratio=78.7,
            gear_efficiency=0.75,
            no_load_current_a=0.3,
            speed_range_mps=(0.15, 0.6),
            max_yaw_rate=0.4,
            vibration_gain=0.6,
        ),
    )
}
