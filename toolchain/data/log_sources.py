"""Read a rover's log into one `Stream` per profile section: rosbag2 (MCAP or sqlite3) or time-series CSV.

Each stream carries the header stamps and, per message, the section's channels in
physical units:
  wheels:       wheel_speed (mean |velocity| over the profile's joints, rad/s),
                motor_current (mean |effort| x current_per_effort, A)
  imu:          acc_x, acc_y, acc_z (m/s^2, gravity still in when the profile says so)
  attitude:     roll, pitch (rad; from a quaternion: REP-103 Z-Y-X Euler angles)
  ground_truth: x, y, z (m)
Bags are read with `rosbags` (no ROS installation needed). A message without the
fields the profile asks for (no effort, an empty PoseArray) is counted `incomplete`.
"""

from __future__ import annotations

import csv
import glob
from collections import Counter
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .rover_profile import POSE_ARRAY, SECTION_TYPES, TIME_UNITS, ProfileError, RoverProfile, StreamSpec
from .timebase import NS, Stream

BAG_SUFFIXES = (".mcap", ".db3")


class _NoMessages(ValueError):
    """A bag without a single message on the profile's topics."""


def quaternion_roll_pitch(q: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions x, y, z, w -> (n, 2) roll, pitch (REP-103 Z-Y-X Euler angles, rad)."""
    x, y, z, w = (q[:, k] for k in range(4))
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    return np.column_stack([roll, pitch])


def source_kind(source: Path) -> str:
    """'bag' for a rosbag2 folder or a bare .mcap/.db3 file, 'csv' for a folder of CSV files."""
    if source.is_file():
        if source.suffix in BAG_SUFFIXES:
            return "bag"
        raise ValueError(f"{source}: not a bag file (.mcap or .db3) nor a folder")
    if not source.is_dir():
        raise FileNotFoundError(f"{source}: no such file or folder")
    if (source / "metadata.yaml").exists() or any(source.glob("*.mcap")) or any(source.glob("*.db3")):
        return "bag"
    return "csv"


# ---------------------------------------------------------------- rosbag2


def _stamp(msg) -> int:
    return int(msg.header.stamp.sec) * NS + int(msg.header.stamp.nanosec)


def _xyz(v) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _quat(q) -> tuple[float, float, float, float]:
    return (q.x, q.y, q.z, q.w)


def _position(msg, msgtype: str):
    if msgtype == POSE_ARRAY:
        return _xyz(msg.poses[0].position) if len(msg.poses) else None
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose  # Odometry or PoseStamped
    return _xyz(pose.position)


def _orientation(msg, msgtype: str):
    return _quat(msg.orientation) if msgtype.endswith("/Imu") else _quat(msg.pose.pose.orientation)


class _Wheels:
    """Per-message wheel channels; the joint order is looked up once per distinct name list."""

    def __init__(self, profile: RoverProfile, topic: str):
        self.profile, self.topic, self.index = profile, topic, {}

    def __call__(self, msg):
        names = tuple(msg.name)
        idx = self.index.get(names)
        if idx is None:
            missing = [j for j in self.profile.joints if j not in names]
            if missing:
                key = "wheels.left_joints" if missing[0] in self.profile.left_joints else "wheels.right_joints"
                raise ProfileError(self.profile.path, key, f"joint {missing[0]!r} is not in {self.topic} "
                                   f"(its joints: {', '.join(names) or 'none'})")
            idx = self.index[names] = np.array([names.index(j) for j in self.profile.joints])
        if len(msg.velocity) != len(names) or len(msg.effort) != len(names):
            return None
        return np.concatenate([msg.velocity[idx], msg.effort[idx]])  # channels: `wheel_channels`, once per stream


def wheel_channels(per_joint: np.ndarray, profile: RoverProfile) -> np.ndarray:
    """(n, 2 k) velocities then efforts of k wheels -> (n, 2) wheel_speed (rad/s), motor_current (A)."""
    k = per_joint.shape[1] // 2
    return np.column_stack([np.abs(per_joint[:, :k]).mean(axis=1) * profile.velocity_scale,
                            np.abs(per_joint[:, k:]).mean(axis=1) * profile.current_per_effort])


def read_bag(source: Path, profile: RoverProfile, progress: bool = True) -> tuple[dict[str, Stream], Counter]:
    """One stream per profile section from a rosbag2 folder or a bare .mcap/.db3 file."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    drops: Counter = Counter()
    specs = profile.streams
    try:
        reader = AnyReader([source], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # noqa: BLE001 - any failure of the storage libraries on a foreign file is bad input
        raise ValueError(f"{source}: cannot open as a rosbag2 (truncated or not a bag?): {type(e).__name__}: {e}") from None
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        for section, spec in specs.items():
            _check_topic(profile, section, spec, topics, source)
        conns = [c for c in reader.connections if c.topic in {s.topic for s in specs.values()}]
        extract = {}
        for section, spec in specs.items():
            mtype = topics[spec.topic]
            if section == "wheels":
                extract[section] = _Wheels(profile, spec.topic)
            elif section == "imu":
                extract[section] = lambda m: _xyz(m.linear_acceleration)
            elif section == "attitude":
                extract[section] = lambda m, t=mtype: _orientation(m, t)
            else:
                extract[section] = lambda m, t=mtype: _position(m, t)
        by_topic: dict[str, list[str]] = {}
        for section, spec in specs.items():
            by_topic.setdefault(spec.topic, []).append(section)
        rows: dict[str, list] = {s: [] for s in specs}
        stamps: dict[str, list] = {s: [] for s in specs}
        total = sum(c.msgcount for c in conns)
        if total == 0:
            raise _NoMessages(f"{source}: the bag holds no messages on {', '.join(sorted(by_topic))}")
        with tqdm(total=total, desc=f"reading {source.name}", unit="msg", unit_scale=True, disable=not progress) as bar:
            for i, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                msg = reader.deserialize(raw, conn.msgtype)
                for section in by_topic[conn.topic]:
                    vals = extract[section](msg)
                    if vals is None:
                        drops["incomplete"] += 1
                        continue
                    rows[section].append(vals)
                    stamps[section].append(_stamp(msg))
                if i % 4096 == 4095:
                    bar.update(4096)
            bar.update(total - bar.n)
    except (ProfileError, _NoMessages):
        raise
    except Exception as e:  # noqa: BLE001 - as above: a corrupt chunk or message is bad input, not a bug
        raise ValueError(f"{source}: cannot read the bag to its end (truncated or corrupt?): "
                         f"{type(e).__name__}: {e}") from None
    finally:
        reader.close()
    streams = {}
    for section in specs:
        width = {"wheels": 2 * len(profile.joints), "imu": 3, "attitude": 4, "ground_truth": 3}[section]
        values = np.array(rows[section], dtype=np.float64).reshape(-1, width)
        if section == "wheels":
            values = wheel_channels(values, profile)
        elif section == "attitude":
            values = quaternion_roll_pitch(values)
        streams[section] = Stream(section, np.array(stamps[section], dtype=np.int64), values)
    return streams, drops


def _check_topic(profile: RoverProfile, section: str, spec: StreamSpec, topics: dict[str, str], source: Path) -> None:
    if spec.topic not in topics:
        listing = ", ".join(f"{t} ({m.split('/')[-1]})" for t, m in sorted(topics.items())) or "no topics"
        raise ProfileError(profile.path, f"{section}.topic", f"{spec.topic!r} is not in {source.name} (it has: {listing})")
    if topics[spec.topic] not in SECTION_TYPES[section]:
        raise ProfileError(profile.path, f"{section}.topic", f"{spec.topic} carries {topics[spec.topic]}, expected "
                           f"{' or '.join(SECTION_TYPES[section])}")


# ---------------------------------------------------------------- time-series CSV


def _read_columns(path: Path, spec: StreamSpec, drops: Counter, profile: RoverProfile) -> tuple[np.ndarray, np.ndarray]:
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        wanted = [("time_column", spec.csv.time_column)] + [(k, c) for k, cols in spec.columns.items() for c in cols]
        index = []
        for key, col in wanted:
            if col not in header:
                raise ProfileError(profile.path, f"{spec.section}.{key}", f"column {col!r} is not in {path.name} "
                                   f"(its columns: {', '.join(header) or 'none'})")
            index.append(header.index(col))
        rows = []
        for fields in reader:
            if not fields or all(not f.strip() for f in fields):
                continue
            row = []
            for i in index:
                try:
                    row.append(float(fields[i]))
                except (ValueError, IndexError):
                    row.append(float("nan"))
            rows.append(row)
    a = np.array(rows, dtype=np.float64).reshape(-1, len(index))
    bad_time = ~np.isfinite(a[:, 0])
    drops["nonfinite"] += int(np.count_nonzero(bad_time))
    a = a[~bad_time]
    t = np.round(a[:, 0] * TIME_UNITS[spec.csv.time_unit]).astype(np.int64)
    return t, a[:, 1:]


def read_timeseries_csv(source: Path, profile: RoverProfile, progress: bool = True) -> tuple[dict[str, Stream], Counter]:
    """One stream per profile section from a folder of per-sensor CSV files (matched by each `file` pattern)."""
    drops: Counter = Counter()
    streams = {}
    for section, spec in tqdm(profile.streams.items(), desc=f"reading {source.name}", unit="sensor",
                              disable=not progress):
        files = sorted(Path(p) for p in glob.glob(str(source / spec.csv.file)))
        if not files:
            raise ProfileError(profile.path, f"{section}.file", f"no file matches {spec.csv.file!r} in {source} "
                               f"(it has: {', '.join(sorted(p.name for p in source.glob('*.csv'))) or 'no CSV files'})")
        parts = [_read_columns(f, spec, drops, profile) for f in files]
        t = np.concatenate([p[0] for p in parts])
        v = np.concatenate([p[1] for p in parts])
        if section == "wheels":
            v = wheel_channels(v, profile)
        elif section == "attitude":
            v = v * profile.angle_scale
        streams[section] = Stream(section, t, v)
    return streams, drops


def read_log(source: Path, profile: RoverProfile, progress: bool = True) -> tuple[dict[str, Stream], Counter]:
    """The streams of a bag or of a CSV folder, with what the reader itself dropped."""
    kind = source_kind(source)
    if kind != profile.kind:
        raise ValueError(f"{source} is a {'rosbag2' if kind == 'bag' else 'time-series CSV folder'} but "
                         f"{profile.path} describes {'topics' if profile.kind == 'bag' else 'CSV files'}")
    return (read_bag if kind == "bag" else read_timeseries_csv)(source, profile, progress)
