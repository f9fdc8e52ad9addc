"""Rigid-wheel / deformable-soil interaction (Bekker, Janosi-Hanamoto, Rankine).

A simplified, lumped version of the Wong-Reece wheel model, written so that
every function broadcasts over numpy arrays (one entry per traverse and per
slip value) and a whole batch of traverses is solved in one call per step.

Equations (W = normal load on one wheel, r = wheel radius, b = wheel width,
soil: cohesion c, internal friction angle phi, shear modulus K, bulk density
rho, Bekker moduli k_c, k_phi and exponent n, gravity g):

* Static sinkage of a rigid wheel, from integrating Bekker's pressure-sinkage
  law p = (k_c / b + k_phi) z^n over a shallow circular contact arc:
      z0 = [3 W / ((3 - n) (k_c + b k_phi) sqrt(2 r))]^(2 / (2n + 1))
* Slip sinkage: a spinning wheel digs itself in. Lyasko's form
  z0 (1 + s) / (1 - 0.5 s) grows so fast for small wheels that the drawbar
  pull never turns positive, so a linearised version is used:
      z(s) = z0 (1 + SLIP_SINKAGE s)          for driving slip s >= 0,
  and z = z0 for braking (s < 0).
* Compaction resistance (work of pressing a rut of depth z, per wheel):
      R_c = (k_c + b k_phi) z^(n+1) / (n + 1)
* Bulldozing resistance, approximated by Rankine's passive earth pressure on
  the soil wedge in front of the wheel (Kp = tan^2(45 deg + phi / 2)):
      R_b = b (0.5 rho g z^2 Kp + 2 c z sqrt(Kp))
* Gross thrust, Janosi-Hanamoto shear-stress/shear-displacement law lumped
  over a contact patch of length L = r acos(1 - z / r) + l_tread (arc from
  soil entry to the bottom of the wheel, plus the extra shearing length of
  grousers/tyre tread) and area A = b L; shear displacement grows linearly
  along the patch to s L, so the mean mobilised fraction is
      H(s) = (A c + W tan phi) * (1 - K / (s L) (1 - exp(-s L / K)))
  (odd in s: a braking wheel gets the same shear with opposite sign).
* Drawbar pull DP(s) = H(s) - R_c(s) - R_b(s). The slip of a wheel is the s at
  which DP(s) equals the thrust the vehicle needs from that wheel; DP is
  tabulated on a fixed slip grid and inverted by linear interpolation. If the
  soil cannot deliver the thrust the wheel spins at the top of the grid.

Lower gravity lowers W: the friction term W tan phi and the sinkage shrink,
while the cohesion term A c and inertia do not, which is what the lunar
scenario exercises.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

# Slip grid for the inverse lookup: braking side coarse, driving side dense near 0.
_S_BRAKE = -np.linspace(0.9, 0.0, 10, endpoint=False)
_S_DRIVE = 0.99 * np.linspace(0.0, 1.0, 32) ** 1.5
SLIP_GRID = np.concatenate([_S_BRAKE, _S_DRIVE])  # increasing, contains 0
SLIP_MIN, SLIP_MAX = float(SLIP_GRID[0]), float(SLIP_GRID[-1])
SLIP_SINKAGE = 0.4  # relative sinkage increase at 100 % slip


@dataclass(frozen=True)
class Soil:
    """Terramechanics parameters of one soil (SI units, angle in degrees)."""

    name: str
    cohesion_pa: float  # c
    friction_deg: float  # internal friction angle phi
    density: float  # bulk density rho, kg/m^3
    k_c: float  # cohesive modulus of deformation, N/m^(n+1)
    k_phi: float  # frictional modulus of deformation, N/m^(n+2)
    n: float  # sinkage exponent
    shear_k: float  # Janosi shear deformation modulus K, m

    def as_arrays(self) -> dict[str, float]:
        """Numeric fields, for blending soils and broadcasting."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "name"}


# Built-in soils. Values are in the ranges published for lunar regolith and its
# simulants and for dry terrestrial sands (Bekker; Wong, "Theory of Ground Vehicles").
SOILS: dict[str, Soil] = {
    s.name: s
    for s in (
        # Firm, cohesive basalt-sand mix of an indoor lunar analog facility.
        Soil("analog_sand", 1200.0, 35.0, 1700.0, 5000.0, 3.5e6, 0.8, 0.008),
        # Looser sand patches of the same facility.
        Soil("analog_loose", 600.0, 32.0, 1600.0, 3000.0, 2.0e6, 0.9, 0.010),
        # Nominal lunar regolith (mare surface).
        Soil("lunar_regolith", 170.0, 35.0, 1600.0, 1400.0, 8.2e5, 1.0, 0.010),
        # Compacted highland regolith.
        Soil("lunar_compacted", 500.0, 40.0, 1800.0, 1800.0, 1.4e6, 0.95, 0.009),
        # Loose fines (crater floors, polar regions).
        Soil("lunar_fluffy", 120.0, 32.0, 1450.0, 1000.0, 6.5e5, 1.0, 0.013),
        # Very soft dust pockets (unseen by the fleet).
        Soil("lunar_dust", 90.0, 31.0, 1350.0, 900.0, 5.5e5, 1.0, 0.015),
    )
}


def _shear_fraction(x: np.ndarray) -> np.ndarray:
    """1 - (1 - e^-x) / x for x >= 0 (x / 2 near 0, -> 1 for large x)."""
    x = np.maximum(x, 1e-9)
    return np.where(x < 1e-4, 0.5 * x, 1.0 - (-np.expm1(-x)) / x)


def static_sinkage(load, radius, width, k_c, k_phi, n):
    """Bekker sinkage z0 of a rigid wheel (m), capped at half the radius."""
    base = 3.0 * np.maximum(load, 0.0) / ((3.0 - n) * (k_c + width * k_phi) * np.sqrt(2.0 * radius))
    return np.minimum(base ** (2.0 / (2.0 * n + 1.0)), 0.5 * radius)


def slip_sinkage(z0, slip, radius):
    """Slip sinkage z(s) = z0 (1 + SLIP_SINKAGE s) for s >= 0, capped at 0.8 r."""
    return np.minimum(z0 * (1.0 + SLIP_SINKAGE * np.clip(slip, 0.0, None)), 0.8 * radius)


@dataclass
class WheelSoilState:
    """Result of the traction solve for a batch of wheels."""

    slip: np.ndarray
    sinkage: np.ndarray  # m
    thrust: np.ndarray  # gross thrust H per wheel, N (what the motor must deliver)
    resistance: np.ndarray  # R_c + R_b per wheel, N


def drawbar_table(load, radius, width, tread, gravity, soil: dict[str, np.ndarray], slip=SLIP_GRID):
    """(H, R, z) on the slip grid: arrays (..., len(slip)) from per-wheel inputs of shape (...)."""
    ex = lambda a: np.asarray(a, dtype=np.float64)[..., None]  # noqa: E731 - broadcast against the grid
    W, r, b, l_t, g = ex(load), ex(radius), ex(width), ex(tread), ex(gravity)
    c, phi = ex(soil["cohesion_pa"]), np.radians(ex(soil["friction_deg"]))
    rho, k_c, k_phi, n, K = (ex(soil[k]) for k in ("density", "k_c", "k_phi", "n", "shear_k"))
    z0 = static_sinkage(W, r, b, k_c, k_phi, n)
    z = slip_sinkage(z0, slip, r)
    resistance = (k_c + b * k_phi) * np.exp((n + 1.0) * np.log(z)) / (n + 1.0)
    kp = np.tan(np.pi / 4 + phi / 2) ** 2
    resistance = resistance + b * (0.5 * rho * g * z**2 * kp + 2.0 * c * z * np.sqrt(kp))
    patch = r * np.arccos(1.0 - z / r) + l_t
    h_max = b * patch * c + W * np.tan(phi)
    thrust = np.sign(slip) * h_max * _shear_fraction(np.abs(slip) * patch / K)
    return thrust, resistance, z


def solve_slip(required, load, radius, width, tread, gravity, soil: dict[str, np.ndarray]) -> WheelSoilState:
    """Slip at which drawbar pull H - R equals `required` (N per wheel), for every wheel.

    All inputs broadcast to one shape (e.g. (n_traverses,)). Below the grid the
    wheel skids at SLIP_MIN; above the peak pull it spins at SLIP_MAX.
    """
    table = drawbar_table(load, radius, width, tread, gravity, soil)
    shape = np.broadcast_shapes(np.shape(required), *(t.shape[:-1] for t in table))
    thrust, resistance, z = (np.broadcast_to(t, shape + t.shape[-1:]).reshape(-1, len(SLIP_GRID)) for t in table)
    req = np.broadcast_to(np.asarray(required, dtype=np.float64), shape).reshape(-1)
    pull = thrust - resistance
    above = pull >= req[:, None]
    hi = np.where(above.any(axis=1), above.argmax(axis=1), len(SLIP_GRID) - 1)
    hi = np.maximum(hi, 1)
    lo = hi - 1
    rows = np.arange(len(req))
    p_lo, p_hi = pull[rows, lo], pull[rows, hi]
    denom = np.where(p_hi > p_lo, p_hi - p_lo, 1.0)
    t = np.clip((req - p_lo) / denom, 0.0, 1.0)
    interp = lambda a: (a[rows, lo] + t * (a[rows, hi] - a[rows, lo])).reshape(shape)  # noqa: E731
    return WheelSoilState(slip=interp(np.broadcast_to(SLIP_GRID, pull.shape)), sinkage=interp(z),
                          thrust=interp(thrust), resistance=interp(resistance))
