"""Featurisation throughput and simulation speed on one core (`fleetlab bench data`, options in
`fleetlab.cli.bench_data`).

* featurise: raw samples turned into window features per second by
  `features.featurise` (best of several repeats on a fixed random trace),
  per CPU second of the one thread and per wall-clock second.
* simulate: simulated traverse-seconds per wall-clock second, for one traverse
  alone and for the built-in scenario's traverses batched together.
"""

from __future__ import annotations

import time

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from ..compute import torch_threads
from .contracts import DEFAULT_RATE_HZ, N_CHANNELS
from .features import WindowSpec, featurise

FEATURISE_TARGET = 5_000_000  # raw samples per second the brief asks for


def bench_featurise(n_samples: int, repeats: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    samples = rng.normal(size=(n_samples, N_CHANNELS))
    spec = WindowSpec.for_rate(DEFAULT_RATE_HZ)
    best, best_cpu = np.inf, np.inf
    for _ in tqdm(range(repeats), desc="featurise", leave=False):
        t0, c0 = time.perf_counter(), time.process_time()
        featurise(samples, spec)
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return {"samples": n_samples, "seconds": best, "samples_per_s": n_samples / best,
            "cpu_seconds": best_cpu, "samples_per_cpu_s": n_samples / max(best_cpu, 1e-9),
            # Judged on CPU time (one thread = one core), which a busy machine does not distort.
            "target_samples_per_s": FEATURISE_TARGET, "meets_target": n_samples / max(best_cpu, 1e-9) >= FEATURISE_TARGET}


def bench_simulate(scale: float, seed: int) -> dict:
    from .simulator.engine import simulate_batch, simulate_traverse
    from .simulator.scenario import scenario_specs

    t0, c0 = time.perf_counter(), time.process_time()
    one = simulate_traverse("leo", "rille_wall", 1.62, 120.0, seed)
    single, single_cpu = time.perf_counter() - t0, time.process_time() - c0
    specs = [s for _, _, s in scenario_specs(seed, scale)]
    sim_s = sum(s.duration_s for s in specs)
    with tqdm(total=int(sim_s * DEFAULT_RATE_HZ), desc="simulate", unit="sample", unit_scale=True, leave=False) as bar:
        t0, c0 = time.perf_counter(), time.process_time()
        simulate_batch(specs, progress=bar)
        batched, batched_cpu = time.perf_counter() - t0, time.process_time() - c0
    return {
        "single_traverse_sim_s_per_wall_s": one.meta["duration_s"] / single,
        "single_traverse_sim_s_per_cpu_s": one.meta["duration_s"] / single_cpu,
        "scenario_scale": scale,
        "scenario_traverses": len(specs),
        "scenario_sim_s": sim_s,
        "scenario_wall_s": batched,
        "scenario_cpu_s": batched_cpu,
        "batched_sim_s_per_wall_s": sim_s / batched,
        "batched_sim_s_per_cpu_s": sim_s / batched_cpu,
    }


def measure(samples: int, repeats: int, sim_scale: float, seed: int) -> dict:
    """Both figures, on one thread (torch's and the BLAS pools alike): a core's throughput, whatever the machine."""
    with torch_threads(1), threadpool_limits(1):
        return {"threads": 1, "featurise": bench_featurise(samples, repeats, seed),
                "simulate": bench_simulate(sim_scale, seed)}


def text(result: dict) -> str:
    """The figures as the two lines `fleetlab bench data` prints."""
    f, s = result["featurise"], result["simulate"]
    return (f"featurise: {f['samples_per_cpu_s'] / 1e6:.1f} M raw samples per CPU second on one core "
            f"({'meets' if f['meets_target'] else 'BELOW'} the {FEATURISE_TARGET / 1e6:.0f} M/s target; "
            f"{f['samples_per_s'] / 1e6:.1f} M per wall second)\n"
            f"simulate:  {s['single_traverse_sim_s_per_wall_s']:.0f} simulated s per wall s for one traverse; "
            f"{s['batched_sim_s_per_wall_s']:.0f} ({s['batched_sim_s_per_cpu_s']:.0f} per CPU s) for the "
            f"{s['scenario_traverses']} batched traverses of the scenario at scale {s['scenario_scale']:g} "
            f"({s['scenario_wall_s']:.1f} s wall, {s['scenario_cpu_s']:.1f} s CPU)")
