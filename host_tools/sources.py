"""Where streamed data comes from: the simulator, a bundle's test vectors, an imported log, a CSV folder, a CAN log.

Telemetry sources give int16 raw samples (whole windows only, like the Python
featuriser, which drops a trailing partial window); feature sources give int16
feature vectors in raw LSB units (`quantize_features`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from fleetlab.data.features_int import SAMPLES_PER_WINDOW, quantize_features, quantize_samples
from fleetlab.errors import InputError, first_line

from .wire.dbc import Frame


@dataclass
class TelemetrySource:
    name: str
    samples_q: np.ndarray  # (n,7) int16, n a multiple of 100
    traces: list[tuple[str, int]]  # (trace name, windows it contributes)
    window_start_ns: np.ndarray | None = None  # (n_windows,) time of each window's first sample (imported logs)
    trace_files: dict[str, str] = field(default_factory=dict)  # trace name -> the log it came from (imported logs)

    @property
    def n_windows(self) -> int:
        return len(self.samples_q) // SAMPLES_PER_WINDOW


@dataclass
class FeatureSource:
    name: str
    feat_q: np.ndarray  # (N,12) int16

    @property
    def n_windows(self) -> int:
        return len(self.feat_q)


def sim_source(seed: int, scale: float) -> TelemetrySource:
    """The built-in fleet scenario, each traverse cut to whole windows and streamed back to back.

    Windows of consecutive traverses line up with the estimator's grid, so one continuous
    stream gives exactly the windows of every traverse.
    """
    try:
        from fleetlab.data.simulator import scenario_traces
    except ImportError:  # older layout: only the scenario module exports it
        from fleetlab.data.simulator.scenario import scenario_traces

    parts, traces = [], []
    for role, name, trace in scenario_traces(seed=seed, scale=scale):
        q = quantize_samples(np.asarray(trace.samples))
        n = len(q) - len(q) % SAMPLES_PER_WINDOW
        if n:
            parts.append(q[:n])
            traces.append((f"{role}/{name}", n // SAMPLES_PER_WINDOW))
    if not parts:
        raise InputError(f"the simulator gave no whole window at scale {scale}")
    return TelemetrySource(f"sim(seed={seed}, scale={scale})", np.concatenate(parts).astype(np.int16), traces)


def vectors_source(bundle_dir: Path | str) -> FeatureSource:
    """The bundle's test vectors (`q_inputs`), checked by the bundle loader."""
    from fleetlab.export.bundle import load_bundle
    from fleetlab.export.vectors import read_vectors

    load_bundle(bundle_dir)  # verifies every file's hash first
    q = np.asarray(read_vectors(Path(bundle_dir)).q_inputs, dtype=np.int16)
    return FeatureSource(f"vectors({bundle_dir})", q)


def csv_dir_source(path: Path | str) -> FeatureSource:
    """Every window row of the Fleet-To-Lab CSV files in a folder (sorted by name)."""
    from fleetlab.data.csvio import WindowTable, read_windows_csv

    root = Path(path)
    files = sorted(root.glob("*.csv"))
    if not files:
        raise InputError(f"{root}: no *.csv window files")
    table = WindowTable.concat([read_windows_csv(f) for f in files])
    # rows holding NaN/Inf cannot be sent as features: the reader drops them, and the name says how many
    dropped = f", {table.rejected_nonfinite} rows with NaN/Inf dropped" if table.rejected_nonfinite else ""
    return FeatureSource(f"csv({root}, {len(files)} files{dropped})", quantize_features(table.features))


def imported_source(path: Path | str) -> TelemetrySource:
    """The raw samples of a `fleetlab data import` folder (its `*.raw.npz`, in import order), back to back.

    Each file holds whole windows only (the windows of its CSV, in order), so the estimator's
    own windowing of the stream gives exactly the imported windows.
    """
    from fleetlab.data.contracts import DEFAULT_RATE_HZ
    from fleetlab.data.log_import import RAW_SUFFIX, raw_files, read_raw

    root = Path(path)
    parts, traces, starts = [], [], []
    for f in raw_files(root):
        samples, rate = read_raw(f)
        if rate != DEFAULT_RATE_HZ or len(samples) % SAMPLES_PER_WINDOW:
            raise InputError(f"{f}: {len(samples)} samples at {rate:g} Hz are not whole windows of the estimator "
                             f"({SAMPLES_PER_WINDOW} samples at {DEFAULT_RATE_HZ:g} Hz)")
        if len(samples):
            parts.append(quantize_samples(samples))
            traces.append((f.name[: -len(RAW_SUFFIX)], len(samples) // SAMPLES_PER_WINDOW))
            with np.load(f) as z:
                starts.append(np.asarray(z["window_start_ns"], dtype=np.int64))
    if not parts:
        raise InputError(f"{root}: no imported raw samples (*{RAW_SUFFIX}); make them with 'fleetlab data import'")
    return TelemetrySource(f"import({root}, {len(parts)} files)", np.concatenate(parts).astype(np.int16), traces,
                           np.concatenate(starts), _imported_logs(root))


def _imported_logs(root: Path) -> dict[str, str]:
    """File stem -> the log (bag, CSV folder) it was imported from, by the folder's import report."""
    import json

    from fleetlab.data.log_import import REPORT_NAME

    logs = json.loads((root / REPORT_NAME).read_text())["logs"]
    return {stem: log["source"] for log in logs for stem in log["files"]}


def log_messages(path: Path | str) -> Iterator:
    """The messages of a python-can log (.log candump, .asc, .blf, ...), error frames included.

    python-can's readers raise whatever their parsing meets (a candump line without its three fields
    is "not enough values to unpack"): here that is one line naming the file and how far it was read."""
    import can

    p = Path(path)
    if not p.is_file():
        raise OSError(f"{p}: no such log file")
    try:
        messages = iter(can.LogReader(str(p)))
    except Exception as e:  # an unknown suffix, an unreadable header
        raise InputError(f"{p}: not a python-can log ({type(e).__name__}: {first_line(e)})") from None
    read = 0
    while True:
        try:
            msg = next(messages)
        except StopIteration:
            return
        except Exception as e:
            raise InputError(f"{p}: malformed python-can log after {read} frames "
                             f"({type(e).__name__}: {first_line(e)})") from None
        read += 1
        yield msg


def log_frames(path: Path | str, skipped: Counter | None = None) -> Iterator[tuple[Frame, float]]:
    """Standard-ID data frames of a python-can log with their timestamps (the DBC has no other kind);
    the others are counted in `skipped`."""
    for msg in log_messages(path):
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            if skipped is not None:
                skipped["error, remote or extended-ID frames"] += 1
            continue
        yield Frame(msg.arbitration_id, bytes(msg.data)), float(msg.timestamp)


LOG_SUFFIXES = (".log", ".asc", ".blf", ".trc", ".mf4")


def resolve(spec: str, seed: int, scale: float, bundle: Path | str | None) -> TelemetrySource | FeatureSource:
    """`sim`, `vectors` (needs the bundle), an imported-log folder (raw samples) or a CSV folder."""
    if spec == "sim":
        return sim_source(seed, scale)
    if spec == "vectors":
        if bundle is None:
            raise InputError("--source vectors needs --bundle")
        return vectors_source(bundle)
    p = Path(spec)
    if p.is_dir():
        from fleetlab.data.log_import import REPORT_NAME

        return imported_source(p) if (p / REPORT_NAME).exists() else csv_dir_source(p)
    raise InputError(f"--source {spec!r}: expected 'sim', 'vectors', a 'fleetlab data import' folder (raw samples "
                     "replayed) or a folder of window CSV files")
