"""Rover profile (`--rover PROFILE.toml`): where each raw channel and the ground truth come from in a log.

A profile describes one rover's logs, whether rosbag2 (a `topic` per section) or
time-series CSV (a `file` pattern per section). See docs/your_rover.md for the
reference. Every mistake is one `ProfileError` line naming the profile key.

Sections:
  [rover]         name, wheel_radius_m
  [wheels]        bag: topic (sensor_msgs/JointState), left_joints, right_joints
                  csv: file, time_column, time_unit, velocity_columns, effort_columns
                  both: velocity_unit (rad/s | rpm | deg/s, or the linear m/s | km/h: then no
                  wheel_radius_m), velocity_scale, current_per_effort (A per effort unit)
  [imu]           bag: topic (sensor_msgs/Imu; its angular_velocity is the gyro); csv: file, time_column,
                  time_unit, acc_columns, gyro_columns (needed by [attitude] source = "imu")
                  both: includes_gravity, gravity_m_s2, acc_unit (m/s^2 | g), acc_scale, range_m_s2
                  (optional), gyro_unit (rad/s | deg/s), gyro_scale
  [attitude]      bag: topic (nav_msgs/Odometry or sensor_msgs/Imu orientation)
                  csv: file, time_column, time_unit, roll_column, pitch_column, angle_unit (rad | deg),
                  angle_scale
                  or source = "imu" (estimated from [imu]'s gyro and accelerometer, `attitude.py`)
                  or source = "level" (roll = pitch = 0: a rover that knows it drives on flat ground)
  [ground_truth]  optional. bag: topic (geometry_msgs/PoseStamped, nav_msgs/Odometry, geometry_msgs/PoseArray)
                  csv: file, time_column, time_unit, position_columns (x, y, z in m), position_scale
A `*_scale` key multiplies a channel given in a unit that is not listed into the unit named beside it
(cm/s: velocity_unit = "m/s" with velocity_scale = 0.01; mg: acc_unit = "g" with acc_scale = 0.001).
  [import]        max_gap_s (default 0.5): a longer pause in any stream ends a traverse segment
                  stamps (bags: "header", the default, or "log"): the messages' header stamps or the bag's log time
"""

from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from ..errors import InputError

TIME_UNITS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
VELOCITY_UNITS = {"rad/s": 1.0, "rpm": 2.0 * 3.141592653589793 / 60.0, "deg/s": 3.141592653589793 / 180.0,
                  "m/s": 1.0, "km/h": 1.0 / 3.6}
LINEAR_VELOCITY_UNITS = ("m/s", "km/h")  # the wheel's rim speed: commanded distance = speed x dt, no radius
GYRO_UNITS = {"rad/s": 1.0, "deg/s": 3.141592653589793 / 180.0}
ATTITUDE_SOURCES = ("imu", "level")  # [attitude] source: estimated from the IMU, or flat ground
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
               "velocity_unit", "velocity_scale", "current_per_effort"),
    "imu": ("topic", *_CSV_KEYS, "acc_columns", "gyro_columns", "includes_gravity", "gravity_m_s2", "acc_unit",
            "acc_scale", "range_m_s2", "gyro_unit", "gyro_scale"),
    "attitude": ("topic", *_CSV_KEYS, "roll_column", "pitch_column", "angle_unit", "angle_scale", "source"),
    "ground_truth": ("topic", *_CSV_KEYS, "position_columns", "position_scale"),
    "import": ("max_gap_s", "stamps"),
}
_REQUIRED_SECTIONS = ("rover", "wheels", "imu", "attitude")


class ProfileError(InputError):
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
    wheel_radius_m: float | None  # None with a linear velocity_unit (the wheel speed is the rim speed then)
    wheels: StreamSpec
    left_joints: tuple[str, ...]
    right_joints: tuple[str, ...]
    velocity_scale: float  # to rad/s (to m/s with a linear velocity_unit)
    current_per_effort: float  # A per effort unit
    imu: StreamSpec
    includes_gravity: bool
    gravity_m_s2: float
    acc_scale: float  # to m/s^2
    imu_range_m_s2: float | None
    attitude: StreamSpec | None  # None when roll and pitch do not come from the log (attitude_source)
    angle_scale: float  # to rad
    ground_truth: StreamSpec | None
    max_gap_s: float
    stamps: str = "header"  # bags: "header" (the messages' header stamps) or "log" (the bag's log time)
    attitude_source: str = "log"  # "log" (topic or columns), "imu" (estimated from gyro + accelerometer), "level"
    velocity_unit: str = "rad/s"
    gyro_scale: float = 1.0  # to rad/s
    position_scale: float = 1.0  # to m

    @property
    def joints(self) -> tuple[str, ...]:
        return self.left_joints + self.right_joints

    @property
    def linear_wheel_speed(self) -> bool:
        """The wheel speed is a rim speed (m/s): commanded distance = speed x dt, no wheel radius."""
        return self.velocity_unit in LINEAR_VELOCITY_UNITS

    @property
    def metres_per_wheel_speed(self) -> float:
        """Commanded distance per unit of wheel speed and second: the radius, or 1 for a rim speed."""
        return 1.0 if self.wheel_radius_m is None else self.wheel_radius_m

    @property
    def imu_gyro(self) -> bool:
        """The IMU stream carries the gyro too (acc x, y, z then gyro x, y, z): for source = "imu"."""
        return self.attitude_source == "imu"

    @property
    def streams(self) -> dict[str, StreamSpec]:
        out = {"wheels": self.wheels, "imu": self.imu}
        if self.attitude is not None:
            out["attitude"] = self.attitude
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

    def choice(self, key: str, choices: dict, default: str, scale_key: str | None = None) -> float:
        """The factor of a listed unit, times the `scale_key` number (default 1) when the profile has one."""
        v = self.text(key, default)
        if v not in choices:
            hint = (f" (a unit not listed: give the nearest listed unit and {scale_key} = the factor from yours "
                    "to it)") if scale_key else ""
            raise self.err(key, f"unknown unit {v!r}; one of {', '.join(choices)}{hint}")
        return choices[v] * (self.number(scale_key, 1.0) if scale_key else 1.0)

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
            hint = ("; logs without orientation: source = \"imu\" (roll and pitch from the gyro and accelerometer, "
                    "[imu] gyro_columns) or source = \"level\" (flat ground)") if section == "attitude" else ""
            raise ProfileError(path, section, "missing section" + hint)


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


STAMPS = ("header", "log")


def _stamps(imp: _Reader, bag: bool) -> str:
    """`[import] stamps`: which time a bag message is put on the time base by."""
    v = imp.text("stamps", "header")
    if v not in STAMPS:
        raise imp.err("stamps", f'must be "header" (the messages\' header stamps) or "log" (the bag\'s log time, '
                      f"when the recorder received each message), got {v!r}")
    if imp.has("stamps") and not bag:
        raise imp.err("stamps", "applies to bags only; a time-series CSV takes its times from each time_column")
    return v


def load_profile(path: Path | str) -> RoverProfile:
    """Read and check a rover profile; every mistake is one ProfileError line."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such rover profile (docs/your_rover.md describes one)") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
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
    vel_unit = wheels.text("velocity_unit", "rad/s")
    velocity_scale = wheels.choice("velocity_unit", VELOCITY_UNITS, "rad/s", "velocity_scale")
    if vel_unit in LINEAR_VELOCITY_UNITS and rover.has("wheel_radius_m"):
        raise rover.err("wheel_radius_m", f"not used with wheels.velocity_unit = {vel_unit!r}: a linear wheel speed "
                        "gives the commanded distance itself (speed x dt); remove wheel_radius_m, or give the "
                        "wheel speed as an angular unit (rad/s, rpm, deg/s)")
    att = _Reader(path, "attitude", data["attitude"])
    source = _attitude_source(att)
    imu = _Reader(path, "imu", data["imu"])
    gyro = imu.has("gyro_columns") or (source == "imu" and not imu.has("topic"))
    imu_stream = _stream(imu, {"acc_columns": 3, **({"gyro_columns": 3} if gyro else {})})
    includes_gravity = imu.flag("includes_gravity")
    gravity = imu.number("gravity_m_s2") if includes_gravity else imu.number("gravity_m_s2", 9.80665)
    if source == "imu" and not includes_gravity:
        raise imu.err("includes_gravity", f"[attitude] source = {source!r} needs the raw accelerometer (gravity in): "
                      "an IMU driver that removed gravity had an attitude of its own, give it as [attitude] topic "
                      "or columns")
    att_stream = _stream(att, {"roll_column": 1, "pitch_column": 1}) if source == "log" else None
    truth = None
    if "ground_truth" in data:
        gt = _Reader(path, "ground_truth", data["ground_truth"])
        truth = _stream(gt, {"position_columns": 3})
    kinds = {s.section: s.topic is not None for s in (wheel_stream, imu_stream, att_stream, truth) if s is not None}
    if len(set(kinds.values())) > 1:
        odd = [k for k, bag in kinds.items() if bag != kinds["wheels"]]
        raise ProfileError(path, odd[0], "mixes a bag 'topic' and a CSV 'file' with [wheels]; a profile describes "
                           "one kind of log")
    imp = _Reader(path, "import", data.get("import", {}))
    return RoverProfile(
        path=path,
        name=rover.text("name"),
        wheel_radius_m=None if vel_unit in LINEAR_VELOCITY_UNITS else rover.number("wheel_radius_m"),
        wheels=wheel_stream,
        left_joints=left,
        right_joints=right,
        velocity_scale=velocity_scale,
        current_per_effort=wheels.number("current_per_effort", 1.0),
        imu=imu_stream,
        includes_gravity=includes_gravity,
        gravity_m_s2=gravity,
        acc_scale=imu.choice("acc_unit", ACC_UNITS, "m/s^2", "acc_scale"),
        imu_range_m_s2=imu.number("range_m_s2") if imu.has("range_m_s2") else None,
        attitude=att_stream,
        angle_scale=att.choice("angle_unit", ANGLE_UNITS, "rad", "angle_scale") if source == "log" else 1.0,
        ground_truth=truth,
        max_gap_s=imp.number("max_gap_s", DEFAULT_MAX_GAP_S),
        stamps=_stamps(imp, wheel_stream.topic is not None),
        attitude_source=source,
        velocity_unit=vel_unit,
        gyro_scale=imu.choice("gyro_unit", GYRO_UNITS, "rad/s", "gyro_scale"),
        position_scale=gt.number("position_scale", 1.0) if truth is not None else 1.0,
    )


def _attitude_source(att: _Reader) -> str:
    """`[attitude] source`: "imu" or "level" (nothing else in the table), or "log" (a topic or columns)."""
    if not att.has("source"):
        return "log"
    v = att.text("source")
    if v not in ATTITUDE_SOURCES:
        raise att.err("source", f'must be "imu" (roll and pitch estimated from [imu]\'s gyro and accelerometer) or '
                      f'"level" (flat ground: roll = pitch = 0), got {v!r}; an attitude in the log is given by '
                      "topic or file instead")
    other = [k for k in att.table if k != "source"]
    if other:
        raise att.err(other[0], f"not used with source = {v!r} (the log's own attitude is given by topic or file, "
                      "without source)")
    return v
