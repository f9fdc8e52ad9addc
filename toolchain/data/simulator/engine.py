"""Time stepping: rovers driving over terrains, and what their sensors report.

Per sample (dt = 1 / rate) and for all traverses of a batch at once:

1. Attitude from the terrain under the rover: pitch = atan((h_front - h_rear) /
   wheelbase), roll = atan((h_left - h_right) / track); the rover's footprint
   filters out terrain shorter than itself.
2. Soil under the rover: blend of the terrain's two soils, times a slowly
   varying random factor on cohesion and friction (small-scale heterogeneity).
3. Quasi-static traction balance per wheel (all wheels share the load):
   load W = m g cos(pitch) cos(roll) / N; required pull
   F = (m g sin(pitch) + m r dw/dt + R_turn) / N, with R_turn = turn_drag *
   m g tan(phi) * min(1, |yaw rate| / 0.15 rad/s) the scrubbing of a turn;
   slip, sinkage and thrust from `terramechanics.solve_slip`.
4. Body speed v = r w (1 - s); the position advances along the heading.
5. The driver reacts to digging in: slip above STUCK_SLIP for STUCK_S makes
   it turn away at full yaw rate for ESCAPE_S (as an operator would), so a
   rover does not spin in one spot for minutes.

Steps 1-3 run at PHYSICS_HZ (25 Hz; the sample rate if that is lower) and
are held in between; wheel speed, heading and distance are integrated per
sample. The driver's wheel-speed and yaw-rate commands come from `driver`.

Sensors (all with white noise, and with a constant bias drawn per traverse):
* wheel_speed: mean over the left and right wheels of |w +- yaw_rate * track / (2 r)|.
* motor_current: mean over both sides of |H +- R_turn / N| r / (k_t G eta) plus
  the no-load current while the wheels turn (they hold the rover when stopped).
* acc_x/y/z: body frame (x forward, y left, z up). Default ACCEL_LINEAR:
  gravity-free linear acceleration a = (dv/dt, v * yaw_rate, 0), as an IMU
  with an attitude filter reports it and as the Fleet-To-Lab files carry it
  (mean acc_z ~ 0 on Earth and Moon alike). ACCEL_SPECIFIC_FORCE: the raw
  accelerometer's specific force, gravity included: f = (dv/dt + g sin(pitch),
  v * yaw_rate + g cos(pitch) sin(roll), g cos(pitch) cos(roll)). Both add
  chassis vibration: coloured noise whose level grows with rim speed, terrain
  roughness, sinkage and slip.
* roll, pitch: attitude estimate = true attitude + noise + bias.

Ground truth per sample: d_actual_step = |v| dt (path length of the body) and,
as in the reference data, d_cmd_step = measured wheel speed * r * dt.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter

from ..contracts import CH, DEFAULT_RATE_HZ, N_CHANNELS
from ..features import LabelledWindows, featurise_trace
from .driver import Commands, drive_commands
from .rovers import GRAVITY_EARTH, ROVERS, Rover
from .terrain import TERRAINS, SoilBlend, TerrainField, TerrainSpec
from .terramechanics import solve_slip
from ...errors import InputError

PHYSICS_HZ = 25.0  # rate of the traction solve
# A driver who sees the rover dig in (slip above STUCK_SLIP for STUCK_S) turns
# away at full yaw rate for ESCAPE_S instead of spinning the wheels forever.
STUCK_SLIP, STUCK_S, ESCAPE_S, N_ESCAPE_SIGNS = 0.7, 5.0, 3.0, 64
TURN_RATE_FULL = 0.15  # rad/s: yaw rate at which a skid-steer turn scrubs fully
HETEROGENEITY = 0.25  # relative std of the soil strength variation along the way
HETEROGENEITY_S = 60.0  # its correlation time at cruise speed
VIBRATION_S = 0.06  # correlation time of chassis vibration
# Site-to-site soil variability: no two traverses cross the same soil, even of one nominal type
# (regolith strength varies with depth, compaction and grain size from site to site). Each traverse
# multiplies these soil parameters by exp(spread * N(0, 1)); a model trained on some traverses
# therefore meets soils it has not seen on the others, as with real rover traverses.
SITE_SPREAD = {"cohesion_pa": 0.6, "friction_deg": 0.12, "k_c": 0.5, "k_phi": 0.5, "shear_k": 0.4}
# Motor current for a given torque drifts from traverse to traverse (winding temperature, gearbox
# friction and lubricant viscosity in the lunar thermal cycle): a per-traverse factor exp(spread * N(0, 1)).
CURRENT_GAIN_SPREAD = 0.3
# How rocky a site is varies around its terrain type's roughness: a per-traverse factor on vibration.
ROCKINESS_SPREAD = 0.55
# Chassis vibration grows as (g_Earth / g) ** this in lower gravity (wheel hop); 0.3 gives the
# Moon about 1.7 times Earth's vibration at the same rim speed and roughness. (The Fleet-To-Lab
# target rover's acc_z std is 1.38 on the Moon against 0.38 in the Earth analog, speed and
# terrain included.)
LOW_GRAVITY_VIBRATION_EXP = 0.3
# The acceleration convention of acc_x/y/z (see the module docstring).
ACCEL_LINEAR = "linear"
ACCEL_SPECIFIC_FORCE = "specific-force"
ACCEL_CONVENTIONS = (ACCEL_LINEAR, ACCEL_SPECIFIC_FORCE)


@dataclass
class Trace:
    """One simulated traverse: raw samples in RAW_CHANNELS order and distance increments."""

    samples: np.ndarray  # (n, 7) float64, physical units
    d_actual_step: np.ndarray  # (n,) m travelled by the body during each sample
    d_cmd_step: np.ndarray  # (n,) m commanded (measured wheel speed x radius x dt)
    rate_hz: float
    meta: dict
    truth: dict[str, np.ndarray] = field(default_factory=dict)  # per-sample slip, sinkage, pose

    def windows(self) -> LabelledWindows:
        """Features and labels, through the one shared featuriser."""
        return featurise_trace(self.samples, self.d_actual_step, self.d_cmd_step, self.rate_hz)


@dataclass(frozen=True)
class TraverseSpec:
    rover: Rover
    terrain: TerrainSpec
    gravity: float
    duration_s: float
    seed: int

    @classmethod
    def make(cls, rover: Rover | str, terrain: TerrainSpec | str, gravity: float, duration_s: float,
             seed: int) -> "TraverseSpec":
        if isinstance(rover, str):
            if rover not in ROVERS:
                raise InputError(f"unknown rover {rover!r} (known: {', '.join(ROVERS)})")
            rover = ROVERS[rover]
        if isinstance(terrain, str):
            if terrain not in TERRAINS:
                raise InputError(f"unknown terrain {terrain!r} (known: {', '.join(TERRAINS)})")
            terrain = TERRAINS[terrain]
        if not (0.0 < gravity < 100.0):
            raise InputError(f"gravity must be in (0, 100) m/s^2, got {gravity}")
        if not duration_s > 0:
            raise InputError(f"duration must be positive, got {duration_s} s")
        return cls(rover, terrain, float(gravity), float(duration_s), int(seed))


@dataclass
class _Draws:
    """Everything random about one traverse, drawn up front from its own generator."""

    field: TerrainField
    commands: Commands
    heading0: float
    soil_noise: np.ndarray  # (n, 2) multiplicative factors on cohesion, friction
    vibration: np.ndarray  # (n, 3) unit-variance coloured noise
    noise: np.ndarray  # (n, 2 * 2 + 5) unit white noise for the sensors
    bias: np.ndarray  # (7,) unit normal draws for the sensor biases
    escape_sign: np.ndarray  # (N_ESCAPE_SIGNS,) +-1: direction of each escape turn
    site: dict[str, float]  # per-traverse multiplicative factors on soil parameters (SITE_SPREAD)
    current_gain: float  # per-traverse factor on motor current (CURRENT_GAIN_SPREAD)
    rockiness: float  # per-traverse factor on chassis vibration (ROCKINESS_SPREAD)


def _ar1(rng: np.random.Generator, shape: tuple[int, int], tau_s: float, dt: float) -> np.ndarray:
    """Unit-variance AR(1) noise along axis 0."""
    a = np.exp(-dt / tau_s)
    e = rng.standard_normal(shape) * np.sqrt(1.0 - a * a)
    return lfilter([1.0], [1.0, -a], e, axis=0, zi=a * rng.standard_normal((1, shape[1])))[0]


def _draw(spec: TraverseSpec, n: int, rate_hz: float) -> _Draws:
    rng = np.random.default_rng(spec.seed)
    dt = 1.0 / rate_hz
    terrain = TerrainField.realise(spec.terrain, rng)
    commands = drive_commands(spec.rover, n, rate_hz, rng)
    heading0 = rng.uniform(0.0, 2 * np.pi)
    soil = _ar1(rng, (n, 2), HETEROGENEITY_S, dt)
    soil = np.column_stack([np.exp(HETEROGENEITY * soil[:, 0]), 1.0 + 0.3 * HETEROGENEITY * soil[:, 1]])
    return _Draws(terrain, commands, heading0, soil, _ar1(rng, (n, 3), VIBRATION_S, dt),
                  rng.standard_normal((n, 9)), rng.standard_normal(7), rng.choice([-1.0, 1.0], N_ESCAPE_SIGNS),
                  {k: float(np.exp(spread * rng.standard_normal())) for k, spread in SITE_SPREAD.items()},
                  float(np.exp(CURRENT_GAIN_SPREAD * rng.standard_normal())),
                  float(np.exp(ROCKINESS_SPREAD * rng.standard_normal())))


def _pad(arrays: list[np.ndarray], n: int) -> np.ndarray:
    """Stack per-traverse arrays of different lengths as (n, B, ...), padding with their last row."""
    out = []
    for a in arrays:
        extra = n - len(a)
        out.append(np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]) if extra else a)
    return np.stack(out, axis=1)


def simulate_batch(specs: list[TraverseSpec], rate_hz: float = DEFAULT_RATE_HZ, progress=None,
                   accel: str = ACCEL_LINEAR) -> list[Trace]:
    """Simulate several traverses in lock-step (vectorised over traverses).

    Each traverse draws from its own generator seeded with its spec.seed, so its
    randomness does not depend on which other traverses share the batch.
    `progress` (optional tqdm bar) is advanced by simulated samples of the batch.
    """
    if not specs:
        return []
    if not rate_hz > 0:
        raise InputError(f"rate must be positive, got {rate_hz} Hz")
    if accel not in ACCEL_CONVENTIONS:
        raise InputError(f"unknown acceleration convention {accel!r}; choose one of {', '.join(ACCEL_CONVENTIONS)}")
    dt = 1.0 / rate_hz
    lengths = [max(1, int(round(s.duration_s * rate_hz))) for s in specs]
    n = max(lengths)
    draws = [_draw(s, m, rate_hz) for s, m in zip(specs, lengths)]

    arr = lambda get: np.array([get(s) for s in specs], dtype=np.float64)  # noqa: E731
    mass, g = arr(lambda s: s.rover.mass_kg), arr(lambda s: s.gravity)
    n_wheels, radius = arr(lambda s: s.rover.n_wheels), arr(lambda s: s.rover.wheel_radius_m)
    width, tread = arr(lambda s: s.rover.wheel_width_m), arr(lambda s: s.rover.tread_m)
    wheelbase, track = arr(lambda s: s.rover.wheelbase_m), arr(lambda s: s.rover.track_m)
    turn_drag = arr(lambda s: s.rover.turn_drag)
    soils = SoilBlend([s.terrain.soils[0] for s in specs], [s.terrain.soils[1] for s in specs])
    site = {k: np.array([d.site[k] for d in draws]) for k in SITE_SPREAD}
    terrain = TerrainField.stack([d.field for d in draws])

    omega = _pad([d.commands.wheel_speed for d in draws], n)  # (n, B)
    alpha = _pad([d.commands.wheel_accel for d in draws], n)
    yaw = _pad([d.commands.yaw_rate for d in draws], n)
    heading = np.array([d.heading0 for d in draws]) + np.cumsum(yaw, axis=0) * dt
    max_yaw = arr(lambda s: s.rover.max_yaw_rate)
    escape_signs = np.stack([d.escape_sign for d in draws])  # (B, N_ESCAPE_SIGNS)
    soil_noise = _pad([d.soil_noise for d in draws], n)  # (n, B, 2)

    # The traction balance runs at PHYSICS_HZ (or the sample rate if lower) and is held
    # between physics steps; wheel speed, heading and distance stay per sample.
    k = max(1, int(round(rate_hz / PHYSICS_HZ)))
    n_phys = (n + k - 1) // k
    keys = ("slip", "sinkage", "thrust", "pitch", "roll", "x", "y", "patch", "turn_force", "escape_yaw")
    rec = {key: np.empty((n_phys, len(specs))) for key in keys}
    x = np.zeros(len(specs))
    y = np.zeros(len(specs))
    half_wb, half_tr = wheelbase / 2, track / 2
    rows = np.arange(len(specs))
    stuck_t, escape_t = np.zeros(len(specs)), np.zeros(len(specs))
    n_escapes, heading_off = np.zeros(len(specs), dtype=np.int64), np.zeros(len(specs))
    every, reported = max(1, 2000 // k), 0  # progress counts simulated samples over all traverses
    for j in range(n_phys):
        i = j * k
        moving = omega[i] > 1e-3
        escaping = (escape_t > 0) & moving  # the escape turn is driven, never a turn on the spot
        escape_yaw = np.where(escaping, escape_signs[rows, (n_escapes - 1) % N_ESCAPE_SIGNS] * max_yaw, 0.0)
        yaw_now = yaw[i] + escape_yaw
        c, s = np.cos(heading[i] + heading_off), np.sin(heading[i] + heading_off)
        px = x[:, None] + np.column_stack([half_wb * c, -half_wb * c, -half_tr * s, half_tr * s])
        py = y[:, None] + np.column_stack([half_wb * s, -half_wb * s, half_tr * c, -half_tr * c])
        h = terrain.height(px, py)  # front, rear, left, right
        pitch = np.arctan((h[:, 0] - h[:, 1]) / wheelbase)
        roll = np.arctan((h[:, 2] - h[:, 3]) / track)
        w_patch = terrain.patch_weight(x, y)
        soil = soils.at(w_patch)
        soil = {k: v * site[k] if k in site else v for k, v in soil.items()}
        soil["cohesion_pa"] = soil["cohesion_pa"] * soil_noise[i, :, 0]
        soil["friction_deg"] = soil["friction_deg"] * soil_noise[i, :, 1]
        weight = mass * g * np.cos(pitch) * np.cos(roll)
        turn = turn_drag * weight * np.tan(np.radians(soil["friction_deg"]))
        turn = np.where(moving, turn * np.minimum(1.0, np.abs(yaw_now) / TURN_RATE_FULL), 0.0)
        required = (mass * g * np.sin(pitch) + mass * radius * alpha[i] + turn) / n_wheels
        st = solve_slip(required, weight / n_wheels, radius, width, tread, g, soil)
        slip = np.where(moving, st.slip, 0.0)
        rec["slip"][j], rec["sinkage"][j], rec["pitch"][j], rec["roll"][j] = slip, st.sinkage, pitch, roll
        # A stopped rover holds itself on the slope with its motors.
        rec["thrust"][j] = np.where(moving, st.thrust, required)
        rec["x"][j], rec["y"][j], rec["patch"][j], rec["turn_force"][j] = x, y, w_patch, turn / n_wheels
        rec["escape_yaw"][j] = escape_yaw
        block = heading[i : i + k] + heading_off + escape_yaw * dt * np.arange(1, len(heading[i : i + k]) + 1)[:, None]
        step = radius * omega[i : i + k] * (1.0 - slip) * dt
        x = x + (step * np.cos(block)).sum(axis=0)
        y = y + (step * np.sin(block)).sum(axis=0)
        heading_off = heading_off + escape_yaw * dt * len(block)
        escape_t = escape_t - k * dt
        stuck_t = np.where(moving & (slip > STUCK_SLIP), stuck_t + k * dt, 0.0)
        start = (stuck_t >= STUCK_S) & (escape_t <= 0)
        escape_t = np.where(start, ESCAPE_S, escape_t)
        stuck_t = np.where(start, 0.0, stuck_t)
        n_escapes = n_escapes + start
        if progress is not None and (j % every == every - 1 or j == n_phys - 1):
            done = sum(min(m, i + k) for m in lengths)
            progress.update(done - reported)
            reported = done
    rec = {key: np.repeat(v, k, axis=0)[:n] for key, v in rec.items()}
    rec["speed"] = radius * omega * (1.0 - rec["slip"])
    yaw = yaw + rec.pop("escape_yaw")

    return [
        _sensors(spec, draws[b], {k: v[: lengths[b], b] for k, v in rec.items()}, yaw[: lengths[b], b],
                 omega[: lengths[b], b], rate_hz, accel)
        for b, spec in enumerate(specs)
    ]


def _sensors(spec: TraverseSpec, d: _Draws, t: dict[str, np.ndarray], yaw: np.ndarray, omega: np.ndarray,
             rate_hz: float, accel_convention: str = ACCEL_LINEAR) -> Trace:
    """Raw sensor channels and distance increments of one traverse from its true states."""
    rover, g, dt = spec.rover, spec.gravity, 1.0 / rate_hz
    r = rover.wheel_radius_m
    noise, bias = d.noise, d.bias
    n = len(omega)

    # Wheel encoders: left and right sides differ by the turn; the channel is the mean |speed|.
    diff = yaw * rover.track_m / (2.0 * r)
    enc = 0.01 + 0.005 * omega
    left = omega - diff + enc * noise[:, 0]
    right = omega + diff + enc * noise[:, 1]
    wheel_speed = 0.5 * (np.abs(left) + np.abs(right))

    # Motors: torque of each side through gearbox and torque constant.
    to_amp = r / (rover.motor_kt * rover.gear_ratio * rover.gear_efficiency)
    turning = omega > 1e-3
    idle = np.where(turning, rover.no_load_current_a, 0.0)
    amps = [np.abs(t["thrust"] + sign * t["turn_force"]) * to_amp + idle for sign in (-1.0, 1.0)]
    cur_noise = 0.01 + 0.02 * (amps[0] + amps[1]) / 2
    current = d.current_gain * 0.5 * (amps[0] + amps[1]) + cur_noise * noise[:, 2] + 0.02 * bias[0]
    current = np.abs(current)

    # IMU: linear acceleration (or specific force with gravity), plus vibration driven by speed,
    # roughness, sinkage and slip.
    speed = t["speed"]
    accel = np.gradient(speed, dt) if n > 1 else np.zeros(n)
    rim = r * omega
    # Low gravity shakes the chassis more: bumps lift a lightly loaded wheel off the ground
    # sooner and it lands with an impact, and the suspension is less preloaded.
    hop = (GRAVITY_EARTH / g) ** LOW_GRAVITY_VIBRATION_EXP
    level = rover.vibration_gain * spec.terrain.roughness * d.rockiness * hop * rim * (
        1.0 + 10.0 * t["sinkage"] / r + 2.0 * np.abs(t["slip"])
    )
    vib = d.vibration * level[:, None] * np.array([0.6, 0.5, 1.0])
    pitch, roll = t["pitch"], t["roll"]
    acc = np.column_stack([accel, speed * yaw, np.zeros(n)])
    if accel_convention == ACCEL_SPECIFIC_FORCE:
        acc = acc + g * np.column_stack([np.sin(pitch), np.cos(pitch) * np.sin(roll), np.cos(pitch) * np.cos(roll)])
    acc = acc + vib + 0.02 * noise[:, 3:6] + 0.03 * bias[1:4]

    samples = np.empty((n, N_CHANNELS))
    samples[:, CH["wheel_speed"]] = wheel_speed
    samples[:, CH["motor_current"]] = current
    samples[:, CH["acc_x"]], samples[:, CH["acc_y"]], samples[:, CH["acc_z"]] = acc.T
    samples[:, CH["roll"]] = roll + 0.003 * noise[:, 6] + 0.005 * bias[4]
    samples[:, CH["pitch"]] = pitch + 0.003 * noise[:, 7] + 0.005 * bias[5]

    meta = {
        "rover": rover.name,
        "terrain": spec.terrain.name,
        "soils": [spec.terrain.soil_a, spec.terrain.soil_b],
        "gravity": g,
        "seed": spec.seed,
        "duration_s": n / rate_hz,
        "rate_hz": rate_hz,
        "n_samples": n,
        "accel": accel_convention,
    }
    truth = {k: t[k] for k in ("slip", "sinkage", "speed", "x", "y", "pitch", "roll", "patch")}
    truth["wheel_left"], truth["wheel_right"] = left, right  # measured side speeds (rad/s), as a bag logs them
    return Trace(samples, np.abs(speed) * dt, wheel_speed * r * dt, float(rate_hz), meta, truth)


def simulate_traverse(rover: Rover | str, terrain: TerrainSpec | str, gravity: float, duration_s: float,
                      seed: int, rate_hz: float = DEFAULT_RATE_HZ, accel: str = ACCEL_LINEAR) -> Trace:
    """One traverse of `rover` on a random instance of `terrain` under `gravity` (m/s^2)."""
    return simulate_batch([TraverseSpec.make(rover, terrain, gravity, duration_s, seed)], rate_hz, accel=accel)[0]
