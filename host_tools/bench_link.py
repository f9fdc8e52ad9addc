"""`fleetlab bench link`: how fast the host emulation loop runs the C estimator over a link, against what
the rover needs (telemetry at 50 Hz = 150 frames/s, one window every 2 s).

* throughput: a soak stream at full speed (frames and windows per second, and the ratio to the rover's
  rate), every window compared bit for bit as in `fleetlab emulate`;
* latency: windows paced in real time at 50 Hz, from the last sample of a window written to its estimate
  read back (p50, p99).

These figures depend on the machine and its load; the tests check what the loop computes, never its speed.
"""

from __future__ import annotations

import argparse
import json

from fleetlab.data.contracts import DEFAULT_RATE_HZ
from .emulate import DEFAULT_SCALE, LINKS, REALTIME_FRAMES_PER_S, emulate, soak_source
from .sources import TelemetrySource, sim_source


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--link", choices=LINKS, default="slcan", help="link to measure (default slcan)")
    parser.add_argument("--frames", type=int, default=30_000, help="frames of the full-speed soak (default 30,000)")
    parser.add_argument("--windows", type=int, default=3,
                        help="windows paced in real time for the latency (default 3: 6 s at 50 Hz)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def run(args: argparse.Namespace) -> int:
    if args.frames < 300 or args.windows < 1:
        raise ValueError("--frames must cover one window (>= 300) and --windows must be >= 1")
    sim = sim_source(seed=args.seed, scale=DEFAULT_SCALE)
    soak = emulate(None, soak_source(args.frames, seed=args.seed, scale=DEFAULT_SCALE, base=sim), args.link,
                   progress=not args.json).summary()
    paced_src = TelemetrySource("paced", sim.samples_q[: 100 * args.windows], [])
    paced = emulate(None, paced_src, args.link, progress=False, realtime=True).summary()
    out = {
        "link": args.link,
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
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{args.link}: {out['frames_per_s']:,.0f} frames/s, {out['windows_per_s']:.1f} windows/s at full speed "
              f"({out['ratio_to_rover_rate']}x the rover's {REALTIME_FRAMES_PER_S:.0f} frames/s; "
              f"{'every window bit-exact' if out['soak_bit_exact'] else 'MISMATCHES OR DROPS'})")
        print(f"{args.link}: estimator latency over {paced['windows']} windows paced at {DEFAULT_RATE_HZ} Hz: "
              f"p50 {out['latency_us_p50']:,.0f} us, p99 {out['latency_us_p99']:,.0f} us")
    return 0 if out["soak_bit_exact"] and paced["mismatches"] == 0 else 1
