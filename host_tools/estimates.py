"""`fleetlab emulate --estimates FILE`: what the C estimator answered for each window, written out.

One row per window the estimator reported: its start and end time, class, integer logits,
saturation count, flags, sample count and the log it came from.

- `FILE.csv`: one line per window (`CSV_COLUMNS`).
- `FILE.mcap`: a rosbag2 MCAP file (ROS 2 profile, CDR) in the replayed log's own time base, so it
  opens beside the input bag (Foxglove, `ros2 bag play`, rosbags' AnyReader given both):
  `/slipest/estimate` (`slipest_msgs/msg/SlipEstimate`, one message per window, logged at the
  window's end) and `/diagnostics` (`diagnostic_msgs/msg/DiagnosticArray`, one per STATUS report
  of the estimator: level OK, WARN when it rejected frames, dropped samples or flagged windows,
  ERROR when a window or a counter differs from the reference, with the counters as values).

`slipest_msgs/msg/SlipEstimate` is not a type rosbags knows: it is registered in rosbags' typestore
from `ros_msgs/SlipEstimate.msg` beside this module, its one definition, and the file carries it
as its schema, so any MCAP reader can decode it.

Times: for a `fleetlab data import` folder, the stamp times of the imported log; for the simulator
and other sources, the time from the start of each trace (window k starts at k x 2 s).
"""

from __future__ import annotations

import csv
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fleetlab.data.contracts import CLASS_NAMES, DEFAULT_RATE_HZ
from fleetlab.data.features_int import SAMPLES_PER_WINDOW

from .sources import FeatureSource, TelemetrySource
from fleetlab.errors import InputError

ESTIMATE_TOPIC = "/slipest/estimate"
DIAGNOSTICS_TOPIC = "/diagnostics"
ESTIMATE_TYPE = "slipest_msgs/msg/SlipEstimate"
DIAGNOSTICS_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
MSG_FILE = Path(__file__).with_name("ros_msgs") / "SlipEstimate.msg"
SUFFIXES = (".csv", ".mcap")
WINDOW_NS = round(SAMPLES_PER_WINDOW * 1e9 / DEFAULT_RATE_HZ)  # 100 samples at 50 Hz: 2 s
CSV_COLUMNS = ("window", "source_file", "start_ns", "end_ns", "slip_class", "class_name", "logit_low",
               "logit_moderate", "logit_high", "saturations", "flags", "n_samples", "window_counter", "bit_exact")
OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels


@dataclass(frozen=True)
class EstimateRow:
    window: int  # index in the replayed source
    source_file: str
    start_ns: int
    end_ns: int
    slip_class: int
    logits: tuple[int, int, int]
    saturations: int
    flags: int
    n_samples: int
    window_counter: int
    bit_exact: bool

    @property
    def class_name(self) -> str:
        return CLASS_NAMES[self.slip_class] if self.slip_class < len(CLASS_NAMES) else "invalid"


def check_path(path: Path) -> None:
    """Refuse an output path this module cannot write, before anything runs."""
    if path.suffix not in SUFFIXES:
        raise InputError(f"--estimates {path}: must end in .csv or .mcap")


def window_places(source: TelemetrySource | FeatureSource) -> list[tuple[str, int]]:
    """(the log it came from, start time in ns) of each window of a source."""
    if isinstance(source, FeatureSource):
        return [(source.name, k * WINDOW_NS) for k in range(source.n_windows)]
    places = []
    for name, n in source.traces:
        places += [(source.trace_files.get(name, name), k * WINDOW_NS) for k in range(n)]
    if len(places) != source.n_windows:  # a source without trace bookkeeping: one trace
        places = [(source.name, k * WINDOW_NS) for k in range(source.n_windows)]
    if source.window_start_ns is not None:
        places = [(f, int(t)) for (f, _), t in zip(places, source.window_start_ns)]
    return places


def estimate_rows(result, source: TelemetrySource | FeatureSource) -> list[EstimateRow]:
    """The estimator's answer for each window of a clean (one-lifetime) replay of `source`."""
    if len(result.segments) != 1:
        raise InputError("--estimates writes the estimates of a plain replay (one estimator lifetime); "
                         "drop --restart-every and --inject restart")
    places = window_places(source)
    verdicts = result.segments[0].verdicts
    if len(verdicts) != len(places):
        raise InputError(f"the replay expected {len(verdicts)} windows, the source has {len(places)}")
    rows = []
    for k, (v, (log, start)) in enumerate(zip(verdicts, places)):
        g = v.got
        if g is None:
            continue
        rows.append(EstimateRow(k, log, start, start + WINDOW_NS, g.slip_class, tuple(g.logits or (0, 0, 0)),
                                g.saturations, g.flags, g.n_samples, g.window_counter, v.bit_exact))
    return rows


def write_csv(path: Path, rows: list[EstimateRow]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in rows:
            w.writerow([r.window, r.source_file, r.start_ns, r.end_ns, r.slip_class, r.class_name, *r.logits,
                        r.saturations, r.flags, r.n_samples, r.window_counter, int(r.bit_exact)])


def typestore():
    """rosbags' ROS 2 typestore with slipest_msgs/msg/SlipEstimate registered from its .msg file."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(MSG_FILE.read_text(), ESTIMATE_TYPE))
    return ts


def _diagnostics(result, rows: list[EstimateRow]) -> list[tuple[int, int, str, dict[str, str]]]:
    """(time ns, level, message, values) of each STATUS report the estimator sent, at the end of the last
    window it had finished by then."""
    seg = result.segments[0]
    ends = {r.window: r.end_ns for r in rows}
    last_end = rows[-1].end_ns if rows else 0
    exact = np.cumsum([v.bit_exact for v in seg.verdicts])
    final_problems = list(seg.status_problems) + list(result.model_hash_problems) + list(result.host_rx_errors)
    out = []
    for k, st in enumerate(seg.statuses):
        done = min(st.windows_done, len(seg.verdicts))
        t = ends.get(done - 1, last_end) if done else (rows[0].start_ns if rows else 0)
        differ = done - int(exact[done - 1]) if done else 0
        final = k == len(seg.statuses) - 1
        problems = ([f"{differ} of {done} windows differ from the torch integer reference"] if differ else []) + (
            final_problems if final else [])
        if problems:
            level, message = ERROR, "; ".join(problems)
        elif st.frames_rejected or st.samples_dropped or st.windows_flagged:
            level, message = WARN, (f"{st.frames_rejected} frames rejected, {st.samples_dropped} samples dropped, "
                                    f"{st.windows_flagged} windows flagged")
        else:
            level, message = OK, f"{done} windows, all bit-exact with the torch integer reference"
        values = {"windows_done": st.windows_done, "frames_received": st.frames_received,
                  "frames_rejected": st.frames_rejected, "samples_dropped": st.samples_dropped,
                  "windows_flagged": st.windows_flagged, "windows_bit_exact": int(exact[done - 1]) if done else 0,
                  "model_hash": f"{st.model_hash:08x}", "lib_version": f"{st.lib_version:#06x}"}
        out.append((int(t), level, message, {key: str(v) for key, v in values.items()}))
    return out


def write_mcap(path: Path, rows: list[EstimateRow], result) -> None:
    """A rosbag2 MCAP file: the estimates and the estimator's diagnostics (see the module doc)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = typestore()
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Est = T[ESTIMATE_TYPE]

    def time(ns: int):
        return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

    hardware = f"slipest over {result.link}"
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.stem}.") as tmp:
        bag = Path(tmp) / path.stem
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            est = w.add_connection(ESTIMATE_TOPIC, ESTIMATE_TYPE, typestore=ts)
            diag = w.add_connection(DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE, typestore=ts)
            messages = []
            for r in rows:
                msg = Est(header=Header(stamp=time(r.end_ns), frame_id="base_link"), window_start=time(r.start_ns),
                          window_end=time(r.end_ns), window=r.window, window_counter=r.window_counter,
                          slip_class=r.slip_class, class_name=r.class_name,
                          logits=np.array(r.logits, dtype=np.int32), saturations=r.saturations, flags=r.flags,
                          n_samples=min(r.n_samples, 255), source_file=r.source_file)
                messages.append((r.end_ns, 0, est, ts.serialize_cdr(msg, ESTIMATE_TYPE)))
            for t, level, message, values in _diagnostics(result, rows):
                status = T["diagnostic_msgs/msg/DiagnosticStatus"](
                    level=level, name="slipest: estimator", message=message, hardware_id=hardware,
                    values=[T["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in values.items()])
                arr = T[DIAGNOSTICS_TYPE](header=Header(stamp=time(t), frame_id=""), status=[status])
                messages.append((t, 1, diag, ts.serialize_cdr(arr, DIAGNOSTICS_TYPE)))
            for t, _, conn, data in sorted(messages, key=lambda m: (m[0], m[1])):
                w.write(conn, t, data)
        shutil.move(str(bag / f"{path.stem}.mcap"), path)


def write_estimates(path: Path | str, result, source: TelemetrySource | FeatureSource) -> list[EstimateRow]:
    """Each window's estimate of an emulation run to `path` (.csv or .mcap, see the module doc)."""
    path = Path(path)
    check_path(path)
    rows = estimate_rows(result, source)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".csv":
        write_csv(path, rows)
    else:
        write_mcap(path, rows, result)
    return rows
