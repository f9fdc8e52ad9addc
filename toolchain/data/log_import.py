"""`fleetlab data import`: a rover's own log -> Fleet-To-Lab window CSVs plus the raw 7-channel samples.

Streams (log_sources) go onto one time base (timebase) at the estimator's raw rate;
gravity is taken out of the IMU with the attitude; windows, features and labels come
from `features.featurise_trace`, the same code the simulator uses. Per gap-free
segment: one CSV (`<stem>.csv`, or `<stem>_segNN.csv` when the log has gaps) and
beside it `<stem>.raw.npz` with the samples of the windows kept, window after window,
for `fleetlab emulate --source DIR`.

Dropped and counted per file: messages (nonfinite, backwards_stamps, saturated_messages,
incomplete), gaps (gaps, gap_s), windows (short_windows: a stream gave fewer than
MIN_SAMPLES_PER_WINDOW messages in it; saturated_windows: a sample the int16 CAN
units cannot carry), and segments too short for one window (short_segments).
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .contracts import CH, DEFAULT_RATE_HZ, FEATURE_NAMES, MIN_SAMPLES_PER_WINDOW, N_CHANNELS, RAW_CHANNELS
from .csvio import WindowTable, write_windows_csv
from .dataset import write_manifest
from .features import LabelledWindows, WindowSpec, featurise_trace
from .features_int import saturated_rows
from .log_sources import read_log
from .rover_profile import RoverProfile
from .timebase import NS, Stream, clean, grid, messages_per_window, resample, segments

RAW_SUFFIX = ".raw.npz"
GRAVITY_LEFT_M_S2 = 0.5  # |mean acc_z| above this after the import: gravity left in (or taken out twice)
REPORT_NAME = "import_report.json"
UNASSIGNED = "unassigned"


def gravity_body(roll: np.ndarray, pitch: np.ndarray, g: float) -> np.ndarray:
    """(n, 3) what an accelerometer at rest reads from gravity, REP-103 body frame (x fwd, y left, z up)."""
    return g * np.column_stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll), np.cos(pitch) * np.cos(roll)])


@dataclass
class Segment:
    """One gap-free part of a log, windowed."""

    stem: str
    windows: LabelledWindows  # kept windows only
    samples: np.ndarray  # (kept * samples_per_window, 7) physical units, window after window
    window_start_ns: np.ndarray  # (kept,) header-stamp time of each kept window's first sample
    labelled: bool


@dataclass
class ImportResult:
    source: Path
    segments: list[Segment]
    drops: Counter
    windows_total: int  # windows cut before drops

    @property
    def windows_kept(self) -> int:
        return sum(len(s.windows.label) for s in self.segments)

    def warnings(self) -> list[str]:
        """Signs of a profile that does not fit the log (the import itself went through)."""
        if not self.segments:
            return []
        acc_z = np.concatenate([s.windows.features[:, FEATURE_NAMES.index("feat_acc_z_mean")] for s in self.segments])
        if abs(acc_z.mean()) > GRAVITY_LEFT_M_S2:
            return [f"{self.source}: mean acc_z is {acc_z.mean():+.2f} m/s^2 after the import; gravity-free "
                    "acceleration averages about 0: check imu.includes_gravity and imu.gravity_m_s2"]
        return []


def _subset(w: LabelledWindows, keep: np.ndarray) -> LabelledWindows:
    return dataclasses.replace(w, **{f.name: getattr(w, f.name)[keep] for f in dataclasses.fields(w)})


def _segment_windows(streams: dict[str, Stream], profile: RoverProfile, span: tuple[int, int], rate_hz: float,
                     drops: Counter) -> tuple[LabelledWindows, np.ndarray, np.ndarray, np.ndarray] | None:
    """Samples and labelled windows of one segment; windows failing a rule are dropped and counted."""
    t = grid(span[0], span[1], rate_hz)
    n = len(t)
    spec = WindowSpec.for_rate(rate_hz)
    if spec.n_windows(n) == 0:
        drops["short_segments"] += 1
        drops["short_segment_s"] += (span[1] - span[0]) / NS
        return None
    wheels = resample(streams["wheels"], t)
    acc = resample(streams["imu"], t) * profile.acc_scale
    att = resample(streams["attitude"], t)
    if profile.includes_gravity:
        acc = acc - gravity_body(att[:, 0], att[:, 1], profile.gravity_m_s2)
    samples = np.empty((n, N_CHANNELS))
    samples[:, [CH["wheel_speed"], CH["motor_current"]]] = wheels
    samples[:, [CH["acc_x"], CH["acc_y"], CH["acc_z"]]] = acc
    samples[:, [CH["roll"], CH["pitch"]]] = att
    d_cmd = samples[:, CH["wheel_speed"]] * profile.wheel_radius_m / rate_hz
    if "ground_truth" in streams:  # sample i travels from grid point i to i + 1 (segments() left room for it)
        pos = resample(streams["ground_truth"], grid(span[0], span[1], rate_hz, extra=1))
        d_act = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    else:
        d_act = np.zeros(n)
    w = featurise_trace(samples, d_act, d_cmd, rate_hz)
    n_win = len(w.label)
    starts = t[np.arange(n_win) * spec.samples_per_stride]
    length = int(round(spec.samples_per_window * NS / rate_hz))
    sparse = np.zeros(n_win, dtype=bool)
    for s in streams.values():
        sparse |= messages_per_window(s.t_ns, starts, length) < MIN_SAMPLES_PER_WINDOW
    rows = np.arange(n_win)[:, None] * spec.samples_per_stride + np.arange(spec.samples_per_window)
    saturated = saturated_rows(samples)[rows].any(axis=1) & ~sparse
    drops["short_windows"] += int(np.count_nonzero(sparse))
    drops["saturated_windows"] += int(np.count_nonzero(saturated))
    keep = ~(sparse | saturated)
    return _subset(w, keep), samples[rows[keep].ravel()], starts[keep], keep


def import_log(source: Path | str, profile: RoverProfile, rate_hz: float = DEFAULT_RATE_HZ,
               progress: bool = True) -> ImportResult:
    """Read, clean, put on one time base and window one log (a bag or a CSV folder)."""
    source = Path(source)
    raw, drops = read_log(source, profile, progress)
    limit = {"imu": profile.imu_range_m_s2 / profile.acc_scale} if profile.imu_range_m_s2 else {}
    streams = {name: clean(s, drops, limit.get(name)) for name, s in raw.items()}
    for name, s in streams.items():
        if len(s) < 2:
            where = profile.streams[name].topic or profile.streams[name].csv.file
            raise ValueError(f"{source}: the {name} stream ({where}) has {len(s)} usable message(s) "
                             f"(dropped: {drop_summary(drops)}); nothing to import")
    step_ns = int(np.ceil(NS / rate_hz))
    spans = segments(list(streams.values()), profile.max_gap_s, drops, {"ground_truth": step_ns})
    stem = source.stem if source.is_file() else source.name
    parts = []
    total = 0
    for span in spans:
        out = _segment_windows(streams, profile, span, rate_hz, drops)
        if out is None:
            continue
        w, samples, starts, keep = out
        total += len(keep)
        if len(w.label):
            parts.append((w, samples, starts))
    segs = [Segment(stem if len(parts) == 1 else f"{stem}_seg{k + 1:02d}", w, s, st, "ground_truth" in streams)
            for k, (w, s, st) in enumerate(parts)]
    return ImportResult(source, segs, drops, total)


UNLABELLED_COLUMNS = FEATURE_NAMES + ("total_dist_cmd", "n_samples", "win_duration_s")


def _write_unlabelled_csv(path: Path, w: LabelledWindows) -> None:
    """Features of windows without ground truth: no label columns at all, so no reader takes them for labels."""
    cols = np.column_stack([w.features, w.d_commanded, w.n_samples, w.duration_s])
    np.savetxt(path, cols, delimiter=",", header=",".join(UNLABELLED_COLUMNS), comments="", fmt="%.17g")


def drop_summary(drops: Counter) -> str:
    """`name count, ...` of every non-zero drop counter (seconds with one decimal)."""
    items = [f"{k} {v:.1f}" if k.endswith("_s") else f"{k} {v}" for k, v in sorted(drops.items()) if v]
    return ", ".join(items) or "none"


def write_import(out: Path | str, results: list[ImportResult], profile: RoverProfile, role: str,
                 rate_hz: float = DEFAULT_RATE_HZ) -> Path:
    """Window CSVs, raw samples, dataset.json (labelled files with `role`) and import_report.json."""
    stems = [seg.stem for res in results for seg in res.segments]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise ValueError(f"two logs would both write {twice[0]}.csv; import them into different folders or rename one")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files, report = {}, []
    for res in results:
        for seg in res.segments:
            table = WindowTable.from_windows(seg.windows)
            name = f"{seg.stem}.csv" if seg.labelled else f"{seg.stem}.unlabelled.csv"
            if seg.labelled:
                write_windows_csv(out / name, table)
            else:
                _write_unlabelled_csv(out / name, seg.windows)
            np.savez_compressed(out / f"{seg.stem}{RAW_SUFFIX}", samples=seg.samples, window_start_ns=seg.window_start_ns,
                                rate_hz=rate_hz, channels=np.array(RAW_CHANNELS), labelled=seg.labelled)
            if seg.labelled:
                files[name] = {"role": role, "rover": profile.name, "source": str(res.source), "raw": seg.stem + RAW_SUFFIX,
                               "windows": len(table), "class_counts": table.class_counts()}
        report.append({"source": str(res.source), "files": [s.stem for s in res.segments],
                       "windows_cut": res.windows_total, "windows_kept": res.windows_kept,
                       "labelled": bool(res.segments and res.segments[0].labelled),
                       "drops": {k: v for k, v in sorted(res.drops.items()) if v}})
    write_manifest(out, files, {"generator": "fleetlab data import", "profile": str(profile.path), "rate_hz": rate_hz})
    (out / REPORT_NAME).write_text(json.dumps({"rate_hz": rate_hz, "profile": str(profile.path), "logs": report},
                                              indent=2) + "\n")
    return out


def raw_files(folder: Path | str) -> list[Path]:
    """The raw-sample files of an import folder, in import order (from import_report.json, so files
    left over from an earlier import into the same folder are never replayed)."""
    folder = Path(folder)
    try:
        logs = json.loads((folder / REPORT_NAME).read_text())["logs"]
    except (OSError, ValueError, KeyError) as e:
        raise ValueError(f"{folder}: not a 'fleetlab data import' folder ({REPORT_NAME}: {e})") from None
    return [folder / f"{stem}{RAW_SUFFIX}" for log in logs for stem in log["files"]]


def read_raw(path: Path | str) -> tuple[np.ndarray, float]:
    """Raw samples (n, 7) of one imported segment and their rate."""
    with np.load(path) as z:
        if tuple(z["channels"]) != RAW_CHANNELS:
            raise ValueError(f"{path}: channels {tuple(z['channels'])} are not {RAW_CHANNELS}")
        return np.asarray(z["samples"], dtype=np.float64), float(z["rate_hz"])
