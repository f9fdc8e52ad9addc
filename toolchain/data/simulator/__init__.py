"""Simulated rover telemetry: terramechanics, rovers, terrains, driver, sensors, scenarios.

Python API (used by the host tools to stream raw samples):
    simulate_traverse(rover, terrain, gravity, duration_s, seed, rate_hz=50) -> Trace
    scenario_traces(seed, scale=1.0) -> [(role, name, Trace)]
    write_scenario(out_dir, seed, scale=1.0) -> Path
A Trace holds `samples` (n, 7) in RAW_CHANNELS order and physical units,
`d_actual_step`, `d_cmd_step` (m per sample), `rate_hz`, `meta` and `truth`.
"""

from .engine import Trace, TraverseSpec, simulate_batch, simulate_traverse
from .rovers import GRAVITY_EARTH, GRAVITY_MOON, ROVERS, Rover
from .scenario import SCENARIO, scenario_traces, write_scenario
from .terrain import TERRAINS, TerrainSpec
from .terramechanics import SOILS, Soil

__all__ = [
    "GRAVITY_EARTH", "GRAVITY_MOON", "ROVERS", "Rover", "SCENARIO", "SOILS", "Soil", "TERRAINS", "TerrainSpec",
    "Trace", "TraverseSpec", "scenario_traces", "simulate_batch", "simulate_traverse", "write_scenario",
]
