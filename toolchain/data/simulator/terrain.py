"""Random terrains: a smooth heightfield and a map of two blended soils.

Height h(x, y) = sum_k a_k cos(k_k . (x, y) + phase_k) over random Fourier
modes with wavelengths drawn log-uniformly in a band; the amplitudes are scaled
so that the RMS magnitude of the surface gradient, sqrt(sum a_k^2 |k_k|^2 / 2),
equals tan(slope_rms). The soil under the rover blends two soils with a weight
p(x, y) in [0, 1] that comes from a second random field through a steep
sigmoid, thresholded so that about `patch_fraction` of the ground is soil B.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from .terramechanics import SOILS, Soil
from ...errors import InputError

N_HEIGHT_MODES = 24
N_PATCH_MODES = 10
_PATCH_EDGE = 0.15  # width of the soil transition, in std of the patch field


@dataclass(frozen=True)
class TerrainSpec:
    """Statistics of a terrain type; `realise` draws one random instance."""

    name: str
    soil_a: str  # dominant soil (key of SOILS)
    soil_b: str  # patch soil
    patch_fraction: float  # share of the ground covered by soil_b
    patch_scale_m: float  # typical patch size
    slope_rms_deg: float  # RMS terrain slope
    wavelength_m: tuple[float, float] = (15.0, 90.0)
    roughness: float = 1.0  # multiplies chassis vibration (rocks, clods)

    def __post_init__(self) -> None:
        for key in (self.soil_a, self.soil_b):
            if key not in SOILS:
                raise InputError(f"terrain {self.name}: unknown soil {key!r} (known: {', '.join(SOILS)})")
        if not 0.0 <= self.patch_fraction <= 1.0:
            raise InputError(f"terrain {self.name}: patch_fraction must be in [0, 1]")
        if not 0.0 <= self.slope_rms_deg < 45.0:
            raise InputError(f"terrain {self.name}: slope_rms_deg must be in [0, 45)")

    @property
    def soils(self) -> tuple[Soil, Soil]:
        return SOILS[self.soil_a], SOILS[self.soil_b]


def _random_modes(rng: np.random.Generator, n: int, lam_min: float, lam_max: float):
    """Wave vectors (n, 2) with log-uniform wavelengths and uniform directions, and phases (n,)."""
    lam = np.exp(rng.uniform(np.log(lam_min), np.log(lam_max), n))
    ang = rng.uniform(0.0, 2 * np.pi, n)
    k = (2 * np.pi / lam)[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    return k, rng.uniform(0.0, 2 * np.pi, n)


@dataclass
class TerrainField:
    """One realised terrain (or a batch: leading axis = traverse)."""

    h_k: np.ndarray  # (B, N_HEIGHT_MODES, 2) wave vectors
    h_amp: np.ndarray  # (B, N_HEIGHT_MODES)
    h_phase: np.ndarray
    p_k: np.ndarray  # (B, N_PATCH_MODES, 2)
    p_phase: np.ndarray  # (B, N_PATCH_MODES)
    p_threshold: np.ndarray  # (B,)

    @classmethod
    def realise(cls, spec: TerrainSpec, rng: np.random.Generator) -> "TerrainField":
        k, phase = _random_modes(rng, N_HEIGHT_MODES, *spec.wavelength_m)
        kmag = np.linalg.norm(k, axis=1)
        amp = rng.rayleigh(1.0, N_HEIGHT_MODES) / kmag
        grad_rms = np.sqrt(np.sum(amp**2 * kmag**2) / 2.0)
        amp *= np.tan(np.radians(spec.slope_rms_deg)) / grad_rms
        pk, pphase = _random_modes(rng, N_PATCH_MODES, 0.5 * spec.patch_scale_m, 2.0 * spec.patch_scale_m)
        # The patch field below has unit variance, so a normal quantile sets the covered share.
        thr = norm.ppf(1.0 - spec.patch_fraction) if 0.0 < spec.patch_fraction < 1.0 else (
            np.inf if spec.patch_fraction == 0.0 else -np.inf
        )
        return cls(k[None], amp[None], phase[None], pk[None], pphase[None], np.array([thr]))

    @classmethod
    def stack(cls, fields: list["TerrainField"]) -> "TerrainField":
        cat = lambda name: np.concatenate([getattr(f, name) for f in fields])  # noqa: E731
        return cls(*(cat(n) for n in ("h_k", "h_amp", "h_phase", "p_k", "p_phase", "p_threshold")))

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Heights at points (B, P) -> (B, P)."""
        arg = x[..., None] * self.h_k[:, None, :, 0] + y[..., None] * self.h_k[:, None, :, 1]
        return np.einsum("bpk,bk->bp", np.cos(arg + self.h_phase[:, None, :]), self.h_amp)

    def patch_weight(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Share of soil B at points (B,) -> (B,), in [0, 1]."""
        arg = x[:, None] * self.p_k[:, :, 0] + y[:, None] * self.p_k[:, :, 1] + self.p_phase
        field = np.cos(arg).sum(axis=1) * np.sqrt(2.0 / self.p_k.shape[1])  # unit variance
        with np.errstate(over="ignore"):
            return 1.0 / (1.0 + np.exp(-(field - self.p_threshold) / _PATCH_EDGE))


class SoilBlend:
    """Per-traverse soil pair; `at(w)` gives the parameters (1 - w) * A + w * B as arrays (B,)."""

    def __init__(self, soils_a: list[Soil], soils_b: list[Soil]):
        keys = list(soils_a[0].as_arrays())
        self.a = {k: np.array([s.as_arrays()[k] for s in soils_a]) for k in keys}
        self.delta = {k: np.array([s.as_arrays()[k] for s in soils_b]) - self.a[k] for k in keys}

    def at(self, weight: np.ndarray) -> dict[str, np.ndarray]:
        return {k: self.a[k] + weight * self.delta[k] for k in self.a}


# Built-in terrains. The Earth analog is a flat-ish indoor facility; the fleet
# rovers drive lunar terrains of three kinds; the target rover meets three
# lunar terrains (and two soils) that no fleet rover has seen.
TERRAINS: dict[str, TerrainSpec] = {
    t.name: t
    for t in (
        TerrainSpec("analog_hall", "analog_sand", "analog_loose", 0.5, 6.0, 11.0, roughness=0.8),
        TerrainSpec("mare_plain", "lunar_regolith", "lunar_fluffy", 0.6, 10.0, 17.0),
        TerrainSpec("highland_slope", "lunar_compacted", "lunar_fluffy", 0.45, 12.0, 21.0, roughness=1.3),
        TerrainSpec("crater_rim", "lunar_regolith", "lunar_fluffy", 0.6, 8.0, 22.0, roughness=1.2),
        TerrainSpec("polar_crater", "lunar_regolith", "lunar_dust", 0.5, 8.0, 16.0),
        TerrainSpec("ejecta_field", "lunar_compacted", "lunar_dust", 0.45, 6.0, 18.0, roughness=1.6),
        TerrainSpec("rille_wall", "lunar_regolith", "lunar_dust", 0.45, 10.0, 16.0, roughness=1.1),
    )
}
