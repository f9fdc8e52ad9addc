"""Windows per second that `fleetlab data import` makes from a 10-minute bag (`fleetlab bench import`, options
in `fleetlab.cli.bench_import`).

One simulated traverse (the target rover on the Moon, `--minutes` long) is written as a
rosbag2 with the collector's topics, then imported with its profile: wall and CPU time,
windows per second, and the same figures beside two peers measured in the same run:
the simulator's own in-memory featurisation of the same samples (`featurise_trace`,
what the import adds on top of it is reading and resampling the bag) and real time
(the rover logs one window per 2 s).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from .contracts import STRIDE_S
from .features import featurise_trace
from .log_import import import_log
from .rover_profile import load_profile


def measure(minutes: float, storage: str, seed: int) -> dict:
    """Write a `minutes`-long traverse of the target rover as a bag (`storage`: mcap or sqlite3) and import it;
    the import's figures beside the in-memory featurisation of the same samples and real time."""
    from .simulator import GRAVITY_MOON, simulate_traverse
    from .simulator.bag import profile_toml, write_traverse_bag

    trace = simulate_traverse("leo", "rille_wall", GRAVITY_MOON, minutes * 60.0, seed)
    with tempfile.TemporaryDirectory(prefix="fleetlab-import-bench-") as tmp:
        bag, profile = Path(tmp) / "bag", Path(tmp) / "leo.toml"
        t0 = time.perf_counter()
        write_traverse_bag(bag, trace, "leo", GRAVITY_MOON, storage)
        write_s = time.perf_counter() - t0
        profile.write_text(profile_toml("leo", GRAVITY_MOON))
        size = sum(p.stat().st_size for p in bag.iterdir())
        t0, c0 = time.perf_counter(), time.process_time()
        res = import_log(bag, load_profile(profile), progress=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    t0 = time.perf_counter()
    peer = featurise_trace(trace.samples, trace.d_actual_step, trace.d_cmd_step, trace.rate_hz)
    peer_s = time.perf_counter() - t0
    windows = res.windows_kept
    return {
        "bag_minutes": minutes, "storage": storage, "bag_bytes": size, "messages": 4 * len(trace.samples) + 1,
        "bag_write_s": write_s, "windows": windows, "import_wall_s": wall, "import_cpu_s": cpu,
        "windows_per_s": windows / wall, "windows_per_cpu_s": windows / max(cpu, 1e-9),
        "peer_featurise_trace_windows_per_s": len(peer.label) / max(peer_s, 1e-9),
        "real_time_windows_per_s": 1.0 / STRIDE_S,
    }


def text(out: dict) -> str:
    """The figures as the three lines `fleetlab bench import` prints."""
    return (f"import of a {out['bag_minutes']:g}-minute {out['storage']} bag ({out['messages']:,} messages, "
            f"{out['bag_bytes'] / 1e6:.1f} MB): {out['windows']} windows in {out['import_wall_s']:.2f} s wall "
            f"({out['import_cpu_s']:.2f} s CPU) = {out['windows_per_s']:.0f} windows/s "
            f"({out['windows_per_cpu_s']:.0f} per CPU s)\n"
            f"  vs the simulator's in-memory featurise_trace of the same samples: "
            f"{out['peer_featurise_trace_windows_per_s']:.0f} windows/s (import at "
            f"{out['windows_per_s'] / out['peer_featurise_trace_windows_per_s']:.4f}x: reading the bag dominates)\n"
            f"  vs real time (one window per {STRIDE_S:g} s): x{out['windows_per_s'] / out['real_time_windows_per_s']:.0f}")
