"""`fleetlab data import`: a rover's own log -> Fleet-To-Lab window CSVs plus the raw 7-channel samples.

Streams (log_sources) go onto one time base (timebase) at the estimator's raw rate;
gravity is taken out of the IMU with the attitude; windows, features and labels come
from `features.featurise_trace`, the same code the simulator uses. Per gap-free
segment: one CSV (`<stem>.csv`, or `<stem>_segNN.csv` when the log has gaps) and
beside it `<stem>.raw.npz` with the samples of the windows kept, window after window,
for `fleetlab emulate --source DIR`.

A folder of time-series CSVs may hold several drives (`timeseries_csv`): each is imported on its
own, as `<folder>_<suffix>` (`import_source`). Without an attitude in the log, roll and pitch are
estimated from the IMU (`attitude.estimate_attitude`, `[attitude] source = "imu"`) or taken as 0
(`source = "level"`), then used like a logged attitude.

Dropped and counted per file: messages (nonfinite, non_numeric (a CSV cell that is not a number),
backwards_stamps, saturated_messages, incomplete), gaps (gaps, gap_s), windows (short_windows: a stream
gave fewer than MIN_SAMPLES_PER_WINDOW messages in it; saturated_windows: a sample the int16 CAN
units cannot carry, with saturated_windows_<channel> naming the channel), and segments too short for
one window (short_segments).
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .contracts import CH, DEFAULT_RATE_HZ, FEATURE_NAMES, MIN_SAMPLES_PER_WINDOW, N_CHANNELS, RAW_CHANNELS
from .csvio import UNLABELLED_COLUMNS, UNLABELLED_SUFFIX, WindowTable, write_windows_csv
from .dataset import write_manifest
from .features import LabelledWindows, WindowSpec, featurise_trace
from .attitude import UNTRUSTED_SHARE, estimate_attitude
from .features_int import saturated_values
from .log_sources import read_log, source_kind
from .reference_ranges import import_range_warnings
from .rover_profile import RoverProfile
from .timeseries_csv import read_csv_drives
from .timebase import NS, Stream, clean, grid, messages_per_window, resample, segments
from ..errors import InputError

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
    notes: list[str] = field(default_factory=list)  # what the reader says about the log itself (a salvaged bag)
    drive: str | None = None  # the drive of a CSV folder of several (its files' common suffix), else None
    files: list[str] = field(default_factory=list)  # the CSV files of this drive, relative to the folder
    attitude_untrusted: int | None = None  # with [attitude] source = "imu": kept windows of high dynamics

    @property
    def name(self) -> str:
        """The log as the summary names it: the source, and the drive of a folder of several."""
        return f"{self.source} [{self.drive}]" if self.drive else str(self.source)

    @property
    def windows_kept(self) -> int:
        return sum(len(s.windows.label) for s in self.segments)

    def warnings(self) -> list[str]:
        """What the reader said about the log (a bag salvaged after a crash), then signs of a profile that
        does not fit the log (the import itself went through)."""
        if not self.segments:
            return list(self.notes)
        acc_z = np.concatenate([s.windows.features[:, FEATURE_NAMES.index("feat_acc_z_mean")] for s in self.segments])
        if abs(acc_z.mean()) > GRAVITY_LEFT_M_S2:
            return self.notes + [f"{self.name}: mean acc_z is {acc_z.mean():+.2f} m/s^2 after the import; "
                                 "gravity-free acceleration averages about 0: check imu.includes_gravity and "
                                 "imu.gravity_m_s2"]
        return list(self.notes)

    def features(self) -> np.ndarray:
        """(kept windows, 12) features of every segment."""
        return np.concatenate([s.windows.features for s in self.segments]) if self.segments else np.empty((0, 12))


def _subset(w: LabelledWindows, keep: np.ndarray) -> LabelledWindows:
    return dataclasses.replace(w, **{f.name: getattr(w, f.name)[keep] for f in dataclasses.fields(w)})


def _segment_windows(streams: dict[str, Stream], profile: RoverProfile, span: tuple[int, int], rate_hz: float,
                     drops: Counter, dynamic: Stream | None = None
                     ) -> tuple[LabelledWindows, np.ndarray, np.ndarray, np.ndarray] | None:
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
    d_cmd = samples[:, CH["wheel_speed"]] * profile.metres_per_wheel_speed / rate_hz
    if "ground_truth" in streams:  # sample i travels from grid point i to i + 1 (segments() left room for it)
        pos = resample(streams["ground_truth"], grid(span[0], span[1], rate_hz, extra=1)) * profile.position_scale
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
    per_channel = saturated_values(samples)[rows].any(axis=1) & ~sparse[:, None]  # (windows, 7)
    saturated = per_channel.any(axis=1)
    drops["short_windows"] += int(np.count_nonzero(sparse))
    drops["saturated_windows"] += int(np.count_nonzero(saturated))
    for c, name in enumerate(RAW_CHANNELS):
        drops[f"saturated_windows_{name}"] += int(np.count_nonzero(per_channel[:, c]))
    keep = ~(sparse | saturated)
    if dynamic is not None:  # share of high-dynamic IMU messages in each kept window
        first = np.searchsorted(dynamic.t_ns, starts, side="left")
        last = np.searchsorted(dynamic.t_ns, starts + length, side="left")
        flagged = np.concatenate([[0], np.cumsum(dynamic.values[:, 0] > 0)])
        share = (flagged[last] - flagged[first]) / np.maximum(last - first, 1)
        drops["attitude_untrusted_windows"] += int(np.count_nonzero((share > UNTRUSTED_SHARE) & keep))
    return _subset(w, keep), samples[rows[keep].ravel()], starts[keep], keep


def _clean(raw: dict[str, Stream], profile: RoverProfile, drops: Counter) -> dict[str, Stream]:
    """Drop and count bad messages. Streams of one group (sections read from the same CSV rows) are cleaned
    together, so a bad row counts once and leaves every section it feeds."""
    limits = {}
    if profile.imu_range_m_s2:  # the sensor's range bounds the accelerometer columns, not the gyro's
        width = raw["imu"].values.shape[1]
        limits["imu"] = np.where(np.arange(width) < 3, profile.imu_range_m_s2 / profile.acc_scale, np.inf)
    groups: dict[str, list[str]] = {}
    for name, s in raw.items():
        groups.setdefault(s.group or name, []).append(name)
    out = {}
    for names in groups.values():
        widths = [raw[n].values.shape[1] for n in names]
        merged = Stream(names[0], raw[names[0]].t_ns, np.hstack([raw[n].values for n in names]))
        limit = (np.concatenate([np.broadcast_to(limits.get(n, np.inf), (w,)) for n, w in zip(names, widths)])
                 if any(n in limits for n in names) else None)
        kept = clean(merged, drops, limit)
        col = 0
        for n, w in zip(names, widths):
            out[n] = Stream(n, kept.t_ns, kept.values[:, col:col + w])
            col += w
    return out


def _attitude(streams: dict[str, Stream], profile: RoverProfile) -> Stream | None:
    """Without an attitude in the log: roll and pitch at the IMU's stamps, from the IMU or level; the IMU
    stream keeps its accelerometer columns only. Returns the high-dynamics flags (source "imu")."""
    imu = streams["imu"]
    if profile.attitude_source == "level":
        streams["attitude"] = Stream("attitude", imu.t_ns, np.zeros((len(imu), 2)))
        return None
    if profile.attitude_source != "imu":
        return None
    est = estimate_attitude(imu.t_ns, imu.values[:, :3] * profile.acc_scale, imu.values[:, 3:6] * profile.gyro_scale,
                            profile.gravity_m_s2, profile.max_gap_s)
    streams["attitude"] = Stream("attitude", imu.t_ns, np.column_stack([est.roll, est.pitch]))
    streams["imu"] = Stream("imu", imu.t_ns, imu.values[:, :3])
    return Stream("dynamic", imu.t_ns, est.dynamic[:, None].astype(np.float64))


def _import_streams(source: Path, stem: str, raw: dict[str, Stream], drops: Counter, notes: list[str],
                    profile: RoverProfile, rate_hz: float) -> ImportResult:
    streams = _clean(raw, profile, drops)
    for name, s in streams.items():
        if len(s) < 2:
            where = profile.streams[name].topic or profile.streams[name].csv.file
            raise InputError(f"{source}: the {name} stream ({where}) has {len(s)} usable message(s) "
                             f"(dropped: {drop_summary(drops)}); nothing to import" + "".join(f" [{n}]" for n in notes))
    dynamic = _attitude(streams, profile)
    step_ns = int(np.ceil(NS / rate_hz))
    spans = segments(list(streams.values()), profile.max_gap_s, drops, {"ground_truth": step_ns})
    parts = []
    total = 0
    for span in spans:
        out = _segment_windows(streams, profile, span, rate_hz, drops, dynamic)
        if out is None:
            continue
        w, samples, starts, keep = out
        total += len(keep)
        if len(w.label):
            parts.append((w, samples, starts))
    segs = [Segment(stem if len(parts) == 1 else f"{stem}_seg{k + 1:02d}", w, s, st, "ground_truth" in streams)
            for k, (w, s, st) in enumerate(parts)]
    untrusted = drops.pop("attitude_untrusted_windows", 0) if dynamic is not None else None
    return ImportResult(source, segs, drops, total, notes, attitude_untrusted=untrusted)


def import_source(source: Path | str, profile: RoverProfile, rate_hz: float = DEFAULT_RATE_HZ,
                  progress: bool = True) -> list[ImportResult]:
    """Read, clean, put on one time base and window one log: a bag, or a folder of time-series CSVs, whose
    drives (`timeseries_csv`) each give one result, named `<folder>_<drive>`."""
    source = Path(source)
    stem = source.stem if source.is_file() else source.name
    if source_kind(source) == "bag" or profile.kind == "bag":
        notes: list[str] = []
        raw, drops = read_log(source, profile, progress, notes)
        return [_import_streams(source, stem, raw, drops, notes, profile, rate_hz)]
    notes = []
    drives = read_csv_drives(source, profile, progress, notes)
    results = []
    for d in drives:
        try:
            res = _import_streams(source, stem if d.name is None else f"{stem}_{d.name}", d.streams, d.drops,
                                  notes if d is drives[0] else [], profile, rate_hz)
        except ValueError as e:
            if len(drives) == 1:
                raise
            res = ImportResult(source, [], d.drops, 0, [f"{e} (drive {d.name} left out)"])
        res.drive, res.files = d.name, d.files
        results.append(res)
    return results


def import_log(source: Path | str, profile: RoverProfile, rate_hz: float = DEFAULT_RATE_HZ,
               progress: bool = True) -> ImportResult:
    """`import_source` of a log that holds one drive (a bag, or a CSV folder of one drive)."""
    results = import_source(source, profile, rate_hz, progress)
    if len(results) != 1:
        raise InputError(f"{source}: holds {len(results)} drives ({', '.join(r.drive or '?' for r in results)}); "
                         "import_source imports each")
    return results[0]


def range_warnings(results: list[ImportResult]) -> list[str]:
    """Features of the imported windows far outside the reference data's range (`reference_ranges`)."""
    x = np.concatenate([r.features() for r in results]) if results else np.empty((0, 12))
    return import_range_warnings(x) if len(x) else []


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
    """Window CSVs, raw samples, dataset.json (labelled files with `role` under `files`; unlabelled ones,
    for `data info` and `data compare` only, under `unlabelled_files`) and import_report.json."""
    stems = [seg.stem for res in results for seg in res.segments]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise InputError(f"two logs would both write {twice[0]}.csv; import them into different folders or rename one")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files, unlabelled, report = {}, {}, []
    for res in results:
        for seg in res.segments:
            table = WindowTable.from_windows(seg.windows)
            name = f"{seg.stem}.csv" if seg.labelled else f"{seg.stem}{UNLABELLED_SUFFIX}"
            if seg.labelled:
                write_windows_csv(out / name, table)
            else:
                _write_unlabelled_csv(out / name, seg.windows)
            np.savez_compressed(out / f"{seg.stem}{RAW_SUFFIX}", samples=seg.samples, window_start_ns=seg.window_start_ns,
                                rate_hz=rate_hz, channels=np.array(RAW_CHANNELS), labelled=seg.labelled)
            entry = {"role": role, "rover": profile.name, "source": str(res.source), "raw": seg.stem + RAW_SUFFIX,
                     "windows": len(table)}
            if seg.labelled:
                files[name] = {**entry, "class_counts": table.class_counts()}
            else:
                unlabelled[name] = entry
        log = {"source": str(res.source), "files": [s.stem for s in res.segments],
               "windows_cut": res.windows_total, "windows_kept": res.windows_kept,
               "labelled": bool(res.segments and res.segments[0].labelled),
               "drops": {k: v for k, v in sorted(res.drops.items()) if v}, "notes": res.notes}
        if res.drive is not None:
            log.update(drive=res.drive, csv_files=res.files)
        if res.attitude_untrusted is not None:
            log["attitude"] = {"source": profile.attitude_source, "untrusted_windows": res.attitude_untrusted}
        report.append(log)
    write_manifest(out, files, {"generator": "fleetlab data import", "profile": str(profile.path), "rate_hz": rate_hz,
                                "unlabelled_files": unlabelled})
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
        raise InputError(f"{folder}: not a 'fleetlab data import' folder ({REPORT_NAME}: {e})") from None
    return [folder / f"{stem}{RAW_SUFFIX}" for log in logs for stem in log["files"]]


def read_raw(path: Path | str) -> tuple[np.ndarray, float]:
    """Raw samples (n, 7) of one imported segment and their rate."""
    with np.load(path) as z:
        if tuple(z["channels"]) != RAW_CHANNELS:
            raise InputError(f"{path}: channels {tuple(z['channels'])} are not {RAW_CHANNELS}")
        return np.asarray(z["samples"], dtype=np.float64), float(z["rate_hz"])
