"""`fleetlab bench link` (options in `fleetlab.cli.bench_link`): how fast the host emulation loop runs the C estimator over a link, against what
the rover needs (telemetry at 50 Hz = 150 frames/s, one window every 2 s).

* throughput: a soak stream at full speed (frames and windows per second, and the ratio to the rover's
  rate), every window compared bit for bit as in `fleetlab emulate`;
* latency: windows paced in real time at 50 Hz, from the last sample of a window written to its estimate
  read back (p50, p99).

These figures depend on the machine and its load; the tests check what the loop computes, never its speed.
"""

from __future__ import annotations

from fleetlab.data.contracts import DEFAULT_RATE_HZ
from .emulate import DEFAULT_SCALE, REALTIME_FRAMES_PER_S, emulate, soak_source
from .sources import TelemetrySource, sim_source


def measure(link: str, frames: int, windows: int, seed: int, progress: bool = True) -> tuple[dict, bool]:
    """The figures of a `frames`-frame soak and `windows` windows paced in real time over `link`, and whether
    every window of both was bit-exact (nothing dropped)."""
    sim = sim_source(seed=seed, scale=DEFAULT_SCALE)
    soak = emulate(None, soak_source(frames, seed=seed, scale=DEFAULT_SCALE, base=sim), link,
                   progress=progress).summary()
    paced_src = TelemetrySource("paced", sim.samples_q[: 100 * windows], [])
    paced = emulate(None, paced_src, link, progress=False, realtime=True).summary()
    out = {
        "link": link,
        "frames_sent": soak["frames_sent"],
        "frames_per_s": soak["frames_per_s"],
        "windows_per_s": soak["windows_per_s"],
        "rover_frames_per_s": REALTIME_FRAMES_PER_S,
        "ratio_to_rover_rate": round(soak["frames_per_s"] / REALTIME_FRAMES_PER_S, 2),
        "soak_bit_exact": soak["bit_exact"] == soak["windows"] and soak["dropped_frames"] == 0,
        "latency_windows": paced["windows"],
        "latency_us_p50": round(paced["latency_us"]["p50"], 1),
        "latency_us_p99": round(paced["latency_us"]["p99"], 1),
    }
    return out, out["soak_bit_exact"] and paced["mismatches"] == 0


def text(out: dict) -> str:
    """The figures as the two lines `fleetlab bench link` prints."""
    link = out["link"]
    return (f"{link}: {out['frames_per_s']:,.0f} frames/s, {out['windows_per_s']:.1f} windows/s at full speed "
            f"({out['ratio_to_rover_rate']}x the rover's {REALTIME_FRAMES_PER_S:.0f} frames/s; "
            f"{'every window bit-exact' if out['soak_bit_exact'] else 'MISMATCHES OR DROPS'})\n"
            f"{link}: estimator latency over {out['latency_windows']} windows paced at {DEFAULT_RATE_HZ} Hz: "
            f"p50 {out['latency_us_p50']:,.0f} us, p99 {out['latency_us_p99']:,.0f} us")
