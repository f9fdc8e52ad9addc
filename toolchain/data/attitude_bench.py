"""`fleetlab bench attitude` (options: `cli/bench_attitude.py`): how far roll and pitch estimated from the
IMU (`[attitude] source = "imu"`) are from the truth, on the simulator's traverses.

Every traverse of the built-in scenario (`--seed`, `--scale`) is simulated twice: on its own terrain
(sloped: 11 to 22 degrees RMS slope) and on a flat twin of that terrain (same soils, rocks and driver,
slope 0). Its IMU is what `fleetlab simulate --csv-logs` writes (`simulator.csv_logs.imu_signals`:
specific force with vibration, noise and bias, gyro with noise and bias, at 100 Hz), the estimate is
`attitude.estimate_attitude`, and the truth is the attitude the simulated IMU had. Per gravity (Earth,
Moon) and terrain (flat, sloped): the mean and 95th percentile of the error in degrees, per IMU sample
and per 2 s window mean (what the pitch and roll features see), and the windows counted high-dynamic
(the import's `att?` column) with their error.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .attitude import UNTRUSTED_SHARE, estimate_attitude
from .contracts import DEFAULT_RATE_HZ, STRIDE_S, WINDOW_S
from ..errors import InputError

NS = 1_000_000_000


@dataclasses.dataclass
class TraverseErrors:
    name: str
    gravity: float
    terrain: str  # "flat" or "sloped"
    sample_deg: np.ndarray  # (n, 2) |estimate - truth| of roll, pitch per IMU sample
    window_deg: np.ndarray  # (w, 2) |mean estimate - mean truth| per 2 s window
    window_signed_rad: np.ndarray  # (w, 2) mean estimate - mean truth per window (rad)
    untrusted: np.ndarray  # (w,) bool: the import would count the window high-dynamic


def traverse_errors(name: str, trace, gravity: float, terrain: str) -> TraverseErrors:
    """The estimate's errors on one simulated traverse's IMU (the one `simulate --csv-logs` writes)."""
    from .simulator.csv_logs import imu_signals

    t_ms, force, gyro, truth = imu_signals(trace, gravity, trace.meta["seed"])
    t_ns = np.round(t_ms * 1e6).astype(np.int64)
    est = estimate_attitude(t_ns, force, gyro, gravity, max_gap_s=0.5)
    att = np.column_stack([est.roll, est.pitch])
    # the import's windows: 2 s of its 50 Hz grid from the first stamp; here the IMU samples in each
    n_grid = int((t_ns[-1] - t_ns[0]) * DEFAULT_RATE_HZ // NS) + 1
    w = (n_grid - int(WINDOW_S * DEFAULT_RATE_HZ)) // int(STRIDE_S * DEFAULT_RATE_HZ) + 1 if n_grid >= 100 else 0
    starts = np.searchsorted(t_ns, t_ns[0] + np.arange(w) * int(STRIDE_S * NS))
    ends = np.searchsorted(t_ns, t_ns[0] + np.arange(w) * int(STRIDE_S * NS) + int(WINDOW_S * NS))
    mean = lambda a: np.array([a[s:e].mean(axis=0) for s, e in zip(starts, ends)]).reshape(w, *a.shape[1:])  # noqa: E731
    signed = mean(att) - mean(truth)
    untrusted = mean(est.dynamic.astype(np.float64)) > UNTRUSTED_SHARE
    return TraverseErrors(name, gravity, terrain, np.degrees(np.abs(att - truth)), np.degrees(np.abs(signed)), signed,
                          untrusted)


def scenario_errors(seed: int, scale: float, flat: bool = True) -> list[TraverseErrors]:
    """Errors on every traverse of the scenario (and on its flat twin)."""
    from .simulator.engine import simulate_batch
    from .simulator.scenario import scenario_specs

    entries = scenario_specs(seed, scale)
    specs = [(name, "sloped", spec) for _, name, spec in entries]
    if flat:
        specs += [(name, "flat", dataclasses.replace(spec, terrain=dataclasses.replace(spec.terrain, slope_rms_deg=0.0)))
                  for _, name, spec in entries]
    traces = simulate_batch([s for _, _, s in specs])
    return [traverse_errors(name, trace, spec.gravity, kind) for (name, kind, spec), trace in zip(specs, traces)]


def summarise(errors: list[TraverseErrors]) -> list[dict]:
    rows = []
    for gravity, place in ((9.81, "Earth"), (1.62, "Moon")):
        for terrain in ("flat", "sloped"):
            sel = [e for e in errors if abs(e.gravity - gravity) < 1e-6 and e.terrain == terrain]
            if not sel:
                continue
            s = np.concatenate([e.sample_deg for e in sel])
            w = np.concatenate([e.window_deg for e in sel])
            u = np.concatenate([e.untrusted for e in sel])
            rows.append({
                "place": place, "terrain": terrain, "traverses": len(sel), "windows": len(w),
                "sample_mean_deg": float(s.mean()), "sample_p95_deg": float(np.percentile(s, 95)),
                "window_mean_deg": float(w.mean()), "window_p95_deg": float(np.percentile(w, 95)),
                "roll_window_mean_deg": float(w[:, 0].mean()), "pitch_window_mean_deg": float(w[:, 1].mean()),
                "untrusted_windows": int(u.sum()),
                "untrusted_window_mean_deg": float(w[u].mean()) if u.any() else None,
                "trusted_window_mean_deg": float(w[~u].mean()) if (~u).any() else None,
            })
    return rows


def measure(seed: int, scale: float) -> dict:
    """The figures of `fleetlab bench attitude`: one row per gravity and terrain, and the time taken."""
    if not 0 < scale <= 10:
        raise InputError(f"--scale must be in (0, 10], got {scale}")
    t0, c0 = time.perf_counter(), time.process_time()
    rows = summarise(scenario_errors(seed, scale))
    return {"seed": seed, "scale": scale, "rows": rows, "wall_s": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0}


def table(result: dict) -> str:
    """The figures as text."""
    lines = [f"roll and pitch from the IMU (Mahony filter, backward-forward-backward) vs the simulated IMU's true attitude; scenario "
             f"seed {result['seed']}, scale {result['scale']:g}, every traverse also on a flat twin; errors in "
             "degrees, roll and pitch together",
             f"{'':7s}{'terrain':8s}{'traverses':>10s}{'windows':>8s} {'sample mean':>12s}{'p95':>7s} "
             f"{'window mean':>12s}{'p95':>7s}   high-dynamic windows: n, mean error (others)"]
    for r in result["rows"]:
        dyn = (f"{r['untrusted_windows']:5d}, {r['untrusted_window_mean_deg']:.2f} ({r['trusted_window_mean_deg']:.2f})"
               if r["untrusted_windows"] and r["trusted_window_mean_deg"] is not None else f"{r['untrusted_windows']:5d}")
        lines.append(f"{r['place']:7s}{r['terrain']:8s}{r['traverses']:>10d}{r['windows']:>8d} "
                     f"{r['sample_mean_deg']:12.2f}{r['sample_p95_deg']:7.2f} {r['window_mean_deg']:12.2f}"
                     f"{r['window_p95_deg']:7.2f}   {dyn}")
    lines.append(f"({result['wall_s']:.1f} s wall, {result['cpu_s']:.1f} s CPU)")
    return "\n".join(lines)
