"""Read a rover's rosbag2 (MCAP or sqlite3) into one `Stream` per profile section (a folder of
time-series CSVs: `timeseries_csv`, which reuses `wheel_channels`).

Each stream carries the header stamps and, per message, the section's channels in
physical units:
  wheels:       wheel_speed (mean |velocity| over the profile's joints, rad/s),
                motor_current (mean |effort| x current_per_effort, A)
  imu:          acc_x, acc_y, acc_z (m/s^2, gravity still in when the profile says so), then with
                [attitude] source = "imu" the gyro x, y, z (the Imu message's angular_velocity, rad/s)
  attitude:     roll, pitch (rad; from a quaternion: REP-103 Z-Y-X Euler angles)
  ground_truth: x, y, z (m)
Bags are read with `rosbags` (no ROS installation needed): a rosbag2 folder, one without its
metadata.yaml, or a bare .mcap/.db3 file. An MCAP bag that rosbags refuses (cut short by a crash:
no summary, index or footer; a damaged chunk) is read front to back up to its last whole message
(`mcap_stream`) and decoded with rosbags' CDR deserialiser; one line says what was salvaged and lost.
Each message is placed at its header stamp, or at its log time with `[import] stamps = "log"`.
A message without the fields the profile asks for (no effort, an empty PoseArray) is counted `incomplete`.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .rover_profile import POSE_ARRAY, SECTION_TYPES, ProfileError, RoverProfile, StreamSpec
from .timebase import NS, Stream
from ..errors import InputError

BAG_SUFFIXES = (".mcap", ".db3")


class _NoMessages(InputError):
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
        raise InputError(f"{source}: not a bag file (.mcap or .db3) nor a folder")
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


ZERO_STAMPS_HINT = 'the header stamps are all zero: set [import] stamps = "log"'


class _Unreadable(Exception):
    """rosbags could not open or read the bag to its end (its reason in the message)."""


class _Collect:
    """The profile's sections from the messages of a bag: values per message, and the header stamp or the
    log time of each (`[import] stamps`)."""

    def __init__(self, profile: RoverProfile, source: Path, topics: dict[str, str]):
        self.profile, self.source = profile, source
        specs = profile.streams
        for section, spec in specs.items():
            _check_topic(profile, section, spec, topics, source)
        self.extract = {}
        for section, spec in specs.items():
            mtype = topics[spec.topic]
            if section == "wheels":
                self.extract[section] = _Wheels(profile, spec.topic)
            elif section == "imu":
                self.extract[section] = ((lambda m: _xyz(m.linear_acceleration) + _xyz(m.angular_velocity))
                                         if profile.imu_gyro else (lambda m: _xyz(m.linear_acceleration)))
            elif section == "attitude":
                self.extract[section] = lambda m, t=mtype: _orientation(m, t)
            else:
                self.extract[section] = lambda m, t=mtype: _position(m, t)
        self.by_topic: dict[str, list[str]] = {}
        for section, spec in specs.items():
            self.by_topic.setdefault(spec.topic, []).append(section)
        self.msgtype = {t: topics[t] for t in self.by_topic}
        self.rows: dict[str, list] = {s: [] for s in specs}
        self.stamps: dict[str, list] = {s: [] for s in specs}
        self.log_time = profile.stamps == "log"
        self.drops: Counter = Counter()

    def add(self, topic: str, msg, log_ns: int) -> None:
        for section in self.by_topic[topic]:
            vals = self.extract[section](msg)
            if vals is None:
                self.drops["incomplete"] += 1
                continue
            self.rows[section].append(vals)
            self.stamps[section].append(log_ns if self.log_time else _stamp(msg))

    def no_messages(self, why: str = "") -> _NoMessages:
        return _NoMessages(f"{self.source}: the bag holds no messages on {', '.join(sorted(self.by_topic))}{why}")

    def streams(self, notes: list[str]) -> dict[str, Stream]:
        profile, streams = self.profile, {}
        for section, spec in profile.streams.items():
            t = np.array(self.stamps[section], dtype=np.int64)
            if not self.log_time and len(t) >= 2:
                zeros = int(np.count_nonzero(t == 0))
                if zeros == len(t):
                    raise InputError(f"{self.source}: {spec.topic}: {ZERO_STAMPS_HINT} in {profile.path} to cut the "
                                     "windows in the bag's log time (when the recorder received each message)")
                if zeros:
                    notes.append(f"{self.source}: {spec.topic}: {zeros} of {len(t)} header stamps are zero (dropped as "
                                 'backwards stamps); if the driver leaves them unset, set [import] stamps = "log"')
            width = {"wheels": 2 * len(profile.joints), "imu": 6 if profile.imu_gyro else 3, "attitude": 4,
                     "ground_truth": 3}[section]
            values = np.array(self.rows[section], dtype=np.float64).reshape(-1, width)
            if section == "wheels":
                values = wheel_channels(values, profile)
            elif section == "attitude":
                values = quaternion_roll_pitch(values)
            streams[section] = Stream(section, t, values)
        return streams


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _bag_metadata(folder: Path) -> dict | None:
    """metadata.yaml of a rosbag2 folder (rosbag2_bagfile_information), or None when absent or unreadable."""
    path = folder / "metadata.yaml"
    if not path.is_file():
        return None
    try:
        from ruamel.yaml import YAML

        info = YAML(typ="safe").load(path.read_text())["rosbag2_bagfile_information"]
        return info if isinstance(info, dict) else None
    except Exception:  # noqa: BLE001 - a damaged metadata.yaml: the storage files are read without it
        return None


def bag_files(source: Path) -> list[Path]:
    """The storage files of a bag: the file given; those metadata.yaml lists; or, without a (usable)
    metadata.yaml (a recorder that stopped before writing it), the folder's .mcap or .db3 files by name."""
    if source.is_file():
        return [source]
    meta = _bag_metadata(source)
    if meta is not None:
        try:
            listed = [source / Path(str(p)).name for p in meta["relative_file_paths"]]
        except (KeyError, TypeError):
            listed = []
        if listed and all(p.is_file() for p in listed):
            return listed
    files = sorted(source.glob("*.mcap")) or sorted(source.glob("*.db3"))
    if not files:
        raise InputError(f"{source}: no .mcap or .db3 file in this folder")
    return files


def _read_rosbags(paths: list[Path], source: Path, profile: RoverProfile, progress: bool) -> _Collect:
    """Every message on the profile's topics, through rosbags (its index, in log-time order)."""
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader(paths, default_typestore=_typestore())
        reader.open()
    except Exception as e:  # noqa: BLE001 - any failure of the storage libraries on a foreign file is bad input
        raise _Unreadable(f"{type(e).__name__}: {e}") from None
    try:
        col = _Collect(profile, source, {c.topic: c.msgtype for c in reader.connections})
        conns = [c for c in reader.connections if c.topic in col.by_topic]
        total = sum(c.msgcount for c in conns)
        if total == 0:
            raise col.no_messages()
        with tqdm(total=total, desc=f"reading {source.name}", unit="msg", unit_scale=True, disable=not progress) as bar:
            for i, (conn, log_ns, raw) in enumerate(reader.messages(connections=conns)):
                col.add(conn.topic, reader.deserialize(raw, conn.msgtype), log_ns)
                if i % 4096 == 4095:
                    bar.update(4096)
            bar.update(total - bar.n)
    except (ProfileError, _NoMessages):
        raise
    except Exception as e:  # noqa: BLE001 - as above: a corrupt chunk or message is bad input, not a bug
        raise _Unreadable(f"{type(e).__name__}: {e}") from None
    finally:
        reader.close()
    return col


def _read_salvaged(files: list[Path], source: Path, profile: RoverProfile, progress: bool, why: str,
                   notes: list[str]) -> _Collect:
    """The whole messages of MCAP files read front to back (`mcap_stream`), for a bag rosbags refused;
    what was salvaged and what was lost is one line in `notes` and counted in the collector's drops."""
    from .mcap_stream import NotMcap, scan_mcap

    try:
        scans = [scan_mcap(f) for f in files]
    except NotMcap as e:
        raise InputError(f"{e} ({why})") from None
    topics: dict[str, str] = {}
    for scan in scans:
        topics.update({c.topic: c.msgtype for c in scan.channels.values()})
    cut = [s for s in scans if not s.complete]
    where = "; ".join(f"{s.path.name}: {s.stop}" for s in cut)
    missing = sorted({spec.topic for spec in profile.streams.values()} - set(topics))
    if cut and missing:  # the topic may well be in the bag, after the cut
        raise _NoMessages(f"{source}: the bag holds no messages on {', '.join(missing)} before it ends ({where})")
    col = _Collect(profile, source, topics)
    ts = _typestore()
    wanted = [(scan.channels[cid], log_ns, raw) for scan in scans for cid, log_ns, raw in scan.messages
              if cid in scan.channels and scan.channels[cid].topic in col.by_topic]
    if not wanted:
        raise col.no_messages(f" that could be read whole ({where or why})")
    for ch in {c for c, _, _ in wanted}:
        if ch.encoding != "cdr":
            raise InputError(f"{source}: {ch.topic} is encoded {ch.encoding!r}, not as ROS 2 CDR ('cdr')")
    for ch, log_ns, raw in tqdm(wanted, desc=f"salvaging {source.name}", unit="msg", unit_scale=True,
                                disable=not progress):
        try:
            msg = ts.deserialize_cdr(raw, ch.msgtype)
        except Exception:  # noqa: BLE001 - a message whose bytes do not decode is dropped and counted
            col.drops["undecodable"] += 1
            continue
        col.add(ch.topic, msg, log_ns)
    n = sum(len(s.messages) for s in scans)
    times = [log_ns for s in scans for _, log_ns, _ in s.messages]
    span = (max(times) - min(times)) / NS if times else 0.0
    lost = sum(s.lost_bytes for s in cut)
    if not cut:
        notes.append(f"{source}: read front to back without its index ({why}): {n} messages, {span:.1f} s")
        return col
    col.drops["bag_lost_bytes"] += lost
    kind = "damaged" if any(s.stop.startswith("a damaged") for s in cut) else "cut short"
    lost_parts = []
    meta = _bag_metadata(source) if source.is_dir() else None
    try:
        listed, start = int(meta["message_count"]), int(meta["starting_time"]["nanoseconds_since_epoch"])
        end = start + int(meta["duration"]["nanoseconds"])
    except (TypeError, KeyError, ValueError):
        listed = None
    if listed is not None:
        col.drops["bag_lost_messages"] += max(listed - n, 0)
        lost_parts.append(f"{max(listed - n, 0)} messages and {max(end - max(times), 0) / NS:.1f} s (metadata.yaml "
                          f"lists {listed} messages over {(end - start) / NS:.1f} s)")
    else:
        lost_parts.append("what came after the cut (how much is unknown: no metadata.yaml)")
    if lost:
        lost_parts.append(f"{lost} bytes of cut or damaged records")
    lost_parts.append("the summary/index")
    line = (f"{source}: bag {kind} ({where}): salvaged {n} messages ({span:.1f} s) up to the last whole one; "
            f"lost {', '.join(lost_parts)}")
    notes.append(line)
    return col


def read_bag(source: Path, profile: RoverProfile, progress: bool = True,
             notes: list[str] | None = None) -> tuple[dict[str, Stream], Counter]:
    """One stream per profile section from a rosbag2 folder (with or without metadata.yaml) or a bare
    .mcap/.db3 file. An MCAP bag that rosbags cannot read (cut short by a crash: no summary, index or
    footer; a damaged chunk) is read front to back up to its last whole message instead, and a line
    saying what was salvaged and what was lost goes into `notes`."""
    notes = notes if notes is not None else []
    files = bag_files(source)
    whole = [source] if source.is_file() or _bag_metadata(source) is not None else files
    try:
        col = _read_rosbags(whole, source, profile, progress)
    except _Unreadable as e:
        if not all(f.suffix == ".mcap" for f in files):
            raise InputError(f"{source}: cannot read as a rosbag2 (truncated, corrupt or not a bag?): {e}"
                             + ("; a sqlite3 bag is not salvaged, only MCAP" if any(f.suffix == ".db3" for f in files)
                                else "")) from None
        col = _read_salvaged(files, source, profile, progress, f"rosbags: {e}", notes)
    return col.streams(notes), col.drops


def _check_topic(profile: RoverProfile, section: str, spec: StreamSpec, topics: dict[str, str], source: Path) -> None:
    if spec.topic not in topics:
        listing = ", ".join(f"{t} ({m.split('/')[-1]})" for t, m in sorted(topics.items())) or "no topics"
        raise ProfileError(profile.path, f"{section}.topic", f"{spec.topic!r} is not in {source.name} (it has: {listing})")
    if topics[spec.topic] not in SECTION_TYPES[section]:
        raise ProfileError(profile.path, f"{section}.topic", f"{spec.topic} carries {topics[spec.topic]}, expected "
                           f"{' or '.join(SECTION_TYPES[section])}")


def read_log(source: Path, profile: RoverProfile, progress: bool = True,
             notes: list[str] | None = None) -> tuple[dict[str, Stream], Counter]:
    """The streams of a bag, with what the reader itself dropped; what the user must hear about the log
    itself (a bag salvaged after a crash) goes into `notes`, one line each. A time-series CSV folder is read
    by `timeseries_csv.read_csv_drives` (it may hold several drives)."""
    kind = source_kind(source)
    if kind != profile.kind:
        raise InputError(f"{source} is a {'rosbag2' if kind == 'bag' else 'time-series CSV folder'} but "
                         f"{profile.path} describes {'topics' if profile.kind == 'bag' else 'CSV files'}")
    if kind != "bag":  # a CSV folder may hold several drives: `timeseries_csv.read_csv_drives`
        raise InputError(f"{source}: a time-series CSV folder is read drive by drive (timeseries_csv)")
    return read_bag(source, profile, progress, notes)
