"""`fleetlab simulate`: write the built-in fleet scenario as a dataset folder."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ..data.contracts import CLASS_NAMES, DEFAULT_RATE_HZ
from ..data.dataset import load_dataset
from ..data.simulator.bag import STORAGES
from ..data.simulator.engine import ACCEL_CONVENTIONS, ACCEL_LINEAR
from ..data.simulator.rovers import ROVERS
from ..data.simulator.scenario import DEFAULT_FLEET, LABEL_SOURCES, SCENARIO, write_scenario
from ..errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    roles = ", ".join(f"{g.role} ({g.rover}, g={g.gravity})" for g in SCENARIO)
    parser.description = (
        "Simulate rover telemetry with a Bekker/Janosi wheel-soil model and write one Fleet-To-Lab "
        f"window CSV per traverse plus dataset.json. Roles: {roles}. The folder loads with "
        "'fleetlab data info DIR' and feeds 'fleetlab fuse'."
    )
    parser.add_argument("--out", required=True, type=Path, help="output folder (created; existing files are overwritten)")
    parser.add_argument("--seed", type=int, default=1, help="scenario seed; the same seed gives byte-identical files (default 1)")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="shrink (<1) or grow the number and length of traverses; 1.0 gives ~7,200 windows (default 1.0)")
    parser.add_argument("--rate", type=float, default=DEFAULT_RATE_HZ, help=f"raw sample rate in Hz (default {DEFAULT_RATE_HZ:g})")
    parser.add_argument("--fleet", metavar="ROVERS", default=",".join(DEFAULT_FLEET),
                        help=f"comma-separated fleet rovers on the Moon, out of {', '.join(ROVERS)} (the target "
                        f"rover is leo, so 'leo' adds a sister rover); the Earth and target traverses do not "
                        f"change with the fleet (default: {','.join(DEFAULT_FLEET)})")
    parser.add_argument("--accel", choices=ACCEL_CONVENTIONS, default=ACCEL_LINEAR,
                        help="acc_x/y/z convention: 'linear' = gravity-free linear acceleration, like the "
                        "Fleet-To-Lab files; 'specific-force' = raw accelerometer output with gravity "
                        f"(default {ACCEL_LINEAR})")
    parser.add_argument("--raw", action="store_true", help="also save the raw samples of each traverse as .npz")
    parser.add_argument("--bag", type=Path, metavar="DIR",
                        help="also write each traverse as a rosbag2 in DIR (topics and types of a ROS 2 collector: "
                        "JointState, Imu with gravity, Odometry, PoseStamped ground truth) with the rover profiles "
                        "beside them, ready for 'fleetlab data import'")
    parser.add_argument("--labels", choices=LABEL_SOURCES, default="exact",
                        help="'vo': also write NAME.vo_labels.csv beside each traverse: the slip and class a rover's "
                        "visual odometry would measure (scale error per traverse, error growing with distance, "
                        "dropouts more frequent on smooth low-texture ground, a time lag; docs/paper_table.md), "
                        "next to the true ones (default: exact only)")
    parser.add_argument("--csv-logs", type=Path, metavar="DIR",
                        help="also write each traverse as time-series CSV logs without attitude, as a rover without "
                        "ROS logs them: DIR/<rover>_<earth|moon>/imu_<traverse>.csv (specific force and gyro, 100 Hz), "
                        "wheels_<traverse>.csv, pose_<traverse>.csv (ground truth), with a rover profile per folder "
                        "beside them ([attitude] source = \"imu\"), ready for 'fleetlab data import'")
    parser.add_argument("--bag-storage", choices=STORAGES, default="mcap",
                        help="storage of the --bag files: mcap (default) or sqlite3 (.db3)")


def run(args: argparse.Namespace) -> int:
    if not np.isfinite(args.rate) or args.rate <= 0:
        raise InputError(f"--rate must be a positive number of Hz, got {args.rate}")
    if not np.isfinite(args.scale) or not 0 < args.scale <= 10:
        raise InputError(f"--scale must be in (0, 10], got {args.scale}")
    if (args.bag or args.csv_logs) and args.accel != ACCEL_LINEAR:
        raise InputError("--bag and --csv-logs write the IMU as a raw accelerometer (gravity added from the attitude) itself; "
                         f"keep the default --accel {ACCEL_LINEAR}")
    fleet = tuple(r.strip() for r in args.fleet.split(",") if r.strip())
    t0 = time.perf_counter()
    out = write_scenario(args.out, args.seed, args.scale, args.rate, raw=args.raw, progress=True, fleet=fleet,
                          accel=args.accel, bag=args.bag, bag_storage=args.bag_storage, labels=args.labels,
                          csv_logs=args.csv_logs)
    elapsed = time.perf_counter() - t0
    ds = load_dataset(out)
    print(f"wrote {len(ds.files)} traverses to {out} in {elapsed:.1f} s (seed {args.seed}, scale {args.scale:g})")
    header = "  ".join(f"{c:>14s}" for c in CLASS_NAMES)
    print(f"{'role':14s} {'files':>5s} {'rows':>6s}  {header}")
    for role in ds.roles:
        t = ds.table(role)
        counts = t.class_counts()
        mix = "  ".join(f"{c:6d} ({100 * c / max(1, len(t)):4.1f}%)" for c in counts)
        print(f"{role:14s} {len(ds.files_of(role)):5d} {len(t):6d}  {mix}")
    if args.labels == "vo":
        vo = [f["vo_labels"] for f in json.loads((out / "dataset.json").read_text())["files"].values()]
        wrong, windows = sum(v["wrong"] for v in vo), sum(len(ds.files[i].table) for i in range(len(ds.files)))
        print(f"wrote {len(vo)} NAME.vo_labels.csv: visual odometry gives another class than the truth in {wrong} of "
              f"{windows} windows ({100 * wrong / max(1, windows):.1f} %), {sum(v['dropouts'] for v in vo)} dropouts")
    if args.bag:
        profiles = sorted({f["bag"]["profile"] for f in json.loads((out / "dataset.json").read_text())["files"].values()})
        print(f"wrote {len(ds.files)} {args.bag_storage} bags and the rover profiles {', '.join(profiles)} to {args.bag}")
    if args.csv_logs:
        logs = [f["csv_logs"] for f in json.loads((out / "dataset.json").read_text())["files"].values()]
        folders = sorted({(c["folder"], c["profile"]) for c in logs})
        print(f"wrote {len(logs)} traverses as time-series CSV logs to {args.csv_logs}: "
              + ", ".join(f"{f}/ ({p})" for f, p in folders))
    return 0
