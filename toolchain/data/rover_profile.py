"""Rover profile (`--rover PROFILE.toml`): where each raw channel and the ground truth come from in a log.

A profile describes one rover's logs, whether rosbag2 (a `topic` per section) or
time-series CSV (a `file` pattern per section). See docs/your_rover.md for the
reference. Every mistake is one `ProfileError` line naming the profile key.

Sections:
  [rover]         name, wheel_radius_m
  [wheels]        bag: topic (sensor_msgs/JointState), left_joints, right_joints
                  csv: file, time_column, time_unit, velocity_columns, effort_columns
                  both: velocity_unit (rad/s | rpm | deg/s), current_per_effort (A per effort unit)
  [imu]           bag: topic (sensor_msgs/Imu); csv: file, time_column, time_unit, acc_columns
                  both: includes_gravity, gravity_m_s2, acc_unit (m/s^2 | g), range_m_s2 (optional)
  [attitude]      bag: topic (nav_msgs/Odometry or sensor_msgs/Imu orientation)
                  csv: file, time_column, time_unit, roll_column, pitch_column, angle_unit (rad | deg)
  [ground_truth]  optional. bag: topic (geometry_msgs/PoseStamped, nav_msgs/Odometry, geometry_msgs/PoseArray)
                  csv: file, time_column, time_unit, position_columns (x, y, z in m)
  [import]        max_gap_s (default 0.5): a longer pause in any stream ends a traverse segment
"""

from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

TIME_UNITS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
VELOCITY_UNITS = {"rad/s": 1.0, "rpm": 2.0 * 3.141592653589793 / 60.0, "deg/s": 3.141592653589793 / 180.0}
ACC_UNITS = {"m/s^2": 1.0, "g": 9.80665}
ANGLE_UNITS = {"rad": 1.0, "deg": 3.141592653589793 / 180.0}
DEFAULT_MAX_GAP_S = 0.5

# Message types each bag section accepts (ROS 2 names as rosbags spells them).
JOINT_STATE = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
SECTION_TYPES: dict[str, tuple[str, ...]] = {
    "wheels": (JOINT_STATE,),
    "imu": (IMU,),
    "attitude": (ODOMETRY, IMU),
    "ground_truth": (POSE_STAMPED, ODOMETRY, POSE_ARRAY),
}

_CSV_KEYS = ("file", "time_column", "time_unit")
_KEYS: dict[str, tuple[str, ...]] = {
    "rover": ("name", "wheel_radius_m"),
    "wheels": ("topic", "left_joints", "right_joints", *_CSV_KEYS, "velocity_columns", "effort_columns",
               "velocity_unit", "current_per_effort"),
    "imu": ("topic", *_CSV_KEYS, "acc_columns", "includes_gravity", "gravity_m_s2", "acc_unit", "range_m_s2"),
    "attitude": ("topic", *_CSV_KEYS, "roll_column", "pitch_column", "angle_unit"),
    "ground_truth": ("topic", *_CSV_KEYS, "position_columns"),
    "import": ("max_gap_s",),
}
_REQUIRED_SECTIONS = ("rover", "wheels", "imu", "attitude")


class ProfileError(ValueError):
    """A rover profile mistake: one line naming the file and the key."""

    def __init__(self, path: Path | str, key: str, message: str):
        super().__init__(f"{path}: [{key}] {message}" if "." not in key else f"{path}: {key}: {message}")
        self.key = key


@dataclass(frozen=True)
class CsvSpec:
    """One time-series CSV source: file pattern (relative to the source folder) and its time column."""

    file: str
    time_column: str
    time_unit: str  # key of TIME_UNITS


@dataclass(frozen=True)
class StreamSpec:
    """Where one section's data comes from: a bag topic or a CSV source (exactly one of them)."""

    section: str
    topic: str | None = None
    csv: CsvSpec | None = None
    columns: dict[str, tuple[str, ...]] = field(default_factory=dict)  # csv field -> column names


@dataclass(frozen=True)
class RoverProfile:
    path: Path
    name: str
    wheel_radius_m: float
    wheels: StreamSpec
    left_joints: tuple[str, ...]
    right_joints: tuple[str, ...]
    velocity_scale: float  # to rad/s
    current_per_effort: float  # A per effort unit
    imu: StreamSpec
    includes_gravity: bool
    gravity_m_s2: float
    acc_scale: float  # to m/s^2
    imu_range_m_s2: float | None
    attitude: StreamSpec
    angle_scale: float  # to rad
    ground_truth: StreamSpec | None
    max_gap_s: float

    @property
    def joints(self) -> tuple[str, ...]:
        return self.left_joints + self.right_joints

    @property
    def streams(self) -> dict[str, StreamSpec]:
        out = {"wheels": self.wheels, "imu": self.imu, "attitude": self.attitude}
        if self.ground_truth is not None:
            out["ground_truth"] = self.ground_truth
        return out

    @property
    def kind(self) -> str:
        """'bag' or 'csv': every section of one profile uses the same kind of source."""
        return "bag" if self.wheels.topic is not None else "csv"


class _Reader:
    """Typed access to one profile table, naming the key in every error."""

    def __init__(self, path: Path, section: str, table: dict):
        self.path, self.section, self.table = path, section, table

    def err(self, key: str, message: str) -> ProfileError:
        return ProfileError(self.path, f"{self.section}.{key}", message)

    def has(self, key: str) -> bool:
        return key in self.table

    def number(self, key: str, default: float | None = None, positive: bool = True) -> float:
        if key not in self.table:
            if default is None:
                raise self.err(key, "missing (a number is required)")
            return default
        v = self.table[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (positive and not v > 0):
            raise self.err(key, f"must be a {'positive ' if positive else ''}number, got {v!r}")
        return float(v)

    def text(self, key: str, default: str | None = None) -> str:
        v = self.table.get(key, default)
        if v is None:
            raise self.err(key, "missing (a string is required)")
        if not isinstance(v, str) or not v:
            raise self.err(key, f"must be a non-empty string, got {v!r}")
        return v

    def choice(self, key: str, choices: dict, default: str) -> float:
        v = self.text(key, default)
        if v not in choices:
            raise self.err(key, f"unknown unit {v!r}; one of {', '.join(choices)}")
        return choices[v]

    def names(self, key: str, length: int | None = None) -> tuple[str, ...]:
        v = self.table.get(key)
        if v is None:
            raise self.err(key, "missing (a list of names is required)")
        if not isinstance(v, list) or not v or not all(isinstance(s, str) and s for s in v):
            raise self.err(key, f"must be a non-empty list of strings, got {v!r}")
        if length is not None and len(v) != length:
            raise self.err(key, f"must name {length} columns, got {len(v)}")
        return tuple(v)

    def flag(self, key: str) -> bool:
        v = self.table.get(key)
        if not isinstance(v, bool):
            raise self.err(key, f"must be true or false, got {v!r}" if v is not None else "missing (true or false)")
        return v


def _check_keys(path: Path, data: dict) -> None:
    for section, table in data.items():
        if section not in _KEYS:
            hint = difflib.get_close_matches(section, _KEYS, 1)
            raise ProfileError(path, section, "unknown section" + (f" (did you mean [{hint[0]}]?)" if hint else "")
                               + f"; sections: {', '.join(_KEYS)}")
        if not isinstance(table, dict):
            raise ProfileError(path, section, "must be a table")
        for key in table:
            if key not in _KEYS[section]:
                hint = difflib.get_close_matches(key, _KEYS[section], 1)
                raise ProfileError(path, f"{section}.{key}", "unknown key" + (f" (did you mean {hint[0]!r}?)" if hint else "")
                                   + f"; [{section}] takes {', '.join(_KEYS[section])}")
    for section in _REQUIRED_SECTIONS:
        if section not in data:
            raise ProfileError(path, section, "missing section")


def _stream(r: _Reader, columns: dict[str, int | None]) -> StreamSpec:
    """The section's source: `topic` (bag) or `file` + time column + the named column lists (CSV)."""
    if r.has("topic") == r.has("file"):
        raise r.err("topic", "give exactly one of 'topic' (rosbag2) or 'file' (time-series CSV)")
    if r.has("topic"):
        return StreamSpec(r.section, topic=r.text("topic"))
    unit = r.text("time_unit", "s")
    if unit not in TIME_UNITS:
        raise r.err("time_unit", f"unknown unit {unit!r}; one of {', '.join(TIME_UNITS)}")
    spec = CsvSpec(r.text("file"), r.text("time_column"), unit)
    cols = {}
    for key, length in columns.items():
        if key.endswith("_column"):
            cols[key] = (r.text(key),)
        else:
            cols[key] = r.names(key, length)
    return StreamSpec(r.section, csv=spec, columns=cols)


def load_profile(path: Path | str) -> RoverProfile:
    """Read and check a rover profile; every mistake is one ProfileError line."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such rover profile (docs/your_rover.md describes one)") from None
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{path}: not valid TOML ({e})") from None
    _check_keys(path, data)
    rover = _Reader(path, "rover", data["rover"])
    wheels = _Reader(path, "wheels", data["wheels"])
    wheel_stream = _stream(wheels, {"velocity_columns": None, "effort_columns": None})
    if wheel_stream.topic is not None:
        left, right = wheels.names("left_joints"), wheels.names("right_joints")
        dup = sorted(set(left) & set(right))
        if dup:
            raise wheels.err("right_joints", f"{', '.join(dup)} also listed in left_joints")
    else:
        left = right = ()
        if len(wheel_stream.columns["velocity_columns"]) != len(wheel_stream.columns["effort_columns"]):
            raise wheels.err("effort_columns", "must name one column per velocity column")
    imu = _Reader(path, "imu", data["imu"])
    imu_stream = _stream(imu, {"acc_columns": 3})
    includes_gravity = imu.flag("includes_gravity")
    gravity = imu.number("gravity_m_s2") if includes_gravity else imu.number("gravity_m_s2", 9.80665)
    att = _Reader(path, "attitude", data["attitude"])
    att_stream = _stream(att, {"roll_column": 1, "pitch_column": 1})
    truth = None
    if "ground_truth" in data:
        truth = _stream(_Reader(path, "ground_truth", data["ground_truth"]), {"position_columns": 3})
    kinds = {s.section: s.topic is not None for s in (wheel_stream, imu_stream, att_stream, truth) if s is not None}
    if len(set(kinds.values())) > 1:
        odd = [k for k, bag in kinds.items() if bag != kinds["wheels"]]
        raise ProfileError(path, odd[0], "mixes a bag 'topic' and a CSV 'file' with [wheels]; a profile describes "
                           "one kind of log")
    imp = _Reader(path, "import", data.get("import", {}))
    return RoverProfile(
        path=path,
        name=rover.text("name"),
        wheel_radius_m=rover.number("wheel_radius_m"),
        wheels=wheel_stream,
        left_joints=left,
        right_joints=right,
        velocity_scale=wheels.choice("velocity_unit", VELOCITY_UNITS, "rad/s"),
        current_per_effort=wheels.number("current_per_effort", 1.0),
        imu=imu_stream,
        includes_gravity=includes_gravity,
        gravity_m_s2=gravity,
        acc_scale=imu.choice("acc_unit", ACC_UNITS, "m/s^2"),
        imu_range_m_s2=imu.number("range_m_s2") if imu.has("range_m_s2") else None,
        attitude=att_stream,
        angle_scale=att.choice("angle_unit", ANGLE_UNITS, "rad"),
        ground_truth=truth,
        max_gap_s=imp.number("max_gap_s", DEFAULT_MAX_GAP_S),
    )
