"""`fleetlab data`: `info PATH`, `compare DIR_A DIR_B` and `import SOURCE...`.

`compare` joins the pure statistics of `fleetlab.data.compare` with the SN-S
learnability figures of `fleetlab.evaluation.realism`; this module only wires the
two to the command line and prints them side by side.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..data.compare import compare_statistics
from ..data.contracts import CLASS_NAMES, FEATURE_NAMES
from ..data.dataset import ROLE_PATTERN, load_dataset
from ..data.info import plot_histograms, summarise
from ..data.log_import import UNASSIGNED, drop_summary, import_source, range_warnings, write_import
from ..data.rover_profile import load_profile
from . import dataset_input
from ..errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    add_info_arguments(sub)
    add_compare_arguments(sub)
    add_import_arguments(sub)


def _report_action(sub, name: str, help: str, description: str, folders: dict[str, str], plot: str):
    """An action that reads dataset folders and prints a report: as tables, or as one JSON object (--json),
    and draws it into a PNG on request (--plot)."""
    p = sub.add_parser(name, help=help, description=description)
    for dest, what in folders.items():
        p.add_argument(dest, type=Path, help=what)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.add_argument("--plot", type=Path, metavar="FILE", help=plot)
    return p


def add_info_arguments(sub) -> None:
    _report_action(
        sub, "info", "summarise a dataset folder",
        "Rows and class counts per role and per file, and per-feature summary statistics, of a "
        "dataset folder (one made by 'fleetlab simulate' or 'fleetlab data import', a folder of the original "
        "Fleet-To-Lab CSV files, or a roles .toml file). Windows without labels count in the rows and the "
        "feature statistics; the class mix is shown where labels exist.",
        {"path": "dataset folder"}, "write per-class feature histograms to this PNG")


def add_compare_arguments(sub) -> None:
    p = _report_action(
        sub, "compare", "compare two dataset folders role by role (realism report)",
        "Side by side, per role: class mix, within-traverse persistence (lag-1 slip "
        "autocorrelation, mean same-class run length), per-feature mean and std with the acceleration "
        "convention detected, and SN-S learnability on the target (leave-one-traverse-out, Earth expert "
        "zero-shot, Earth + FullFinetune at |D_Cal| = 150 under both protocols).",
        {"dir_a": "first dataset folder", "dir_b": "second dataset folder"},
        "write per-role class mix and feature means to this PNG")
    p.add_argument("--runs", type=int, default=5, help="D_Cal draws per protocol for Earth + FullFinetune (default 5)")
    p.add_argument("--seed", type=int, default=0, help="model seed (default 0)")
    p.add_argument("--no-learnability", action="store_true", help="statistics only, no model training (fast)")


def add_import_arguments(sub) -> None:
    p = sub.add_parser(
        "import",
        help="turn your rover's logs (rosbag2 MCAP/sqlite3, time-series CSV) into window CSVs + raw samples",
        description="Read each SOURCE (a rosbag2 folder, a bare .mcap or .db3 file, or a folder of time-series "
        "CSVs) as the rover profile describes it, put every stream on one time base from the header stamps at "
        "the estimator's raw rate (linear interpolation, no extrapolation, cut at gaps), take gravity out of the "
        "IMU if it is in, and cut 2 s windows with the 12 features and the slip label by the pipeline's own code. "
        "A folder of time-series CSVs may hold several drives (files paired by their common suffix, else by "
        "time): each is its own log. A log without orientation gets roll and pitch from the IMU's gyro and "
        "accelerometer ([attitude] source = \"imu\"). "
        "Writes one Fleet-To-Lab CSV per log (or per gap-free segment), the raw 7-channel samples beside it "
        "(<name>.raw.npz, for 'fleetlab emulate --source DIR'), dataset.json and import_report.json with every "
        "drop counted. See docs/your_rover.md.",
    )
    p.add_argument("sources", nargs="+", type=Path, metavar="SOURCE", help="rosbag2 folder, .mcap/.db3 file or CSV folder")
    p.add_argument("--rover", required=True, type=Path, metavar="PROFILE.toml", help="rover profile (docs/your_rover.md)")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder (created)")
    p.add_argument("--role", default=UNASSIGNED,
                   help="role of these logs in dataset.json: earth, target or fleet_<rover> (default: "
                   f"{UNASSIGNED}; a roles file can assign it later)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run_import(args: argparse.Namespace) -> int:
    import time

    if args.role != UNASSIGNED and not ROLE_PATTERN.match(args.role):
        raise InputError(f"--role {args.role!r}: expected earth, target or fleet_<rover>")
    profile = load_profile(args.rover)
    t0 = time.perf_counter()
    results = [r for src in args.sources for r in import_source(src, profile, progress=not args.no_progress)]
    elapsed = time.perf_counter() - t0
    if not any(r.segments for r in results):
        raise InputError("no window survived the import: " + "; ".join(
            f"{r.name}: {drop_summary(r.drops)}" for r in results))
    write_import(args.out, results, profile, args.role)
    kept = sum(r.windows_kept for r in results)
    imu = profile.attitude_source == "imu"
    print(f"{'source':40s} {'files':>5s} {'windows':>8s} {'kept':>6s}  " + ("att?  " if imu else "") + "dropped")
    for r in results:
        untrusted = f"{r.attitude_untrusted:4d}  " if imu and r.attitude_untrusted is not None else ("   -  " if imu else "")
        print(f"{r.name[-40:]:40s} {len(r.segments):5d} {r.windows_total:8d} {r.windows_kept:6d}  {untrusted}"
              f"{drop_summary(r.drops)}")
    if imu:
        n = sum(r.attitude_untrusted or 0 for r in results)
        print(f"attitude from the IMU (gyro + accelerometer): {n} of {kept} windows kept are high-dynamic (att?: the "
              "rover turned fast or accelerated in over a quarter of the window, so roll and pitch there lean on the "
              "gyro alone; docs/your_rover.md gives the estimate's accuracy)")
    if profile.attitude_source == "level":
        print(f'warning: {profile.path}: [attitude] source = "level": roll and pitch are taken as 0 and gravity is '
              "taken out as on flat ground; on a slope acc_x and acc_y keep g sin(slope) and the pitch and roll "
              'features say nothing: use source = "imu" (with [imu] gyro_columns) unless the rover only drives flat')
    if profile.linear_wheel_speed:
        print(f"{profile.path}: wheels.velocity_unit = {profile.velocity_unit!r}: the wheel-speed features are the rim "
              "speed in m/s, not rad/s; compare and fuse with data in the same unit")
    for r in results:
        for warning in r.warnings():
            print(f"warning: {warning}")
    for warning in range_warnings(results):
        print(f"warning: {warning}")
    if profile.ground_truth is None:
        print(f"{profile.path}: no [ground_truth]: the windows are UNLABELLED (*.unlabelled.csv, listed apart in "
              "dataset.json); 'fleetlab data info' and 'data compare' show their statistics and they replay through "
              "'fleetlab emulate --source', but they cannot train or evaluate a model")
    print(f"imported {kept} windows from {len(results)} log(s) into {args.out} in {elapsed:.1f} s "
          f"({kept / max(elapsed, 1e-9):.0f} windows/s); role {args.role}")
    return 0


def _fmt(v, spec: str = ".3f") -> str:
    return "—" if v is None else format(v, spec)


def print_report(rep: dict) -> None:
    a, b = rep["a"], rep["b"]
    print(f"A: {a['path']}\nB: {b['path']}")
    roles = list(dict.fromkeys([*a["roles"], *b["roles"]]))
    for role in roles:
        ra, rb = a["roles"].get(role), b["roles"].get(role)
        print(f"\n== {role} ==")
        rows = [("files / rows", lambda r: f"{r['files']} / {r['rows']}")]
        rows.append(("class mix " + "/".join(CLASS_NAMES),
                     lambda r: " / ".join(f"{100 * m:.1f}" for m in r["class_mix"]) if r["class_mix"] else "no labels"))
        rows.append(("slip lag-1 autocorr (mean)", lambda r: _fmt(r["persistence"]["slip_lag1_autocorr_mean"])))
        rows.append(("slip lag-1 autocorr (min..max)", lambda r: f"{_fmt(r['persistence']['slip_lag1_autocorr_min'], '.2f')}"
                     f"..{_fmt(r['persistence']['slip_lag1_autocorr_max'], '.2f')}"))
        rows.append(("mean same-class run (windows)", lambda r: _fmt(r["persistence"]["mean_run_length"], ".1f")))
        rows.append(("acceleration", lambda r: f"{r['acceleration']['convention'].split(' (')[0]}, "
                     f"acc_z {r['acceleration']['mean_acc_z']:+.2f}"))
        for name in FEATURE_NAMES:
            rows.append((name, lambda r, n=name: f"{r['features'][n]['mean']:.3g} ± {r['features'][n]['std']:.3g}"))
        print(f"{'':32s} {'A':>30s} {'B':>30s}")
        for label, get in rows:
            print(f"{label:32s} {get(ra) if ra else '—':>30s} {get(rb) if rb else '—':>30s}")
    if rep.get("warnings"):
        print("\n== features far outside B's range (all windows of each side) ==")
        for line in rep["warnings"]:
            print(f"warning: {line}")
    if "learnability" in rep:
        la, lb = rep["learnability"]["a"], rep["learnability"]["b"]
        print("\n== learnability on the target (SN-S, balanced accuracy) ==")
        for label, key in (("leave-one-traverse-out", "loto_bacc_mean"), ("Earth expert zero-shot", "earth_zero_shot_bacc"),
                           ("Earth + FullFinetune 150, paper", "earth_ft_paper_bacc"),
                           ("Earth + FullFinetune 150, traverse", "earth_ft_traverse_bacc")):
            print(f"{label:36s}{_fmt(la.get(key)):>12s}{_fmt(lb.get(key)):>12s}")


def plot_report(rep: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    roles = list(dict.fromkeys([*rep["a"]["roles"], *rep["b"]["roles"]]))
    fig, axes = plt.subplots(1, 2, figsize=(14, 5))
    for k, side in enumerate(("a", "b")):
        mix = np.array([rep[side]["roles"].get(r, {}).get("class_mix") or [0, 0, 0] for r in roles])
        axes[0].bar(np.arange(len(roles)) + 0.4 * k, mix[:, 0], 0.38, label=f"{side.upper()} {CLASS_NAMES[0]}")
        axes[0].bar(np.arange(len(roles)) + 0.4 * k, mix[:, 1], 0.38, bottom=mix[:, 0], label=f"{side.upper()} {CLASS_NAMES[1]}")
        axes[0].bar(np.arange(len(roles)) + 0.4 * k, mix[:, 2], 0.38, bottom=mix[:, :2].sum(1), label=f"{side.upper()} {CLASS_NAMES[2]}")
        t = rep[side]["roles"].get("target")
        if t:
            means = [t["features"][n]["mean"] / (abs(t["features"][n]["std"]) + 1e-9) for n in FEATURE_NAMES]
            axes[1].plot(means, "o-", label=side.upper())
    axes[0].set_xticks(np.arange(len(roles)) + 0.2, roles, rotation=20)
    axes[0].set_title("class mix per role (A left, B right)")
    axes[0].legend(fontsize=7)
    axes[1].set_xticks(range(len(FEATURE_NAMES)), [n.replace("feat_", "") for n in FEATURE_NAMES], rotation=60)
    axes[1].set_title("target: feature mean / std")
    axes[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run_compare(args: argparse.Namespace) -> int:
    ds_a, ds_b = dataset_input.load(args.dir_a), dataset_input.load(args.dir_b)
    rep = compare_statistics(ds_a, ds_b)
    if not args.no_learnability:
        from ..evaluation.realism import learnability

        try:
            rep["learnability"] = {side: learnability(ds, seed=args.seed, runs=args.runs).as_dict()
                                   for side, ds in (("a", ds_a), ("b", ds_b))}
        except InputError as e:  # a dataset the learnability check cannot use (too few traverses or roles)
            raise InputError(f"{e}; add --no-learnability for the statistics alone") from None
    return _output(rep, args, print_report, lambda path: plot_report(rep, path))


def _mix(counts: list[int]) -> str:
    n = max(sum(counts), 1)
    return " / ".join(f"{c} ({100 * c / n:.0f}%)" for c in counts)


def print_info(s: dict) -> None:
    unlabelled = s["total_rows"] - s["labelled_rows"]
    print(f"{s['path']}: {s['total_rows']} rows in {len(s['files'])} files (roles from {s['recognised_by']})"
          + (f"; {unlabelled} rows without labels (statistics only)" if unlabelled else ""))
    if s["rejected_nonfinite_rows"]:
        print(f"  rejected {s['rejected_nonfinite_rows']} rows holding NaN/Inf")
    print(f"\n{'role':<16}{'files':>6}{'rows':>7}   low / moderate / high")
    for role, r in s["roles"].items():
        mix = _mix(r["classes"]) if r["classes"] is not None else "no labels"
        if r["classes"] is not None and r.get("unlabelled_rows"):
            mix += f" (and {r['unlabelled_rows']} rows without labels)"
        print(f"{role:<16}{r['files']:>6}{r['rows']:>7}   {mix}")
    print(f"\n{'file':<70}{'role':<14}{'rows':>6}   classes")
    for f in s["files"]:
        name = f["file"] if len(f["file"]) < 70 else "…" + f["file"][-68:]
        print(f"{name:<70}{f['role']:<14}{f['rows']:>6}   {f['classes'] if f['classes'] is not None else 'no labels'}")
    print(f"\n{'feature':<20}{'mean':>12}{'std':>12}{'min':>12}{'max':>12}")
    for name, st in s["features"].items():
        print(f"{name:<20}{st['mean']:>12.4g}{st['std']:>12.4g}{st['min']:>12.4g}{st['max']:>12.4g}")


def run_info(args: argparse.Namespace) -> int:
    ds = load_dataset(args.path)
    s = summarise(ds)
    return _output(s, args, print_info, lambda path: plot_histograms(ds, path))


def _output(rep: dict, args: argparse.Namespace, print_text, plot) -> int:
    """The report as one JSON object (--json) or as text tables, then the plot if --plot names a file."""
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        print_text(rep)
    if args.plot:
        plot(args.plot)
        if not args.json:
            print(f"\nwrote {args.plot}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.action == "import":
        return run_import(args)
    return run_compare(args) if args.action == "compare" else run_info(args)
